"""Synthetic run directories (docs/run-format.md) with known values, for the analysis and figure tests.

``write_run`` writes one run whose evaluation return ramps linearly from 0 to ``final`` over
``frames`` (evaluations every ``eval_every`` frames), so the score at the budget is exactly ``final``.
``full_coverage_root`` writes runs for every artifact of ARTIFACTS.md.
"""

from __future__ import annotations

import copy
import functools
import json
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
from omegaconf import DictConfig, OmegaConf

from repro.agent.agent import ACTOR_METRICS, CRITIC_METRICS
from repro.agent.networks import default_latent_action_dim
from repro.config.compose import compose, group_options, typed, validate
from repro.config.schema import is_offline
from repro.data.reference import PAPER_TACO_RETURN, normalized_score, score_reference
from repro.envs import get_task
from repro.runs import rundir, runformat
from repro.runs.logger import format_row, header_line
from repro.runs.video import save_frames as write_frames

METRICS = (*CRITIC_METRICS, *ACTOR_METRICS)  # the online learner's base update metrics (train.csv)
FRAMES = 100_000  # the synthetic frame budget
EVAL_EVERY = 20_000
DMC9 = ["quadruped_run", "hopper_hop", "walker_run", "quadruped_walk", "cheetah_run", "finger_turn_hard",
        "acrobot_swingup", "reacher_hard", "reach_duplo"]
METAWORLD6 = ["hammer", "assembly", "disassemble", "stick-pull", "pick-place-wall", "hand-insert"]
UPDATES = 10_000  # the synthetic offline.updates budget
EVAL_EVERY_UPDATES = 2_000


_DICT_KEYS = ("agent.objectives",)  # dict values, passed through the cache below as JSON text


@functools.cache
def _composed(agent: str, task: str) -> DictConfig:
    return compose([f"agent={agent}", f"task={task}"])


@functools.cache
def _validated(agent: str, task: str, overrides: tuple[tuple[str, Any], ...]) -> DictConfig:
    """The composed config of agent ``agent`` (its agent.name) on ``task`` with dotted ``overrides`` applied in
    struct mode (a key the schema lacks raises) and validated like any training config."""
    agent_file = agent if agent in group_options("agent") else "drqv2"  # an agent without its own file on drqv2
    cfg = copy.deepcopy(_composed(agent_file, task))
    for key, value in (("agent.name", agent), *overrides):
        OmegaConf.update(cfg, key, json.loads(value) if key in _DICT_KEYS else value, merge=False)
    return validate(cfg)


def run_config(agent: str, task: str, seed: int, results_root: Path, **overrides: Any) -> DictConfig:
    """A training config built like ``repro train agent=... task=... key=value ...`` (dotted ``overrides``;
    values None are left at the config's own value)."""
    items = tuple(sorted((k, json.dumps(v) if k in _DICT_KEYS else v) for k, v in overrides.items()
                         if v is not None))
    cfg = copy.deepcopy(_validated(agent, task, items))
    OmegaConf.update(cfg, "seed", seed, merge=False)
    OmegaConf.update(cfg, "runtime.results_root", str(results_root), merge=False)
    return cfg


def resolved_for(cfg: DictConfig, resolved: dict[str, Any] | None = None) -> dict[str, Any]:
    """resolved.json's values for ``cfg``, by the code training uses (rundir.resolved_values) on a learner
    exposing what the Agent exposes: its action encoder's latent dim (the Agent's own default) and weights."""
    rc = typed(cfg)
    encoder = None
    if rc.agent.action_encoder:
        action_dim = get_task(rc.task.name).action_dim + rc.env.distracting_dims
        latent = rc.agent.latent_action_dim or default_latent_action_dim(action_dim, rc.agent.latent_action_rounding)
        encoder = SimpleNamespace(latent_dim=latent)
    weights = {k: float(w) for k, w in rc.agent.objectives.items() if w}
    learner = SimpleNamespace(action_encoder=encoder, weights=weights, resolved=resolved or {})
    return rundir.resolved_values(rc, learner)


