"""Before/after record of every learner, for refactors that must not change a number (issue 25).

For each setup (online agents and their objectives, the bf16 autocast path, every offline learner) it builds
the learner at tiny sizes from a fixed seed, runs a few updates on a fixed synthetic batch stream (and a few
``act`` calls), and records the metrics (as Python floats), every state dict (modules and optimizers), the
parameter table, the metric names, what resolved.json would record, the actions and the torch / numpy RNG
state afterwards. ``compare`` checks two records bit for bit (NaN equal to NaN, -0.0 unequal to 0.0).

    PYTHONPATH=<tree> python scripts/learner_equality.py record OUT.pt
    python scripts/learner_equality.py compare BEFORE.pt AFTER.pt
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch

OBS = (9, 32, 32)
A = 6  # cheetah_run
UPDATES = 3
ONLINE_STEP = 5000  # inside the stddev schedule's decay

# name -> overrides (all run under profile=tiny, task=cheetah_run)
SETUPS: dict[str, list[str]] = {
    "taco": ["agent=taco"],
    "drqv2": ["agent=drqv2"],
    "curl": ["agent=curl"],
    "spr": ["agent=spr"],
    "spr_momentum": ["agent=spr", "agent.objective_params.spr.momentum=0.9"],
    "atc": ["agent=atc"],
    "driml": ["agent=driml"],
    "reward": ["agent=taco", "agent.objectives.taco=0", "agent.objectives.curl=0"],
    "taco_amp": ["agent=taco", "agent.amp=true"],
    "taco_no_action_encoder": ["agent=taco", "agent.action_encoder=false"],
    "alix": ["agent=alix"],  # A-LIX: its encoder, critic and loss passed to the backbone as parts (issue 51)
    "alix_variants": ["agent=alix", "agent.alix.input_shift=4", "agent.alix.critic_relu_gain=false",
                      "agent.alix.fixed_batch=false"],
    "alix_taco": ["agent=alix", "agent.action_encoder=true", "+agent.objectives.taco=1.0",
                  "+agent.objectives.curl=1.0", "agent.K=3"],
    "alix_amp": ["agent=alix", "agent.amp=true"],  # bf16 only where repro/agent/numerics.py allows it
    "bc": ["agent=bc"],
    "td3bc": ["agent=td3bc"],
    "td3bc_taco": ["agent=td3bc_taco"],
    "cql": ["agent=cql"],
    "cql_taco": ["agent=cql_taco"],
    "iql": ["agent=iql"],
    "iql_jax": ["agent=iql", "agent.iql.reward_scaling=return_range", "agent.iql.learned_log_std=true",
                "agent.iql.actor_lr_cosine_updates=5", "agent.iql.value_for_targets=before"],
    "dt": ["agent=dt", "agent.dt.context=4", "agent.dt.embed_dim=16", "agent.dt.n_layers=1",
           "agent.dt.batch_size=4", "agent.dt.dropout=0.1", "agent.dt.warmup_steps=2"],
}
OFFLINE = ("bc", "td3bc", "td3bc_taco", "cql", "cql_taco", "iql", "iql_jax", "dt")


def batch(u: int, K: int, B: int = 4) -> dict[str, torch.Tensor]:
    """Update ``u``'s replay batch (every key any learner reads)."""
    g = torch.Generator().manual_seed(1000 + u)

    def frames(*lead: int) -> torch.Tensor:
        return torch.randint(0, 256, (*lead, *OBS), generator=g, dtype=torch.uint8)

    return {"obs": frames(B), "next_obs": frames(B), "future_obs": frames(B), "future_obs_seq": frames(B, K),
            "action": torch.rand(B, A, generator=g) * 2 - 1, "action_seq": torch.rand(B, K, A, generator=g) * 2 - 1,
            "reward": torch.rand(B, 1, generator=g), "discount": torch.full((B, 1), 0.99 ** 3),
            "reward_ksum": torch.rand(B, 1, generator=g) * 3}


def episodes() -> list[dict[str, np.ndarray]]:
    rng = np.random.default_rng(7)
    return [{"frames": rng.integers(0, 256, (n + 1, 3, *OBS[1:]), dtype=np.uint8),
             "actions": rng.uniform(-1, 1, (n, A)).astype(np.float32),
             "rewards": rng.uniform(0, 1, n).astype(np.float32),
             "discounts": np.ones(n, dtype=np.float32), "ep_id": np.array(i)} for i, n in enumerate((9, 6, 11))]


