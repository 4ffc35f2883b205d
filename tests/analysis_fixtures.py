"""Synthetic run directories (docs/run-format.md) with known values, for the analysis and figure tests.

``write_run`` writes one run whose evaluation return ramps linearly from 0 to ``final`` over
``frames`` (evaluations every ``eval_every`` frames), so the score at the budget is exactly ``final``.
``full_coverage_root`` writes runs for every artifact of ARTIFACTS.md.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import yaml

EVAL_HEADER = "frame,step,episode,episode_reward,episode_reward_std,episode_length,success,eval_episodes,total_time"
TRAIN_HEADER = ("frame,step,episode,episode_reward,episode_length,success,buffer_size,stddev,fps,total_time,"
                "critic_loss,critic_q1,critic_q2,critic_target_q,actor_loss,actor_logprob,actor_ent")
FRAMES = 100_000  # the synthetic frame budget
EVAL_EVERY = 20_000
DMC9 = ["quadruped_run", "hopper_hop", "walker_run", "quadruped_walk", "cheetah_run", "finger_turn_hard",
        "acrobot_swingup", "reacher_hard", "reach_duplo"]
METAWORLD6 = ["hammer", "assembly", "disassemble", "stick-pull", "pick-place-wall", "hand-insert"]


def write_run(
    root: Path,
    *,
    experiment: str,
    algo: str,
    task: str,
    seed: int,
    final: float,
    variant: str = "base",
    suite: str | None = None,
    K: int = 3,
    batch_size: int | None = None,
    latent_action_dim: int | None = None,
    action_encoder: bool = True,
    objectives: dict[str, float] | None = None,
    action_repeat: int = 2,
    distracting_dims: int = 0,
    frames: int = FRAMES,
    eval_every: int = EVAL_EVERY,
    done: bool = True,
    dataset: str | None = None,
    cql_alpha: float | None = None,
    fps: float = 50.0,
    device: str = "cpu",
    success: bool = False,
    path: Path | None = None,
) -> Path:
    """Write one run directory and return it."""
    suite = suite or ("metaworld" if task in METAWORLD6 else "dmc")
    if objectives is None:
        objectives = {"taco": 1.0, "curl": 1.0, "reward": 1.0} if algo == "taco" else {}
    if batch_size is None:
        batch_size = 1024 if algo == "taco" else 256
    run = path or root / experiment / algo / variant / task / f"seed_{seed}"
    run.mkdir(parents=True, exist_ok=True)
    cfg: dict[str, Any] = {
        "experiment": experiment,
        "variant": variant,
        "seed": seed,
        "agent": {"name": algo, "K": K, "batch_size": batch_size, "latent_action_dim": latent_action_dim,
                  "action_encoder": action_encoder, "objectives": objectives},
        "task": {"name": task, "suite": suite},
        "env": {"action_repeat": action_repeat, "distracting_dims": distracting_dims},
        "train": {"frames": frames},
        "runtime": {"results_root": str(root)},
    }
    if dataset is not None:
        cfg["offline"] = {"dataset": dataset}
    if cql_alpha is not None:
        cfg["agent"]["cql_alpha"] = cql_alpha
    (run / "config.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    meta = {"git_sha": "abc1234", "git_dirty": False, "versions": {"torch": "2.13.0"}, "host": "testhost",
            "device": device, "cpu": "Test CPU", "python": "3.11", "resumes": []}
    (run / "meta.json").write_text(json.dumps(meta))
    lines = [EVAL_HEADER]
    for i, frame in enumerate(range(0, frames + 1, eval_every)):
        value = final * frame / frames
        if success:  # ``final`` is a success fraction; the return is arbitrary
            lines.append(f"{frame},{frame // action_repeat},{i},{value * 1000:.6f},0.0,500,{value:.6f},10,{i}")
        else:
            lines.append(f"{frame},{frame // action_repeat},{i},{value:.6f},0.0,500,,10,{i}")
    (run / "eval.csv").write_text("\n".join(lines) + "\n")
    train = [TRAIN_HEADER]
    for i in range(1, 4):
        loss = "" if i == 1 else "0.5"
        train.append(f"{i * 1000},{i * 500},{i},1.0,500,,{i * 500},0.2,{fps if i > 1 else fps * 10},{i},"
                     f"{loss},{loss},{loss},{loss},{loss},{loss},{loss}")
    (run / "train.csv").write_text("\n".join(train) + "\n")
    if done:
        (run / "DONE").write_text(json.dumps({"frame": frames}))
    return run


def write_encoder_checkpoint(run: Path, true_dim: int = 6, distracting: int = 20, latent: int = 8) -> None:
    """A checkpoint whose action encoder ignores the distracting dims (so latent actions cluster)."""
    import torch

    g = torch.Generator().manual_seed(0)
    w0 = torch.randn(64, true_dim + distracting, generator=g)
    w0[:, true_dim:] = 0.0
    state = {"step.0.weight": w0, "step.0.bias": torch.zeros(64), "step.2.weight": torch.randn(latent, 64, generator=g),
             "step.2.bias": torch.zeros(latent)}
    torch.save({"agent": {"action_encoder": state}}, run / "checkpoint.pt")


# Per-seed offsets: seeds 0, 1, 2 score final - 10, final, final + 10 (mean final, std 10).
OFFSETS = (-10.0, 0.0, 10.0)


def _seeds(root: Path, n: int, spread: float = 1.0, **kw) -> None:
    for s in range(n):
        write_run(root, seed=s, **{**kw, "final": kw["final"] + spread * OFFSETS[s % 3]})


def full_coverage_root(root: Path, seeds: int = 2) -> Path:
    """Runs for every artifact; returns ``root``. Values are chosen so that the claims hold."""
    main = {"TACO": 1.4, "DrQ-v2": 1.0, "A-LIX": 0.9}
    for i, task in enumerate(DMC9):
        base = 300 + 40 * i
        k = 1 if task in ("quadruped_run", "walker_run") else 3
        _seeds(root, seeds, experiment="main", algo="taco", task=task, final=base * main["TACO"], K=k)
        _seeds(root, seeds, experiment="main", algo="drqv2", task=task, final=base)
        _seeds(root, seeds, experiment="main", algo="alix", task=task, final=base * main["A-LIX"])
        k3_better = task in ("hopper_hop", "quadruped_walk", "acrobot_swingup", "reacher_hard")
        _seeds(root, seeds, experiment="horizon", algo="taco", task=task, K=1, variant="K1",
               final=base * (1.2 if k3_better else 1.4))
        _seeds(root, seeds, experiment="horizon", algo="taco", task=task, K=3, variant="K3",
               final=base * (1.4 if k3_better else 1.2))
    for task in ["quadruped_run", "walker_run", "hopper_hop", "reacher_hard", "acrobot_swingup"]:
        for algo, f in (("spr", 0.5), ("atc", 0.45), ("driml", 0.55)):
            _seeds(root, seeds, experiment="repr_objectives", algo=algo, task=task, final=300 * f + 100)
    for task in ["quadruped_run", "reacher_hard", "hopper_hop", "walker_run"]:
        _seeds(root, seeds, experiment="action_repr", algo="taco", task=task, action_encoder=False,
               variant="no_action_repr", final=300 + 40 * DMC9.index(task) + 30)
    best = {1: 5, 2: 3, 4: 1}
    for ar in (1, 2, 4):
        for k in (1, 3, 5):
            _seeds(root, seeds, experiment="action_repeat", algo="taco", task="hopper_hop", K=k, action_repeat=ar,
                   variant=f"ar{ar}_K{k}", final=400 if best[ar] == k else 300)
    for b, (ft, fd) in {256: (400, 300), 512: (450, 305), 1024: (500, 300)}.items():
        _seeds(root, seeds, experiment="batch_size", algo="taco", task="quadruped_run", batch_size=b, variant=f"bs{b}", final=ft)
        _seeds(root, seeds, experiment="batch_size", algo="drqv2", task="quadruped_run", batch_size=b, variant=f"bs{b}", final=fd)
    for name, f in (("no_taco", 300), ("no_curl", 400), ("no_reward", 410)):
        obj = {"taco": 1.0, "curl": 1.0, "reward": 1.0}
        obj[name[3:]] = 0.0
        _seeds(root, seeds, experiment="objective_removal", algo="taco", task="quadruped_run", objectives=obj,
               variant=name, final=f)
    for dim, f in ((6, 300), (12, 410), (None, 420), (18, 415), (24, 310)):
        _seeds(root, seeds, experiment="action_dim", algo="taco", task="quadruped_run", latent_action_dim=dim,
               variant=f"dim{dim or 'default'}", final=f)
    for task in METAWORLD6:
        for algo, f in (("taco", 0.8), ("drqv2", 0.5), ("alix", 0.4)):
            _seeds(root, seeds, spread=0.005, experiment="metaworld", algo=algo, task=task, final=f, success=True)
    for s in range(3):
        write_run(root, experiment="manipulator", algo="taco", task="manipulator_bring_ball", seed=s,
                  final=700 if s == 0 else 200)
        write_run(root, experiment="manipulator", algo="drqv2", task="manipulator_bring_ball", seed=s, final=100)
    offline = {"td3bc": 0.6, "cql": 0.62, "iql": 0.3, "bc": 0.5, "dt": 0.45}
    for task in ["hopper_hop", "cheetah_run", "walker_run", "quadruped_run"]:
        for ds in ("medium", "medium_replay", "full_replay"):
            for algo, f in offline.items():
                top = 300 * 1.4
                _seeds(root, seeds, experiment="offline", algo=algo, task=task, dataset=ds, variant=ds,
                       objectives={}, final=f * top, cql_alpha=0.5 if algo == "cql" else None)
                if algo in ("td3bc", "cql"):
                    _seeds(root, seeds, experiment="offline", algo=algo, task=task, dataset=ds, variant=f"{ds}_taco",
                           objectives={"taco": 1.0}, final=(f + 0.05) * top, cql_alpha=0.5 if algo == "cql" else None)
    tsne = write_run(root, experiment="tsne", algo="taco", task="cheetah_run", seed=0, distracting_dims=20, final=500)
    write_encoder_checkpoint(tsne)
    for algo, b, fps in (("taco", 1024, 10.0), ("taco", 512, 18.0), ("taco", 256, 26.0), ("drqv2", 256, 36.0)):
        write_run(root, experiment="speed", algo=algo, task="quadruped_run", seed=0, batch_size=b, fps=fps,
                  variant=f"bs{b}", final=100)
    bench = root / "bench"
    bench.mkdir(exist_ok=True)
    (bench / "cpu.json").write_text(json.dumps({"hardware": "CPU: Bench CPU", "results": [
        {"algo": "taco", "batch_size": 1024, "update_seconds": 0.5, "fps_estimate": 8.0},
        {"algo": "drqv2", "batch_size": 256, "update_seconds": 0.1, "fps_estimate": 30.0}]}))
    return root


def rng_values(seed: int, n: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0, 1000, n)