def write_run(
    root: Path,
    *,
    experiment: str,
    agent: str,
    task: str,
    seed: int,
    final: float,
    variant: str = "base",
    K: int | None = None,
    batch_size: int | None = None,
    latent_action_dim: int | None = None,
    action_encoder: bool | None = None,
    objectives: dict[str, float] | None = None,
    action_repeat: int | None = None,
    distracting_dims: int = 0,
    frames: int = FRAMES,
    eval_every: int = EVAL_EVERY,
    done: bool = True,
    dataset: str | None = None,
    cql_alpha: float | None = None,
    updates: int = UPDATES,
    eval_every_updates: int = EVAL_EVERY_UPDATES,
    reference: float | None = None,
    fps: float = 50.0,
    device: str = "cpu",
    success: bool = False,
    path: Path | None = None,
    resolved: bool = True,
    resolved_values: dict[str, Any] | None = None,
    curve: Sequence[float] | None = None,
    train_rows: int = 3,
    save_frames: bool = False,
    config: dict[str, Any] | None = None,
) -> Path:
    """Write one run directory and return it. Arguments left None keep the composed config's value; the
    config goes through the training schema, and resolved.json through the code training uses
    (``resolved=False`` leaves it out, like a run written before runs recorded it; ``resolved_values`` are
    written instead, e.g. those of a real Agent).

    An offline agent (conf/agent/td3bc.yaml, cql_taco.yaml, ...; needs ``dataset``) writes the offline format
    instead: ``updates`` and ``eval_every_updates`` are its offline.updates and offline.eval_every_updates, its
    evaluation return ramps from 0 to ``final`` over the updates, normalised by ``reference`` (default: the
    return repro.data.reference falls back to, the paper's TACO return of the task), and ``done`` writes
    DONE as the offline trainer does; ``cql_alpha`` None leaves CQL's alpha to the config (Table 6).
    ``curve``: an online run's evaluation returns at frames 0, eval_every, ... (instead of the ramp to ``final``).
    ``train_rows``: train.csv rows of an online run (one per episode at the paper's scale, benchmarks/).
    ``save_frames``: a done online run also writes its final evaluation episode's frames (frames.npz, by the writer
    training uses) where its config's train.save_frames says so (on by default), as a trained run does; synthetic
    frames of the run's image size, one per action-repeated step of a 500-step episode. ``config``: other dotted
    config values (e.g. ``{"env.max_episode_frames": 100}``). ``agent``: the run's agent.name."""
    cfg = run_config(
        agent, task, seed, root, experiment=experiment, variant=variant, **{
            "agent.K": K, "agent.batch_size": batch_size, "agent.latent_action_dim": latent_action_dim,
            "agent.action_encoder": action_encoder, "agent.objectives": objectives,
            "env.action_repeat": action_repeat, "env.distracting_dims": distracting_dims, "train.frames": frames,
            "offline.dataset": dataset, "agent.cql.alpha": cql_alpha, **({
                "offline.updates": updates, "offline.eval_every_updates": eval_every_updates}
                if dataset is not None else {}), **(config or {})})
    offline = is_offline(str(cfg.agent.learner))
    run = path or rundir.run_dir(cfg)
    run.mkdir(parents=True, exist_ok=True)
    rundir.write_config(run, cfg)
    if resolved:
        # what an offline learner adds (repro/learners/cql.py ``resolved``): the alpha its config resolved
        learner_fields = {"cql_alpha": float(cfg.agent.cql.alpha)} if str(cfg.agent.learner) == "cql" else {}
        rundir.write_resolved(run, resolved_values or resolved_for(cfg, learner_fields))
    meta = {"git_sha": "abc1234", "git_dirty": False, "versions": {"torch": "2.13.0"}, "host": "testhost",
            "device": device, "cpu": "Test CPU", "python": "3.11", "resumes": []}
    (run / runformat.META).write_text(json.dumps(meta))
    if offline:
        ref = (reference, "source") if reference is not None else score_reference(task, None)
        _write_offline_logs(run, final, updates, eval_every_updates, ref, fps)
        if done:
            rundir.write_done(run, {"update": updates, "dataset": str(dataset)})
        return run
    repeat = int(cfg.env.action_repeat)
    lines = [header_line(runformat.EVAL_COLUMNS)]
    for i, frame in enumerate(range(0, frames + 1, eval_every)):
        value = final * frame / frames if curve is None else float(curve[i])
        lines.append(format_row(runformat.EVAL_COLUMNS, {
            "frame": frame, "step": frame // repeat, "episode": i,
            # Meta-world: ``final`` is a success fraction and the return is arbitrary
            "episode_reward": value * 1000 if success else value, "episode_reward_std": 0.0,
            "episode_length": 500, "success": value if success else None, "eval_episodes": 10,
            "total_time": float(i)}))
    (run / runformat.EVAL).write_text("".join(lines))
    columns = runformat.train_columns(METRICS)
    train = [header_line(columns)]
    for i in range(1, train_rows + 1):
        loss = None if i == 1 else 0.5
        train.append(format_row(columns, {
            "frame": i * 1000, "step": i * 500, "episode": i, "episode_reward": 1.0, "episode_length": 500,
            "success": None, "buffer_size": i * 500, "stddev": 0.2, "fps": fps if i > 1 else fps * 10,
            "total_time": float(i), **{m: loss for m in METRICS}}))
    (run / runformat.TRAIN).write_text("".join(train))
    if done and save_frames and bool(cfg.train.save_frames):
        size, steps = int(cfg.env.image_size), 500 // repeat + 1
        t = np.arange(steps, dtype=np.int64)[:, None, None, None]
        yx = np.add.outer(np.arange(size), np.arange(size))[None, :, :, None]
        write_frames(run, ((t * 3 + yx + np.arange(3) * 40 + seed) % 256).astype(np.uint8))
    if done:
        rundir.write_done(run, {"frame": frames})
    return run