def as_float(v: Any) -> float:
    return float(v.item()) if isinstance(v, torch.Tensor) else float(v)


def run_setup(name: str) -> dict[str, Any]:
    from repro.config.compose import compose, typed
    from repro.learners import EpisodicActor, SequenceLearner, build_learner
    from repro.runs.rundir import resolved_values

    overrides = SETUPS[name] + ["profile=tiny", "task=cheetah_run", "agent.batch_size=4", "agent.hidden_dim=32",
                                "agent.feature_dim=16"]
    if name in OFFLINE:
        overrides.append("offline.dataset=medium")
    rc = typed(compose(overrides))
    torch.manual_seed(0)
    np.random.seed(0)
    learner = build_learner(rc.agent, OBS, A, "cpu", explore_steps=0 if name in OFFLINE else 2)
    if name.startswith("iql"):
        learner.set_dataset_returns([3.0, 11.5, 7.25])  # return_range scaling reads them
    sampler = learner.make_sampler(episodes(), seed=3) if isinstance(learner, SequenceLearner) else None
    metrics = []
    for u in range(UPDATES):
        b = sampler.sample(4) if sampler is not None else batch(u, rc.agent.K)
        step = u if name in OFFLINE else ONLINE_STEP + 2 * u
        metrics.append({k: as_float(v) for k, v in learner.update(b, step).items()})
    obs = np.random.default_rng(5).integers(0, 256, OBS, dtype=np.uint8)
    learner.train(False)
    actions = []
    for step, eval_mode in ((1, True), (ONLINE_STEP, False)):
        if isinstance(learner, EpisodicActor):
            learner.begin_episode()
        actions.append(learner.act(obs, step, eval_mode=eval_mode))
        if isinstance(learner, EpisodicActor):
            learner.observe(actions[-1], 0.5)
    learner.train(True)
    return {"metrics": metrics, "metric_names": list(learner.metric_names()), "state": learner.state_dict(),
            "parameter_counts": list(learner.parameter_counts()), "resolved": resolved_values(rc, learner),
            "sample_options": dict(learner.sample_options), "actions": actions,
            "torch_rng": torch.get_rng_state(), "numpy_rng": np.random.get_state()[1].copy()}


def record(out: Path) -> None:
    torch.set_num_threads(1)
    result = {}
    for name in SETUPS:
        result[name] = run_setup(name)
        print(f"{name}: {len(result[name]['metrics'][0])} metrics", flush=True)
    torch.save(result, out)


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def diff(a: Any, b: Any, where: str = "") -> list[str]:
    """Where ``a`` and ``b`` differ (bit for bit)."""
    if type(a) is not type(b):
        return [f"{where}: type {type(a).__name__} != {type(b).__name__}"]
    if isinstance(a, dict):
        out = [] if list(a) == list(b) else [f"{where}: keys {list(a)} != {list(b)}"]
        for k in a:
            if k in b:
                out += diff(a[k], b[k], f"{where}.{k}")
        return out
    if isinstance(a, (list, tuple)):
        if len(a) != len(b):
            return [f"{where}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in diff(x, y, f"{where}[{i}]")]
    if isinstance(a, torch.Tensor):
        same = (a.dtype == b.dtype and a.shape == b.shape
                and a.reshape(-1).contiguous().view(torch.uint8).equal(b.reshape(-1).contiguous().view(torch.uint8)))
        return [] if same else [f"{where}: tensors differ"]
    if isinstance(a, np.ndarray):
        return [] if a.dtype == b.dtype and a.tobytes() == b.tobytes() else [f"{where}: arrays differ"]
    if isinstance(a, float):
        return [] if _bits(a) == _bits(b) else [f"{where}: {a!r} != {b!r}"]
    return [] if a == b else [f"{where}: {a!r} != {b!r}"]


def compare(before: Path, after: Path) -> int:
    a, b = torch.load(before, weights_only=False), torch.load(after, weights_only=False)
    problems = diff(a, b)
    for p in problems[:40]:
        print(p)
    print(f"{len(a)} setups; " + ("bit for bit equal" if not problems else f"{len(problems)} differences"))
    return 1 if problems else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "record":
        record(Path(sys.argv[2]))
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    else:
        sys.exit(__doc__)
