"""`repro dataset make`: medium, medium-replay and full-replay datasets from a recorded online run.

- medium: the policy snapshot whose evaluation return is nearest ``medium_fraction`` x the run's best
  evaluation return (ties: the earliest; its encoder and actor built as the run's learner builds them, in eval
  mode), rolled out with its exploration noise (a truncated-normal sample around the actor's mean with the
  stddev of the schedule at the snapshot's step, as the online actor acts in training after its uniform
  exploration steps) on fresh episode seeds, whole episodes until at least N transitions.
- medium-replay: recorded training episodes that ended at or before that snapshot's step, drawn uniformly
  without replacement (seeded) as whole episodes until at least N transitions.
- full-replay: the same draw over the whole recording.

The dataset is built in a hidden staging folder beside its destination and renamed into place once its
manifest is written and checked, so a killed ``make`` never leaves a dataset that looks complete. A re-run
of the same request continues in the staging folder (``write_dataset``: an episode file already there is
kept when the episode computed again equals it, so files are not rewritten, but the episodes are computed
again: the result is the same for the same seed); a staging folder of another request is removed first.
One ``make`` writes a destination at a time (an flock beside it).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
import yaml
from torch import nn

from repro.config.compose import CONF_DIR, ConfigError, typed
from repro.config.schema import DatasetKind, RunConfig
from repro.data.dataset import MANIFEST, PENDING, DatasetError, check_dataset, load_manifest, write_dataset
from repro.data.record import EPISODES, SNAPSHOTS, load_snapshot, record_dir, snapshot_path, snapshot_steps
from repro.envs import TASKS
from repro.learners import OnlineLearner, build_learner
from repro.runs import rundir
from repro.runs.fsutil import holder_words, try_flock, writable_folder
from repro.train.build import build_env, run_action_dim
from repro.train.common import episode_seed
from repro.train.devices import DeviceError, resolve_device

DEFAULTS_FILE = CONF_DIR / "datasets.yaml"
ROLLOUT_KIND = 2  # episode_seed kind of dataset rollouts (0: training, 1: evaluation)


class MakeError(DatasetError):
    """A source or request that cannot make a dataset, in one line."""


def defaults() -> dict[str, Any]:
    return yaml.safe_load(DEFAULTS_FILE.read_text())


def default_transitions(task: str) -> int:
    sizes = defaults()["transitions"]
    return int(sizes.get(task, sizes["default"]))


def config_hash(identity: dict) -> str:
    """sha256 of a run's identity (its config without ``runtime``), keys sorted."""
    return hashlib.sha256(json.dumps(identity, sort_keys=True, default=str).encode()).hexdigest()


@dataclass(frozen=True)
class RecordedEpisode:
    ep_id: int
    path: Path
    transitions: int
    end_step: int  # agent step at which the episode ended (episodes are consecutive from step 0)
    ret: float


@dataclass(frozen=True)
class Snapshot:
    step: int
    path: Path
    eval_return: float


@dataclass
class Source:
    run_dir: Path
    cfg: RunConfig
    config_hash: str
    episodes: list[RecordedEpisode]
    snapshots: list[Snapshot]
    # the hash a dataset made before config.yaml format 2 recorded for this run (its identity then: every section
    # but runtime and the video switches), so an earlier make of the same request is still found
    legacy_hash: str | None = None

    @property
    def task(self) -> str:
        return self.cfg.task.name

    @property
    def total_transitions(self) -> int:
        return sum(e.transitions for e in self.episodes)

    def describe(self) -> str:
        return (f"{len(self.episodes)} episodes, {self.total_transitions} transitions, "
                f"{len(self.snapshots)} snapshots")