def _write_offline_logs(run: Path, final: float, updates: int, eval_every: int, reference: tuple[float | None, str],
                        rate: float) -> None:
    """eval.csv and train.csv in the offline format (repro/runs/runformat.py OFFLINE_*_COLUMNS), as the offline
    trainer writes them: an evaluation at update 0, every ``eval_every`` updates and at ``updates``."""
    points = sorted({*range(0, updates + 1, eval_every), updates})
    lines = [header_line(runformat.OFFLINE_EVAL_COLUMNS)]
    for i, update in enumerate(points):
        value = final * update / updates
        lines.append(format_row(runformat.OFFLINE_EVAL_COLUMNS, {
            "update": update, "episode_reward": value, "episode_reward_std": 0.0, "episode_length": 1000,
            "success": None, "eval_episodes": 10, "normalized_score": normalized_score(value, reference[0]),
            "reference_return": reference[0], "score_reference": reference[1], "total_time": float(i)}))
    (run / runformat.EVAL).write_text("".join(lines))
    columns = [*runformat.OFFLINE_TRAIN_COLUMNS, *METRICS]
    train = [header_line(columns)]
    for i, update in enumerate(points[1:], start=1):
        train.append(format_row(columns, {"update": update, "updates_per_s": rate, "total_time": float(i),
                                          **{m: 0.5 for m in METRICS}}))
    (run / runformat.TRAIN).write_text("".join(train))


def write_encoder_checkpoint(run: Path, true_dim: int = 6, distracting: int = 20, latent: int = 8) -> None:
    """A checkpoint whose action encoder ignores the distracting dims (so latent actions cluster)."""
    import torch

    g = torch.Generator().manual_seed(0)
    w0 = torch.randn(64, true_dim + distracting, generator=g)
    w0[:, true_dim:] = 0.0
    state = {"step.0.weight": w0, "step.0.bias": torch.zeros(64), "step.2.weight": torch.randn(latent, 64, generator=g),
             "step.2.bias": torch.zeros(latent)}
    torch.save({"agent": {"action_encoder": state}}, run / runformat.CHECKPOINT)


