"""The run directory format (docs/run-format.md), defined once.

File names, CSV columns per file, run states, the config keys that identify a run and the resolved
values a run records about itself. Training (logger, rundir, api), sweeps (launch/status), analysis
(analysis/load) and the test fixtures all read these names from here. This module only names things
and reads small files; it imports nothing heavier than the standard library and the config layer.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from repro.config.compose import is_folder_value
from repro.config.errors import UserError

# ---------------------------------------------------------------- file names
CONFIG = "config.yaml"  # the resolved config, identity of the run (atomic, at start)
META = "meta.json"  # provenance: git sha, versions, host, device, command, resumes (atomic)
RESOLVED = "resolved.json"  # values the learner actually used (atomic, at start): RESOLVED_FIELDS
EVAL = "eval.csv"  # one row per evaluation: EVAL_COLUMNS
TRAIN = "train.csv"  # one row per training episode: TRAIN_COLUMNS + the learner's metric names
CHECKPOINT = "checkpoint.pt"  # state for resume (atomic replace)
DONE = "DONE"  # written last: the run reached its budget
FRAMES = "frames.npz"  # the final evaluation's first episode (trajectory figures)
TSNE = "tsne.npz"  # the final action encoder's F6 t-SNE embedding (runs with distracting action dims)
REPLAY = "replay"  # folder of replay episodes, so that a resume does not rewrite the buffer
TB = "tb"  # runtime.tensorboard: TensorBoard event files mirroring eval.csv and train.csv (repro/runs/tblog.py)
WANDB = "wandb"  # runtime.wandb: the W&B run id and the offline W&B run folder mirroring the CSVs (repro/runs/wblog.py)
VIDEOS = "videos"  # train.save_video: frame_XXXXXXXXX.mp4 (offline: update_...) per evaluation (repro/runs/video.py)
WRITER_LOCK = ".writer.lock"  # flock()ed by the one process writing the run, naming it; removed on release (rundir.py)

# ---------------------------------------------------------------- CSV columns
EVAL_COLUMNS = ("frame", "step", "episode", "episode_reward", "episode_reward_std", "episode_length", "success",
                "eval_episodes", "total_time")
TRAIN_COLUMNS = ("frame", "step", "episode", "episode_reward", "episode_length", "success", "buffer_size",
                 "stddev", "fps", "total_time")  # followed by the learner's metric names
WALLCLOCK_COLUMNS = ("total_time", "fps")  # every other column is deterministic on CPU
EVAL_REQUIRED = ("frame", "step", "episode", "episode_reward")  # a readable eval.csv has at least these
TRAIN_REQUIRED = ("frame", "fps")  # a readable train.csv has at least these


# Offline runs (a learner trained from offline.dataset): one eval row per evaluation, one train row every
# offline.log_every_updates updates. normalized_score = 100 x episode_reward / reference_return, the reference
# being the dataset source run's best evaluation return (score_reference "source") or the paper's Table 1
# TACO value for the task ("paper"); "none" when neither is known.
OFFLINE_EVAL_COLUMNS = ["update", "episode_reward", "episode_reward_std", "episode_length", "success",
                        "eval_episodes", "normalized_score", "reference_return", "score_reference", "total_time"]
OFFLINE_TRAIN_COLUMNS = ["update", "updates_per_s", "total_time"]  # followed by the learner's metric names
# A return-conditioned learner (Decision Transformer; agent.protocol.ReturnConditioned) is evaluated twice on the
# same episode seeds: at the best online return (the columns above: target_return, target_reference 'source' or
# 'paper' as score_reference, or 'dataset' when neither is known) and at the dataset's best episode return
# (dataset_target_return and the *_dataset_target columns; normalised by the same reference_return).
RETURN_TARGET_EVAL_COLUMNS = ["target_return", "target_reference", "dataset_target_return",
                              "episode_reward_dataset_target", "episode_reward_std_dataset_target",
                              "normalized_score_dataset_target"]
OFFLINE_WALLCLOCK_COLUMNS = ("total_time", "updates_per_s")
OFFLINE_EVAL_REQUIRED = ("update", "episode_reward")  # a readable offline eval.csv has at least these
OFFLINE_EVAL_TEXT = ("score_reference",)  # the offline eval.csv's one text column (normalized_score may be empty)
OFFLINE_TRAIN_REQUIRED = ("update", "updates_per_s")  # a readable offline train.csv has these


def offline_eval_columns(return_conditioned: bool = False) -> list[str]:
    """The header of an offline run's eval.csv (a return-conditioned learner adds its target columns)."""
    return OFFLINE_EVAL_COLUMNS + (RETURN_TARGET_EVAL_COLUMNS if return_conditioned else [])