def open_source(run_dir: str | Path, task: str | None = None) -> Source:
    """Read and check a recorded run: its config, contiguous episodes 0..n-1 and snapshots."""
    run_dir = Path(run_dir).expanduser().absolute()
    if not (run_dir / rundir.CONFIG).is_file():
        raise MakeError(f"{run_dir} is not a run directory (no {rundir.CONFIG})")
    try:
        cfg = typed(rundir.saved_config(run_dir))
    except (ConfigError, yaml.YAMLError, ValueError) as exc:
        raise MakeError(f"{run_dir}/{rundir.CONFIG} cannot be read: {exc}") from None
    if task is not None and cfg.task.name != task:
        raise MakeError(f"{run_dir} is a {cfg.task.name} run, not {task}")
    rec = record_dir(run_dir)
    ep_dir = rec / EPISODES
    ids = sorted(int(p.stem[3:]) for p in ep_dir.glob("ep_*.npz")) if ep_dir.is_dir() else []
    if not ids:
        raise MakeError(f"{run_dir} has no recording (no {rec.name}/{EPISODES}/; train with runtime.record=true)")
    missing = sorted(set(range(ids[-1] + 1)) - set(ids))
    if missing:
        raise MakeError(f"{run_dir}: the recording has a gap: {len(ids)} episodes up to id {ids[-1]}, "
                        f"missing {_ids(missing)} (was recording off for part of the run?)")
    done = run_dir / rundir.DONE
    if done.is_file():
        expected = int(json.loads(done.read_text()).get("episode", len(ids)))
        if len(ids) != expected:
            raise MakeError(f"{run_dir}: the recording holds {len(ids)} episodes, the finished run had {expected}")
    episodes, step = [], 0
    for ep_id in ids:
        path = ep_dir / f"ep_{ep_id:07d}.npz"
        try:
            with np.load(path) as z:
                rewards = z["rewards"]
                action_dim = z["actions"].shape[-1]
        except (OSError, ValueError, KeyError) as exc:
            raise MakeError(f"{path}: unreadable episode ({type(exc).__name__}: {exc})") from None
        n = int(len(rewards))
        step += n
        episodes.append(RecordedEpisode(ep_id, path, n, step, float(np.sum(rewards, dtype=np.float64))))
    expected_dim = run_action_dim(cfg) if cfg.task.name in TASKS else None
    if expected_dim is not None and action_dim != expected_dim:
        raise MakeError(f"{run_dir}: recorded actions have {action_dim} dims, {cfg.task.name} has {expected_dim}")
    snaps = []
    for s in snapshot_steps(rec / SNAPSHOTS):
        path = snapshot_path(rec / SNAPSHOTS, s)
        try:
            snaps.append(Snapshot(s, path, float(load_snapshot(path)["eval_return"])))
        except (OSError, RuntimeError, ValueError, KeyError) as exc:
            raise MakeError(f"{path}: unreadable snapshot ({type(exc).__name__})") from None
    ident = rundir.saved_identity(run_dir) or {}
    return Source(run_dir, cfg, config_hash(ident), episodes, snaps, legacy_hash=_legacy_hash(run_dir))


def _legacy_hash(run_dir: Path) -> str | None:
    """config_hash of a format-1 config.yaml as the code before format 2 computed it; None for a newer file."""
    try:
        raw = yaml.safe_load((run_dir / rundir.CONFIG).read_text())
    except (OSError, yaml.YAMLError):
        return None
    if not isinstance(raw, dict) or "format" in raw:
        return None
    raw.pop("runtime", None)
    for key in ("save_video", "video_every", "video_size"):
        (raw.get("train") or {}).pop(key, None)
    return config_hash(raw)


def _ids(ids: list[int]) -> str:
    return ", ".join(map(str, ids[:5])) + (f" and {len(ids) - 5} more" if len(ids) > 5 else "")


def medium_snapshot(source: Source, fraction: float) -> tuple[Snapshot, float]:
    """The snapshot whose eval return is nearest ``fraction`` x the best one (ties: earliest); and the best."""
    if not source.snapshots:
        raise MakeError(f"{source.run_dir}: the recording has no policy snapshots ({source.describe()})")
    best = max(s.eval_return for s in source.snapshots)
    target = fraction * best
    return min(source.snapshots, key=lambda s: (abs(s.eval_return - target), s.step)), best


def draw_episodes(pool: list[RecordedEpisode], n: int, seed: int, what: str) -> list[RecordedEpisode]:
    """Whole episodes drawn uniformly without replacement until at least ``n`` transitions, in id order."""
    have = sum(e.transitions for e in pool)
    if have < n:
        raise MakeError(f"asked for {n} transitions, {what} holds {have} in {len(pool)} episodes "
                        f"(pass --transitions {have} or fewer)")
    order = np.random.default_rng(seed).permutation(len(pool))
    chosen, total = [], 0
    for i in order:
        if total >= n:
            break
        chosen.append(pool[int(i)])
        total += pool[int(i)].transitions
    return sorted(chosen, key=lambda e: e.ep_id)


