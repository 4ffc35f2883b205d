"""The learner contract's metrics (issue 25): every learner's ``update`` returns its train.csv columns as detached 0-d
tensors without a host sync from the tree's code (neither a Tensor method that reads a value on the host nor an
operator whose result's size depends on the data, such as indexing with a boolean mask), and the loops' mean of
them (``MetricMeans``) is the same bits as the former Python-float arithmetic, through a checkpoint too."""

from __future__ import annotations

import math
import struct
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from torch.utils._python_dispatch import TorchDispatchMode

import repro
from repro.config.compose import compose, typed
from repro.learners import SequenceLearner, build_learner
from repro.train.common import MetricMeans

OBS, A = (9, 32, 32), 6
REPRO = str(Path(repro.__file__).parent)
SYNCS = ("item", "tolist", "cpu", "numpy", "__float__", "__int__", "__bool__")  # each waits for the device
TORCH = Path(torch.__file__).parent
# torch's dispatch plumbing between a caller and the operator (not a caller itself)
PLUMBING = tuple(str(TORCH / p) for p in ("_dynamo", "_compile.py", "_ops.py", "_tensor.py", "overrides.py",
                                         "utils/_python_dispatch.py"))
# operators that read a value on the host, or size their result by the data (the host waits for the count)
DATA_SIZED = {"_local_scalar_dense", "nonzero", "masked_select", "unique", "_unique", "_unique2", "unique_dim",
              "unique_consecutive", "is_nonzero", "equal"}


class DataSizedOps(TorchDispatchMode):
    """Records the host-syncing operators (``DATA_SIZED``, indexing with a boolean mask, ``repeat_interleave``
    by a tensor of counts) that the tree's code calls: an operator that torch's own code calls (an optimizer's
    CPU step count, autograd's backward) is torch's."""

    def __init__(self) -> None:
        super().__init__()
        self.calls: list[str] = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        name = func._schema.name.split("::")[-1]
        bool_index = (name in ("index", "index_put", "index_put_") and len(args) > 1
                      and any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in args[1]))
        by_counts = name == "repeat_interleave" and func._overloadname == "Tensor"
        if name in DATA_SIZED or bool_index or by_counts:
            frame = sys._getframe(1)
            while frame is not None and (frame.f_code.co_filename == __file__
                                         or frame.f_code.co_filename.startswith(PLUMBING)):
                frame = frame.f_back
            if frame is not None and frame.f_code.co_filename.startswith(REPRO):
                self.calls.append(f"{func} at {frame.f_code.co_filename}:{frame.f_lineno}")
        return func(*args, **(kwargs or {}))


def _batch(K: int, B: int = 4) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    frames = lambda *lead: torch.randint(0, 256, (*lead, *OBS), generator=g, dtype=torch.uint8)  # noqa: E731
    return {"obs": frames(B), "next_obs": frames(B), "future_obs": frames(B), "future_obs_seq": frames(B, K),
            "action": torch.rand(B, A, generator=g) * 2 - 1, "action_seq": torch.rand(B, K, A, generator=g) * 2 - 1,
            "reward": torch.rand(B, 1, generator=g), "discount": torch.full((B, 1), 0.97),
            "reward_ksum": torch.rand(B, 1, generator=g)}


def _episodes() -> list[dict[str, np.ndarray]]:
    rng = np.random.default_rng(0)
    return [{"frames": rng.integers(0, 256, (n + 1, 3, *OBS[1:]), dtype=np.uint8),
             "actions": rng.uniform(-1, 1, (n, A)).astype(np.float32), "rewards": rng.uniform(0, 1, n),
             "discounts": np.ones(n, dtype=np.float32), "ep_id": np.array(i)} for i, n in enumerate((6, 8))]


@pytest.mark.parametrize("overrides", [["agent=taco", "agent.amp=true"], ["agent=spr"], ["agent=atc"], ["agent=bc"],
                                       ["agent=td3bc_taco"], ["agent=cql_taco"], ["agent=iql"],
                                       ["agent=dt", "agent.dt.embed_dim=16", "agent.dt.n_layers=1"]],
                         ids=lambda o: "-".join(x.split("=")[1] for x in o))
def test_update_returns_detached_scalars_without_a_host_sync_from_the_tree(overrides, monkeypatch):
    offline = [] if overrides[0] in ("agent=taco", "agent=spr", "agent=atc") else ["offline.dataset=medium"]
    rc = typed(compose(overrides + offline + ["task=cheetah_run", "profile=tiny", "agent.hidden_dim=32",
                                              "agent.feature_dim=16", "agent.batch_size=4"]))
    torch.manual_seed(0)
    learner = build_learner(rc.agent, OBS, A, "cpu")
    batch = (learner.make_sampler(_episodes(), seed=0).sample(4) if isinstance(learner, SequenceLearner)
             else _batch(rc.agent.K))
    calls: list[str] = []
    for name in SYNCS:
        real = getattr(torch.Tensor, name)

        def watched(self, *args, _real=real, _name=name, **kwargs):
            caller = sys._getframe(1).f_code.co_filename
            if caller.startswith(REPRO):  # torch's own internals (Adam's CPU step count) are not the tree's
                calls.append(f"{_name} at {caller}:{sys._getframe(1).f_lineno}")
            return _real(self, *args, **kwargs)

        monkeypatch.setattr(torch.Tensor, name, watched)
    with DataSizedOps() as ops:
        metrics = learner.update(batch, 0)
    monkeypatch.undo()
    assert not calls and not ops.calls, calls + ops.calls
    assert sorted(metrics) == sorted(learner.metric_names())
    assert all(isinstance(v, torch.Tensor) and v.dim() == 0 and not v.requires_grad for v in metrics.values())


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def test_metric_means_are_the_former_python_float_arithmetic_through_a_checkpoint():
    rng = np.random.default_rng(3)
    updates = [{"a": torch.tensor(v, dtype=torch.float32), "b": torch.tensor(-1e-3 * v, dtype=torch.bfloat16),
                "lr": 1e-4 / (i + 3), "zero": torch.tensor(-0.0)} for i, v in enumerate(rng.normal(size=7) * 1e3)]
    sums: dict[str, float] = {}
    for m in updates:  # the loops' former arithmetic: Python floats of .item(), summed from 0.0, over n
        for k, v in m.items():
            sums[k] = sums.get(k, 0.0) + (v.item() if isinstance(v, torch.Tensor) else v)
    expected = {k: s / len(updates) for k, s in sums.items()}
    means = MetricMeans()
    for m in updates[:4]:
        means.add(m)
    assert _bits(means.means()["a"]) != _bits(expected["a"])  # four updates are not seven
    state = means.state()
    assert all(type(v) is float for v in state["sums"].values())  # a checkpoint holds plain floats
    resumed = MetricMeans()
    resumed.load(state["sums"], state["n"])
    for m in updates[4:]:
        resumed.add(m)
        means.add(m)
    for got in (means.means(), resumed.means()):
        assert list(got) == list(expected)
        assert all(_bits(got[k]) == _bits(expected[k]) for k in expected), (got, expected)
    # Python's 0.0 + -0.0 is 0.0: a sum started from the first value would log -0.0
    assert math.copysign(1.0, means.means()["zero"]) == 1.0
    means.reset()
    assert means.means() == {} and means.n == 0
