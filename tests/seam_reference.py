"""A fixed-seed record of a few online agent updates (losses, actions, every parameter and optimizer state).

Shared by tests/make_seam_fixture.py (which writes tests/data/online_updates.json) and tests/test_seam.py
(which recomputes it with today's code and compares with a tolerance). No environment is needed: the replay
is filled with random frames.

Why a tolerance: the same torch computes other last bits on another CPU (oneDNN and ATen pick AVX2 or
AVX-512 kernels, so float sums run in another order); a record from disk can only be compared up to that
noise. Bit-identity is checked where it is a property of one process (tests/test_seam.py runs the record
twice side by side; resume, compile and amp have their own in-process checks). Each tensor is kept as four
float64 summaries (sum, sum of |x|, sum of x^2, and a sum weighted by fixed random signs, which moves when
any single element moves), so the record stays small while every element counts.
"""

from __future__ import annotations

import platform
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from repro.config.compose import compose, typed
from repro.data.replay import ReplayBuffer
from repro.train import build

AGENTS = ("taco", "drqv2")
UPDATES = 3
EPISODES, EPISODE_STEPS = 3, 12
# Tolerances, relative to a scale: |want| for a metric or an action (at least FLOOR), a tensor's sum of |x|
# for its sums (its sum of x^2 for that one). Measured on torch 2.13.0+cpu, AVX2 against AVX-512 kernels
# (ATEN_CPU_CAPABILITY=avx2 ONEDNN_MAX_CPU_ISA=AVX2 against the default on an AVX-512 CPU), worst over both
# agents after three updates: metrics 1.9e-6, actions 5.2e-5, parameters 5.6e-4, optimizer state 2.8e-3
# (a few near-zero encoder gradients flip the sign of Adam's first step). Dropping the target-noise clip
# moves them by 0.27, 7.3, 0.23 and 0.78: the metrics and actions carry a margin of three orders of
# magnitude over their tolerance, the state summaries (coarser) one order. tests/test_seam.py checks both.
RTOL = {"metrics": 1e-4, "actions": 1e-3, "parameters": 1e-2, "optimizer": 5e-2}
FLOOR = {"metrics": 1e-3, "actions": 1e-3, "parameters": 1e-12, "optimizer": 1e-12}


def capability() -> str:
    """The CPU kernel family torch runs here (e.g. AVX2, AVX512): what decides the last bits."""
    return str(torch.backends.cpu.get_cpu_capability())


def _summary(t: torch.Tensor) -> list[float]:
    x = t.detach().cpu().double().flatten()
    signs = torch.randint(0, 2, (x.numel(),), generator=torch.Generator().manual_seed(x.numel()),
                          dtype=torch.float64) * 2 - 1
    return [float(x.sum()), float(x.abs().sum()), float((x * x).sum()), float((x * signs).sum())]


def _flat(prefix: str, obj: Any, out: dict[str, Any]) -> None:
    """Summaries of every tensor in a nested state dict, keyed by its dotted path (other values by repr)."""
    if isinstance(obj, torch.Tensor):
        out[prefix] = _summary(obj)
    elif isinstance(obj, dict):
        for k in sorted(obj, key=str):
            _flat(f"{prefix}.{k}" if prefix else str(k), obj[k], out)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _flat(f"{prefix}.{i}", v, out)
    else:
        out[prefix] = repr(obj)