def _replay_episodes(chosen: list[RecordedEpisode]) -> Iterator[dict[str, np.ndarray]]:
    for i, ep in enumerate(chosen):
        with np.load(ep.path) as z:
            data = {k: z[k] for k in z.files}
        data["ep_id"] = np.array(i)
        yield data


def snapshot_policy(cfg: RunConfig, path: Path, state: dict[str, Any], device: str) -> tuple[nn.Module, nn.Module]:
    """The encoder and actor of a policy snapshot, built as the run's own learner builds them (``agent.learner`` of
    its config: A-LIX's encoder holds its mixing strength, not the plain encoder's weights only) and put in eval mode,
    as the online loop acts (A-LIX: no mixing). MakeError (one line) when the snapshot does not fit that learner."""
    spec = state["policy"]
    shape = cast("tuple[int, int, int]", tuple(int(d) for d in spec["obs_shape"]))
    with torch.random.fork_rng(devices=[]):  # building draws initial weights: leave the caller's generator alone
        learner = build_learner(cfg.agent, shape, int(spec["action_dim"]), device)
    if not isinstance(learner, OnlineLearner):
        raise MakeError(f"{path}: learner {cfg.agent.learner!r} of the run does not act online (no acting modules)")
    modules = dict(learner.acting_modules())
    missing = sorted({"encoder", "actor"} - set(modules)) + sorted(set(modules) - set(state))
    if missing:
        raise MakeError(f"{path}: the snapshot and learner {cfg.agent.learner!r} do not share the acting module(s) "
                        f"{', '.join(missing)}")
    for name, module in modules.items():
        _load_module(path, name, module, state[name])
    return modules["encoder"], modules["actor"]


def _load_module(path: Path, name: str, module: nn.Module, weights: dict[str, torch.Tensor]) -> None:
    """``weights`` into ``module`` (strict), eval mode; MakeError naming the first mismatch."""
    try:
        module.load_state_dict(weights)
    except RuntimeError as exc:
        detail = " ".join(str(exc).split())
        raise MakeError(f"{path}: its {name} does not fit the run's learner: {detail}") from None
    module.train(False)


def _rollouts(source: Source, snap: Snapshot, n: int, seed: int, device: str) -> Iterator[dict[str, np.ndarray]]:
    """Whole episodes of the snapshot's noisy policy until at least ``n`` transitions."""
    state = load_snapshot(snap.path)
    spec = state["policy"]
    encoder, actor = snapshot_policy(source.cfg, snap.path, state, device)
    std = float(state["stddev"])
    rc = source.cfg
    env = build_env(rc, rc.seed + 20_000)
    try:
        total, i = 0, 0
        while total < n:
            noise = torch.Generator().manual_seed(episode_seed(rc.seed, ROLLOUT_KIND + 1, i, seed))
            ts = env.reset(seed=episode_seed(rc.seed, ROLLOUT_KIND, i, seed))
            frames, actions, rewards, discounts = [ts.observation[-3:]], [], [], []
            while not ts.last:
                with torch.no_grad():
                    obs = torch.as_tensor(ts.observation, device=device).float().unsqueeze(0)
                    dist = actor(encoder(obs), std)
                    eps = torch.randn(dist.loc.shape, generator=noise).to(device) * std
                    action = torch.clamp(dist.loc + eps, dist.low + dist.eps, dist.high - dist.eps)
                a = action.cpu().numpy()[0].astype(np.float32)
                ts = env.step(a)
                frames.append(ts.observation[-3:])
                actions.append(a)
                rewards.append(ts.reward)
                discounts.append(ts.discount)
            yield {"ep_id": np.array(i), "frames": np.stack(frames),
                   "actions": np.asarray(actions, dtype=np.float32).reshape(-1, int(spec["action_dim"])),
                   "rewards": np.asarray(rewards, dtype=np.float32),
                   "discounts": np.asarray(discounts, dtype=np.float32)}
            total += len(actions)
            i += 1
    finally:
        env.close()