def write_run_tsne(run: Path) -> Path:
    """The run's tsne.npz as a trained run writes it at its final evaluation (repro/train/action_tsne.py), from the
    action encoder of its checkpoint, at the frame of its DONE."""
    from analysis.tsne import load_step_mlp
    from repro.train.action_tsne import save_final_tsne

    mlp = load_step_mlp(run / runformat.CHECKPOINT)
    frame = int((rundir.read_done(run) or {})["frame"])
    distracting = int(OmegaConf.load(run / runformat.CONFIG).env.distracting_dims)
    return save_final_tsne(run, mlp, mlp[0].in_features, distracting, frame)


# Per-seed offsets: seeds 0, 1, 2 score final - 10, final, final + 10 (mean final, std 10).
OFFSETS = (-10.0, 0.0, 10.0)


def _seeds(root: Path, n: int, spread: float = 1.0, **kw) -> None:
    for s in range(n):
        write_run(root, seed=s, **{**kw, "final": kw["final"] + spread * OFFSETS[s % 3]})


_ONLINE_SCALE = ("frames", "eval_every", "train_rows", "save_frames")
_OFFLINE_SCALE = ("updates", "eval_every_updates")


def _scaled_run(scale: dict[str, Any], root: Path, **kw: Any) -> Path:
    keys = _OFFLINE_SCALE if kw.get("dataset") is not None else _ONLINE_SCALE
    return write_run(root, **{**{k: v for k, v in scale.items() if k in keys}, **kw})


def _scaled_seeds(scale: dict[str, Any], root: Path, n: int, spread: float = 1.0, **kw: Any) -> None:
    for s in range(n):
        _scaled_run(scale, root, seed=s, **{**kw, "final": kw["final"] + spread * OFFSETS[s % 3]})


