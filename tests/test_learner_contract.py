"""The learner contract's metrics (issue 25): every learner's ``update`` returns its train.csv columns as detached 0-d
tensors without a host sync from the tree's code (neither a Tensor method that reads a value on the host nor an
operator whose result's size depends on the data, such as indexing with a boolean mask), and the loops' mean of
them (``MetricMeans``) is the same bits as the former Python-float arithmetic, through a checkpoint too."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
import torch

from helpers import host_syncs
from repro.config.compose import compose, typed
from repro.learners import SequenceLearner, build_learner
from repro.train.common import MetricMeans

OBS, A = (9, 32, 32), 6
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
    with host_syncs(monkeypatch) as calls:
        metrics = learner.update(batch, 0)
    assert not calls, calls
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