def results_root_of(run_dir: Path, cfg: RunConfig) -> Path:
    """The results root a run directory sits under ({root}/{experiment}/{agent}/{variant}/{task}/seed_N)."""
    tail = (cfg.experiment, cfg.agent.name, cfg.variant, cfg.task.name, f"seed_{cfg.seed}")
    if len(run_dir.parts) > len(tail) and tuple(run_dir.parts[-len(tail):]) == tail:
        return run_dir.parents[len(tail) - 1]
    raise MakeError(f"cannot tell the results root of {run_dir} from its path; pass --results or --out")


def _check_seed_and_device(seed: int, device: str) -> str:
    """The resolved torch device; MakeError (one line) for a negative seed or a device this machine lacks."""
    if int(seed) < 0:
        raise MakeError(f"--seed must be >= 0 (got {seed})")
    try:
        return resolve_device(device, "--device")
    except DeviceError as exc:
        raise MakeError(str(exc)) from None


@dataclass
class Plan:
    kind: str
    out: Path
    fields: dict[str, Any]  # task, kind, source, rule (write_dataset's keyword arguments)
    episodes: Callable[[], Iterator[dict[str, np.ndarray]]]


def plan(source: Source, kind: str, transitions: int | None = None, medium_fraction: float | None = None,
         seed: int = 0, out: str | Path | None = None, results_root: str | Path | None = None,
         device: str = "auto") -> Plan:
    """Check the request and decide what to write (no file is written)."""
    if kind not in DatasetKind.values():
        raise MakeError(f"unknown kind {kind!r}; one of {', '.join(DatasetKind.values())}")
    dev = _check_seed_and_device(seed, device)
    n = default_transitions(source.task) if transitions is None else int(transitions)
    if n < 1:
        raise MakeError(f"--transitions must be >= 1 (got {n})")
    fraction = float(defaults()["medium_fraction"] if medium_fraction is None else medium_fraction)
    if not 0.0 <= fraction <= 1.0:
        raise MakeError(f"--medium-fraction must be in [0, 1] (got {fraction})")
    if out is None:
        root = Path(results_root).expanduser() if results_root else results_root_of(source.run_dir, source.cfg)
        out = root / "datasets" / source.task / kind
    rule: dict[str, Any] = {"kind": kind, "transitions": n, "seed": int(seed)}
    src: dict[str, Any] = {"run_dir": str(source.run_dir), "config_hash": source.config_hash,
                           "agent": source.cfg.agent.name, "seed": source.cfg.seed,
                           "recorded_episodes": len(source.episodes),
                           "recorded_transitions": source.total_transitions}
    if source.snapshots:
        src["best_return"] = max(s.eval_return for s in source.snapshots)
    if kind in ("medium", "medium-replay"):
        snap, best = medium_snapshot(source, fraction)
        rule["medium_fraction"] = fraction
        src.update({"snapshot_step": snap.step, "snapshot_frame": snap.step * source.cfg.env.action_repeat,
                    "snapshot_return": snap.eval_return, "best_return": best})
    if kind == "medium":
        stddev = float(load_snapshot(snap.path)["stddev"])
        rule.update({"selection": "rollouts of the snapshot policy with its exploration noise, whole episodes "
                                  "until >= transitions", "stddev": stddev,
                     "episode_seeds": f"episode_seed(run seed, {ROLLOUT_KIND}, index, seed)"})
        episodes = lambda: _rollouts(source, snap, n, int(seed), dev)  # noqa: E731
    else:
        if kind == "medium-replay":
            pool = [e for e in source.episodes if e.end_step <= snap.step]
            what = f"the recording before step {snap.step} (the medium snapshot)"
        else:
            pool = source.episodes
            what = "the recording"
        chosen = draw_episodes(pool, n, int(seed), what)
        rule.update({"selection": "whole recorded episodes drawn uniformly without replacement until >= "
                                  "transitions", "pool_episodes": len(pool),
                     "source_episodes": [e.ep_id for e in chosen]})
        episodes = lambda: _replay_episodes(chosen)  # noqa: E731
    fields = {"task": source.task, "kind": kind, "source": src, "rule": rule}
    return Plan(kind, Path(out).expanduser().absolute(), fields, episodes)