def record(agent_name: str, overrides: Sequence[str] = ()) -> dict:
    """Build the agent from its config (profile=tiny), fill a replay with random frames, run a few updates."""
    torch.set_num_threads(1)
    cfg = compose([f"agent={agent_name}", "profile=tiny", "task=cheetah_run", "seed=5", *overrides])
    rc = typed(cfg)
    obs_shape = (3 * rc.env.frame_stack, rc.env.image_size, rc.env.image_size)
    action_dim = 6
    agent = build.build_run_learner(rc, obs_shape, action_dim, "cpu")
    buffer = ReplayBuffer(rc.replay.capacity, (3, *obs_shape[1:]), action_dim, rc.env.frame_stack,
                          rc.agent.nstep, rc.agent.K, rc.agent.discount, seed=rc.seed)
    rng = np.random.default_rng(123)
    for _ in range(EPISODES):
        buffer.start_episode(rng.integers(0, 256, (3, *obs_shape[1:]), dtype=np.uint8))
        for _ in range(EPISODE_STEPS):
            buffer.add(rng.uniform(-1, 1, action_dim).astype(np.float32), float(rng.normal()), 1.0,
                       rng.integers(0, 256, (3, *obs_shape[1:]), dtype=np.uint8))
        buffer.end_episode()
    obs = rng.integers(0, 256, obs_shape, dtype=np.uint8)
    out: dict = {"metrics": [], "actions": [],
                 "parameter_counts": [list(r) for r in agent.parameter_counts()],
                 "metric_names": list(agent.metric_names())}
    step = 2000
    for i in range(UPDATES):
        batch = buffer.sample(rc.agent.batch_size, **agent.sample_options)
        out["metrics"].append({k: float(v) for k, v in agent.update(batch, step + i).items()})
        out["actions"].append([agent.act(obs, step + i, eval_mode=False).tolist(),
                               agent.act(obs, step + i, eval_mode=True).tolist()])
    state: dict[str, Any] = {}
    _flat("", agent.state_dict(), state)
    out["state"] = state
    return out


def written_by() -> dict[str, str]:
    """What decides the last bits of a record: torch's version and the CPU kernels it ran."""
    return {"torch": torch.__version__, "cpu_capability": capability(), "machine": platform.machine()}


def record_all() -> dict:
    return {"written_by": written_by(), **{name: record(name) for name in AGENTS}}


def deviation(got: dict, want: dict) -> dict[str, tuple[float, str]]:
    """Per kind of number (metrics, actions, parameters, optimizer state): the largest
    |got - want| / (RTOL[kind] * scale) and where it is; 1.0 is the tolerance. Structure (names, counts,
    state keys, non-tensor state) must be equal: AssertionError otherwise."""
    assert got["parameter_counts"] == want["parameter_counts"], "parameter counts differ"
    assert got["metric_names"] == want["metric_names"], "metric names differ"
    assert sorted(got["state"]) == sorted(want["state"]), "state dict keys differ"
    worst: dict[str, tuple[float, str]] = {kind: (0.0, "") for kind in RTOL}

    def check(kind: str, g: float, w: float, scale: float, name: str) -> None:
        d = abs(g - w) / (RTOL[kind] * max(abs(scale), FLOOR[kind]))
        if not d <= worst[kind][0]:  # NaN counts as the worst
            worst[kind] = (d if d == d else float("inf"), name)

    assert len(got["metrics"]) == len(want["metrics"]) == len(got["actions"]) == len(want["actions"])
    for i, (gm, wm) in enumerate(zip(got["metrics"], want["metrics"])):
        assert sorted(gm) == sorted(wm), f"update {i}: metric keys differ"
        for k in wm:
            check("metrics", gm[k], wm[k], wm[k], f"metrics[{i}].{k}")
    for i, (ga, wa) in enumerate(zip(got["actions"], want["actions"])):
        for mode, (gv, wv) in enumerate(zip(ga, wa)):
            for j, (g, w) in enumerate(zip(gv, wv)):
                check("actions", g, w, w, f"actions[{i}][{'eval' if mode else 'explore'}][{j}]")
    for key, w in want["state"].items():
        g = got["state"][key]
        if isinstance(w, str):
            assert g == w, f"{key}: {g} != {w}"
            continue
        kind = "optimizer" if key.startswith("optimizers.") else "parameters"
        for idx, name in enumerate(("sum", "abs", "sq", "signed")):
            check(kind, g[idx], w[idx], w[2] if name == "sq" else w[1], f"{key}[{name}]")
    return worst