def train_columns(metric_names: Sequence[str]) -> list[str]:
    """The header of train.csv for a learner with these metric names."""
    return [*TRAIN_COLUMNS, *metric_names]


# ---------------------------------------------------------------- run states
STATE_DONE, STATE_PARTIAL, STATE_ABSENT = "done", "partial", "absent"


def read_done(path: str | Path) -> dict | None:
    """The run's DONE file as JSON (None when the run has none or it is unreadable)."""
    try:
        data = json.loads((Path(path) / DONE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def reached_budgets(path: str | Path) -> list[int]:
    """Every budget the run has reached (frames online, updates offline), ascending: meta.json's ``budgets``
    (format 2) and the DONE file's ``frame`` / ``update`` (any format)."""
    reached: set[int] = set()
    try:
        meta = json.loads((Path(path) / META).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        meta = {}
    for entry in (meta.get("budgets") or []) if isinstance(meta, dict) else []:
        if isinstance(entry, dict) and _is_int(entry.get("budget")):
            reached.add(int(entry["budget"]))
    done = read_done(path)
    if done is not None:
        value = done.get("frame", done.get("update"))
        if isinstance(value, int) and not isinstance(value, bool):
            reached.add(value)
    return sorted(reached)


def run_state(path: str | Path, budget: int | None = None) -> str:
    """``done``, ``partial`` (a config or checkpoint: resumable) or ``absent``.

    Without ``budget``: done iff DONE exists (the run reached the budget it was last started with). With one (frames
    online, updates offline): done iff the run has reached that budget or a larger one, even while it is being
    extended beyond it; a DONE run of a smaller budget is ``partial`` (a start extends it)."""
    path = Path(path)
    done = (path / DONE).exists()
    if budget is None and done:
        return STATE_DONE
    if budget is not None and (done or (path / META).exists()):
        reached = reached_budgets(path)
        if reached and reached[-1] >= budget:
            return STATE_DONE
    if done or (path / CHECKPOINT).exists() or (path / CONFIG).exists():
        return STATE_PARTIAL
    return STATE_ABSENT


# ---------------------------------------------------------------- identity
# The run directory is {runtime.results_root}/{experiment}/{agent.name}/{variant}/{task.name}/seed_{seed}.


def run_path(results_root: str | Path, experiment: str, agent: str, variant: str, task: str, seed: int,
             dataset: str | None = None) -> Path:
    """The run directory of these identity values (no timestamps: the same command finds the same folder).
    Offline runs (a ``dataset``) have one more component, ``{task}/{dataset_tag}/seed_{seed}``."""
    task_dir = Path(results_root) / str(experiment) / str(agent) / str(variant) / str(task)
    if dataset is not None:
        task_dir = task_dir / dataset_tag(dataset)
    return task_dir / f"seed_{seed}"


def dataset_tag(value: str) -> str:
    """Run directory component of ``offline.dataset``: a kind (``medium``) as is; a folder: its name and the
    first 8 hex digits of the sha256 of the value (``84px-1a2b3c4d``), so two folders never share one. The config
    turns a folder value into its absolute real path first (repro/config/compose.py), so every spelling of one folder
    gives one tag, and an absolute real path gives the tag it always had."""
    if not is_folder_value(value):
        return value
    name = re.sub(r"[^A-Za-z0-9_.\-]", "_", Path(value.rstrip("/")).name) or "dataset"
    return f"{name}-{hashlib.sha256(value.encode()).hexdigest()[:8]}"


# Identity columns of analysis tables read from config.yaml: column -> dotted config key.
IDENTITY_KEYS: dict[str, str] = {
    "experiment": "experiment",
    "variant": "variant",
    "agent": "agent.name",
    "task": "task.name",
    "suite": "task.suite",
    "seed": "seed",
    "distracting_dims": "env.distracting_dims",
    "train_frames": "train.frames",
}

# ---------------------------------------------------------------- resolved values (resolved.json)
RESOLVED_FORMAT = 1
# Values a run records about what it actually used; analysis reads them and never recomputes them.
#   learner            agent.learner that trained the run
#   K, batch_size, nstep, action_repeat   the values in effect
#   action_encoder     whether the learner has an action encoder
#   latent_action_dim  size of one latent action of that encoder (None without one)
#   objectives         active auxiliary objectives -> weight (zero weights left out)
#   dataset            offline dataset the learner trained from (None for online learners)
#   cql_alpha          CQL's alpha actually used (None unless the learner uses one)
RESOLVED_FIELDS = ("learner", "K", "batch_size", "action_repeat", "nstep", "action_encoder", "latent_action_dim",
                   "objectives", "dataset", "cql_alpha")
# Where a run written before resolved.json existed keeps each value in its config.yaml. Analysis falls back
# to these (and marks the run) instead of recomputing anything from a formula.
RESOLVED_CONFIG_KEYS: dict[str, str] = {
    "learner": "agent.learner",
    "K": "agent.K",
    "batch_size": "agent.batch_size",
    "action_repeat": "env.action_repeat",
    "nstep": "agent.nstep",
    "action_encoder": "agent.action_encoder",
    "latent_action_dim": "agent.latent_action_dim",
    "objectives": "agent.objectives",
    "dataset": "offline.dataset",
    "cql_alpha": "agent.cql.alpha",
}
_INT_FIELDS = ("K", "batch_size", "action_repeat", "nstep")


class ResolvedError(UserError, ValueError):
    """A resolved.json (or the values meant for one) does not follow the format."""


def check_resolved(values: Mapping[str, Any]) -> dict[str, Any]:
    """``values`` as a plain dict after checking every RESOLVED_FIELDS entry; extra keys are kept as they are."""
    missing = [k for k in RESOLVED_FIELDS if k not in values]
    if missing:
        raise ResolvedError(f"missing field(s) {', '.join(missing)}")
    out = dict(values)
    for key in _INT_FIELDS:
        if not _is_int(out[key]) or out[key] < 1:
            raise ResolvedError(f"{key} must be a positive integer (got {out[key]!r})")
    if out["learner"] is None or not isinstance(out["learner"], str) or not out["learner"]:
        raise ResolvedError(f"learner must be a name (got {out['learner']!r})")
    if not isinstance(out["action_encoder"], bool):
        raise ResolvedError(f"action_encoder must be true or false (got {out['action_encoder']!r})")
    dim = out["latent_action_dim"]
    if out["action_encoder"] != (dim is not None) or (dim is not None and (not _is_int(dim) or dim < 1)):
        raise ResolvedError(f"latent_action_dim must be a positive integer with an action encoder and null "
                            f"without one (action_encoder {out['action_encoder']}, got {dim!r})")
    objectives = out["objectives"]
    if not isinstance(objectives, Mapping) or not all(
            isinstance(k, str) and _is_number(w) and w != 0 for k, w in objectives.items()):
        raise ResolvedError(f"objectives must map names to non-zero weights (got {objectives!r})")
    out["objectives"] = {str(k): float(w) for k, w in objectives.items()}
    if out["dataset"] is not None and not isinstance(out["dataset"], str):
        raise ResolvedError(f"dataset must be a name or null (got {out['dataset']!r})")
    if out["cql_alpha"] is not None and not _is_number(out["cql_alpha"]):
        raise ResolvedError(f"cql_alpha must be a number or null (got {out['cql_alpha']!r})")
    return out


def resolved_json(values: Mapping[str, Any]) -> str:
    """The text of resolved.json for ``values`` (checked), with the format number."""
    return json.dumps({"format": RESOLVED_FORMAT, **check_resolved(values)}, indent=2, sort_keys=False) + "\n"


def read_resolved(path: str | Path) -> dict[str, Any]:
    """The resolved values of the run directory ``path``; FileNotFoundError if it has none, ResolvedError if
    the file is malformed."""
    file = Path(path) / RESOLVED
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise ResolvedError(f"not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ResolvedError("not a JSON object")
    if data.get("format") != RESOLVED_FORMAT:
        raise ResolvedError(f"format {data.get('format')!r}, expected {RESOLVED_FORMAT}")
    data.pop("format")
    return check_resolved(data)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