def manifest_json(folder: str | Path) -> dict[str, Any]:
    """The manifest of a complete dataset as plain JSON (``load_manifest`` checks it first)."""
    load_manifest(folder)
    return json.loads((Path(folder) / "manifest.json").read_text())


def _same_request(manifest: dict, fields: dict, legacy_hash: str | None = None) -> bool:
    """Whether ``manifest`` records this request; a dataset made before config.yaml format 2 recorded the source
    run's ``legacy_hash`` (its identity then), which counts as the same source."""
    keys = ("task", "kind", "source", "rule")
    recorded = json.loads(json.dumps({k: manifest.get(k) for k in keys}))
    wanted = json.loads(json.dumps({k: fields[k] for k in keys}))
    if legacy_hash is not None and isinstance(recorded.get("source"), dict) \
            and recorded["source"].get("config_hash") == legacy_hash:
        recorded["source"]["config_hash"] = wanted["source"]["config_hash"]
    return recorded == wanted


def _staging_of(staging: Path, fields: dict) -> bool:
    """Whether ``staging`` is a partial (or complete, not yet renamed) write of this very request."""
    for name in (PENDING, MANIFEST):
        try:
            recorded = json.loads((staging / name).read_text())
        except (OSError, ValueError):
            continue
        return isinstance(recorded, dict) and _same_request(recorded, fields)
    return False


@contextmanager
def _make_lock(out: Path) -> Iterator[None]:
    """An flock on ``.{name}.make.lock`` beside ``out``: one ``make`` writes a destination at a time (a second
    refuses in one line naming the first); the kernel releases it when its holder dies; removed on release."""
    out.parent.mkdir(parents=True, exist_ok=True)
    file = out.parent / f".{out.name}.make.lock"
    lock = try_flock(file, {"pid": os.getpid(), "host": socket.gethostname()})
    if lock is None:
        raise MakeError(f"{out} is being made by {holder_words(file)}; wait for it to finish (re-running then finds "
                        "it made)")
    with lock:  # removed while still held: a process that opened it before takes a new one and sees out made
        yield


def make(source_dir: str | Path, kind: str, transitions: int | None = None, medium_fraction: float | None = None,
         seed: int = 0, out: str | Path | None = None, results_root: str | Path | None = None,
         task: str | None = None, device: str = "auto", echo: Callable[[str], None] = print) -> Path:
    """Make (or find already made) the dataset; return its folder. Raises MakeError with one line."""
    _check_seed_and_device(seed, device)
    source = open_source(source_dir, task)
    p = plan(source, kind, transitions, medium_fraction, seed, out, results_root, device)
    if p.out.exists():
        try:
            manifest = manifest_json(p.out)
        except DatasetError:
            if p.out.is_dir() and not any(p.out.iterdir()):
                p.out.rmdir()
            else:
                raise MakeError(f"{p.out} exists and holds no complete dataset; move it away or pass --out") from None
        else:
            if _same_request(manifest, p.fields, source.legacy_hash) and not check_dataset(p.out):
                echo(f"already made: {p.out}")
                return p.out
            raise MakeError(f"{p.out} holds another dataset ({manifest.get('kind')} from "
                            f"{manifest.get('source', {}).get('run_dir')}); move it away or pass --out")
    writable_folder(p.out, "--out" if out is not None else "dataset folder")
    staging = p.out.parent / f".{p.out.name}.partial"
    with _make_lock(p.out):
        if p.out.exists():  # another make finished it while this one waited for the lock
            return make(source_dir, kind, transitions, medium_fraction, seed, out, results_root, task, device, echo)
        if staging.exists() and not _staging_of(staging, p.fields):
            shutil.rmtree(staging)  # left by another request (or killed before it recorded one): start afresh
        write_dataset(staging, p.episodes(), **p.fields)
        manifest = manifest_json(staging)
        problems = check_dataset(staging)
        if problems:
            raise MakeError(f"{staging}: the dataset written fails its check: {problems[0]}")
        staging.rename(p.out)
    echo(f"{kind}: {manifest['transitions']} transitions in {len(manifest['episodes'])} episodes -> {p.out}")
    return p.out