def full_coverage_root(root: Path, seeds: int = 2, **scale: Any) -> Path:
    """Runs for every artifact; returns ``root``. Values are chosen so that the claims hold. ``scale``: write_run's
    budget and log-size arguments (``frames``, ``eval_every``, ``train_rows``, ``save_frames``, ``updates``,
    ``eval_every_updates``) for every run, e.g. the paper's scale in benchmarks/report_speed.py; ``save_tsne``: the
    t-SNE run writes its tsne.npz at the paper's settings, as a trained run does (about 25 s)."""
    _seeds = functools.partial(_scaled_seeds, scale)
    write_run = functools.partial(_scaled_run, scale)
    main = {"TACO": 1.4, "DrQ-v2": 1.0, "A-LIX": 0.9}
    for i, task in enumerate(DMC9):
        base = 300 + 40 * i
        k = 1 if task in ("quadruped_run", "walker_run") else 3
        _seeds(root, seeds, experiment="main", agent="taco", task=task, final=base * main["TACO"], K=k)
        _seeds(root, seeds, experiment="main", agent="drqv2", task=task, final=base)
        _seeds(root, seeds, experiment="main", agent="alix", task=task, final=base * main["A-LIX"])
        k3_better = task in ("hopper_hop", "quadruped_walk", "acrobot_swingup", "reacher_hard")
        _seeds(root, seeds, experiment="horizon", agent="taco", task=task, K=1, variant="K1",
               final=base * (1.2 if k3_better else 1.4))
        _seeds(root, seeds, experiment="horizon", agent="taco", task=task, K=3, variant="K3",
               final=base * (1.4 if k3_better else 1.2))
    for task in ["quadruped_run", "walker_run", "hopper_hop", "reacher_hard", "acrobot_swingup"]:
        for agent, f in (("spr", 0.5), ("atc", 0.45), ("driml", 0.55)):
            _seeds(root, seeds, experiment="repr_objectives", agent=agent, task=task, final=300 * f + 100)
    for task in ["quadruped_run", "reacher_hard", "hopper_hop", "walker_run"]:
        _seeds(root, seeds, experiment="action_repr", agent="taco", task=task, action_encoder=False,
               variant="no_action_repr", final=300 + 40 * DMC9.index(task) + 30)
    best = {1: 5, 2: 3, 4: 1}
    for ar in (1, 2, 4):
        for k in (1, 3, 5):
            _seeds(root, seeds, experiment="action_repeat", agent="taco", task="hopper_hop", K=k, action_repeat=ar,
                   variant=f"ar{ar}_K{k}", final=400 if best[ar] == k else 300)
    for b, (ft, fd) in {256: (400, 300), 512: (450, 305), 1024: (500, 300)}.items():
        for agent, final in (("taco", ft), ("drqv2", fd)):
            _seeds(root, seeds, experiment="batch_size", agent=agent, task="quadruped_run", batch_size=b,
                   variant=f"bs{b}", final=final)
    for name, f in (("no_taco", 300), ("no_curl", 400), ("no_reward", 410)):
        obj = {"taco": 1.0, "curl": 1.0, "reward": 1.0}
        obj[name[3:]] = 0.0
        _seeds(root, seeds, experiment="objective_removal", agent="taco", task="quadruped_run", objectives=obj,
               variant=name, final=f)
    for dim, f in ((6, 300), (12, 410), (None, 420), (18, 415), (24, 310)):
        _seeds(root, seeds, experiment="action_dim", agent="taco", task="quadruped_run", latent_action_dim=dim,
               variant=f"dim{dim or 'default'}", final=f)
    for task in METAWORLD6:
        for agent, f in (("taco", 0.8), ("drqv2", 0.5), ("alix", 0.4)):
            _seeds(root, seeds, spread=0.005, experiment="metaworld", agent=agent, task=task, final=f, success=True)
    for s in range(3):
        write_run(root, experiment="manipulator", agent="taco", task="manipulator_bring_ball", seed=s,
                  final=700 if s == 0 else 200)
        write_run(root, experiment="manipulator", agent="drqv2", task="manipulator_bring_ball", seed=s, final=100)
    offline = {"td3bc": 0.6, "td3bc_taco": 0.65, "cql": 0.62, "cql_taco": 0.67, "iql": 0.3, "bc": 0.5, "dt": 0.45}
    for task in ["hopper_hop", "cheetah_run", "walker_run", "quadruped_run"]:
        for ds in ("medium", "medium-replay", "full-replay"):
            for agent, f in offline.items():
                if agent in group_options("agent"):  # dt once conf/agent/dt.yaml exists
                    _seeds(root, seeds, spread=0.1, experiment="offline", agent=agent, task=task, dataset=ds,
                           final=f * PAPER_TACO_RETURN[task])
    tsne = write_run(root, experiment="tsne", agent="taco", task="cheetah_run", seed=0, distracting_dims=20, final=500,
                     latent_action_dim=8)
    write_encoder_checkpoint(tsne)
    if scale.get("save_tsne"):
        write_run_tsne(tsne)
    for agent, b, fps in (("taco", 1024, 10.0), ("taco", 512, 18.0), ("taco", 256, 26.0), ("drqv2", 256, 36.0)):
        write_run(root, experiment="speed", agent=agent, task="quadruped_run", seed=0, batch_size=b, fps=fps,
                  variant=f"bs{b}", final=100)
    bench = root / "bench"
    bench.mkdir(exist_ok=True)
    # a bench file of format 1 (no kind or format, the agent under "algo"), as early versions wrote: still read
    (bench / "cpu.json").write_text(json.dumps({"hardware": "CPU: Bench CPU", "results": [
        {"algo": "taco", "batch_size": 1024, "update_seconds": 0.5, "fps_estimate": 8.0},
        {"algo": "drqv2", "batch_size": 256, "update_seconds": 0.1, "fps_estimate": 30.0}]}))
    return root


def rng_values(seed: int, n: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(0, 1000, n)
