"""Walk a results root, validate every run directory (docs/run-format.md) and build tidy tables.

A run directory is any folder holding ``config.yaml`` (format: repro/runs/runformat.py). Identity columns come
from the config and from the values the run recorded in ``resolved.json``, never from the path and never
recomputed. A malformed or truncated CSV is reported as a :class:`Problem` (with its path) and
skipped; loading never raises because of one bad run.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException
from pandas.api.types import is_numeric_dtype, is_object_dtype

from analysis.cache import file_signature, lookup
from analysis.identity import agent_key, enabled_objectives, method_label
from analysis.plaincsv import plain_columns
from repro.bench.results import BenchFile, BenchFormatError, path_of
from repro.bench.results import read as read_bench
from repro.config.compose import ABSENT, get_key
from repro.config.errors import UserError
from repro.config.schema import normalize_dataset
from repro.runs.migrate import migrate_config
from repro.runs.runformat import (
    CONFIG,
    EVAL,
    EVAL_COLUMNS,
    EVAL_REQUIRED,
    IDENTITY_KEYS,
    META,
    OFFLINE_EVAL_COLUMNS,
    OFFLINE_EVAL_REQUIRED,
    OFFLINE_EVAL_TEXT,
    OFFLINE_TRAIN_REQUIRED,
    REPLAY,
    RESOLVED,
    RESOLVED_CONFIG_KEYS,
    RESOLVED_FIELDS,
    TRAIN,
    TRAIN_REQUIRED,
    ResolvedError,
    reached_budgets,
    read_resolved,
    run_state,
)
from repro_data import PUBLISHED_DIR

# Identity columns of every row of the tidy tables (run_id is the run directory relative to the root):
# the config's identity keys and the run's resolved values (repro/runs/runformat.py), plus labels and status.
IDENTITY = (
    "run_id",
    "experiment",
    "variant",
    "agent",
    "method",
    "task",
    "suite",
    "seed",
    "learner",
    "K",
    "batch_size",
    "nstep",
    "latent_action_dim",
    "action_encoder",
    "objectives",
    "action_repeat",
    "distracting_dims",
    "max_episode_frames",
    "camera",
    "train_frames",
    "dataset",
    "cql_alpha",
    "offline_updates",
    "status",
)
# The eval table's columns: an online run fills EVAL_COLUMNS, an offline run (a dataset) OFFLINE_EVAL_COLUMNS;
# each leaves the other's columns empty (an offline run has no frame, an online one no update).
EVAL_TABLE_COLUMNS = (*EVAL_COLUMNS, *(c for c in OFFLINE_EVAL_COLUMNS if c not in EVAL_COLUMNS))
RESOLVED_FROM_FILE, RESOLVED_FROM_CONFIG = RESOLVED, CONFIG  # the runs table's ``resolved_from`` values
# The ``source`` column of the runs and eval tables: the user's runs, or the DrQ-v2 authors' published curves
# (:func:`load_published`). The two are loaded separately and never concatenated.
SOURCE_RUNS, SOURCE_PUBLISHED = "runs", "published"
PUBLISHED_EXPERIMENT = "published"
PUBLISHED_REQUIRED = ("agent", "task", "seed", "frame", "episode_reward")
PUBLISHED_ACTION_REPEAT = 2  # the DrQ-v2 authors' DMC setting; their ``frame`` counts frames after it
_SKIP_DIRS = {REPLAY, "__pycache__", ".git"}


@dataclass(frozen=True)
class Problem:
    """Something wrong with one file; the file (or run) was skipped or partly used."""

    path: str
    message: str
    level: str = "error"  # "error": skipped; "warning": used with a caveat

    def __str__(self) -> str:
        return f"{self.level}: {self.path}: {self.message}"


@dataclass
class Results:
    """Everything loaded from one results root.

    Attributes:
        root: the results root.
        runs: one row per valid run: identity columns, status, ``resolved_from`` (``resolved.json``, or
            ``config.yaml`` for a run that predates it), number of eval rows, last eval frame (online) or
            update (offline: ``last_update``, its budget ``offline_updates`` from its config), median
            training FPS (online) or updates per second (offline), provenance (git sha, device, host, cpu,
            versions).
        eval: one row per evaluation: identity columns + the eval.csv columns (EVAL_TABLE_COLUMNS).
        problems: every file that was skipped or is suspicious.
        benches: the ``{root}/bench/*.json`` files (repro/bench/results.py's :class:`BenchFile`, with its ``path``).
    """

    root: Path
    runs: pd.DataFrame
    eval: pd.DataFrame
    problems: list[Problem] = field(default_factory=list)
    benches: list[BenchFile] = field(default_factory=list)

    @property
    def empty(self) -> bool:
        return self.runs.empty


class ResultsRootError(UserError, FileNotFoundError):
    """The results root does not exist or is not a directory."""


def _get(cfg: dict[str, Any], dotted: str, default: Any = None) -> Any:
    value = get_key(cfg, dotted)
    return default if value is ABSENT else value


def identity_from_config(cfg: dict[str, Any]) -> dict[str, Any]:
    """The identity columns a run's resolved config gives (runformat.IDENTITY_KEYS), without resolved values."""
    ident = {col: _get(cfg, key) for col, key in IDENTITY_KEYS.items()}
    return {
        "experiment": str(ident["experiment"] or ""),
        "variant": str(ident["variant"] or "base"),
        "agent": agent_key(ident["agent"]) if ident["agent"] is not None else None,
        "task": ident["task"],
        "suite": ident["suite"],
        "seed": _int_or_none(ident["seed"]),
        "distracting_dims": _int_or_none(ident["distracting_dims"]) or 0,
        # the environment beside the paper's (analysis/comparable.py labels a run whose episodes or camera differ)
        "max_episode_frames": _int_or_none(_get(cfg, "env.max_episode_frames")),
        "camera": _text_or_none(_get(cfg, "env.camera")),
        "train_frames": _int_or_none(ident["train_frames"]),
        "offline_updates": None,
    }


def resolved_from_config(cfg: dict[str, Any]) -> dict[str, Any]:
    """For a run without resolved.json: each resolved value as its config.yaml states it
    (runformat.RESOLVED_CONFIG_KEYS), nothing recomputed; a null latent dim stays unknown (None)."""
    values = {field: _get(cfg, key) for field, key in RESOLVED_CONFIG_KEYS.items()}
    objectives = values["objectives"] if isinstance(values["objectives"], dict) else {}
    values["objectives"] = {k: w for k, w in objectives.items() if k in enabled_objectives(objectives)}
    if values["learner"] is None:  # configs written before agent.learner existed: the online learner
        values["learner"] = "actor_critic"
    if not values["action_encoder"]:
        values["latent_action_dim"] = None
    return values


def resolved_columns(values: dict[str, Any], agent: Any) -> dict[str, Any]:
    """The identity columns of a run's resolved values (runformat.RESOLVED_FIELDS); ``agent``: its agent.name."""
    objectives = enabled_objectives(values.get("objectives") or {})
    encoder = values.get("action_encoder")
    return {
        "learner": values.get("learner"),
        "K": _int_or_none(values.get("K")),
        "batch_size": _int_or_none(values.get("batch_size")),
        "nstep": _int_or_none(values.get("nstep")),
        "latent_action_dim": _int_or_none(values.get("latent_action_dim")),
        "action_encoder": None if encoder is None else bool(encoder),
        "objectives": "+".join(objectives),
        "method": _method(values, agent, objectives),
        "action_repeat": _int_or_none(values.get("action_repeat")),
        "dataset": normalize_dataset(values.get("dataset")),
        "cql_alpha": _float_or_none(values.get("cql_alpha")),
    }


def _method(values: dict[str, Any], agent: Any, objectives: tuple[str, ...]) -> str | None:
    """The paper's label, from what the run trained: its learner and its enabled objectives (``td3bc_taco`` trains
    learner td3bc with TACO's objectives: ``TD3+BC+TACO``; ``taco`` the online learner with them: ``TACO``)."""
    if values.get("learner"):
        return method_label(values["learner"], objectives)
    return method_label("actor_critic", objectives) if agent is not None else None


def _int_or_none(value: Any) -> int | None:
    if value is None:
        return None
    try:
        return int(value)
    except (TypeError, ValueError):
        return None


def _text_or_none(value: Any) -> str | None:
    return None if value is None else str(value)


def _float_or_none(value: Any) -> float | None:
    try:
        return None if value is None else float(value)
    except (TypeError, ValueError):
        return None


def _field_counts(text: str) -> tuple[list[str], list[int]]:
    """(the header's fields, every later row's number of fields) as the csv module reads ``text``; text without
    quotes, carriage returns or NUL (what the runs write) is split on newlines and commas instead, with the same
    result (a blank line is a row of no fields)."""
    if '"' in text or "\r" in text or "\0" in text:
        rows = list(csv.reader(io.StringIO(text)))
        return rows[0], [len(r) for r in rows[1:]]
    lines = text.split("\n")[:-1]  # the text ends with a newline (checked by the caller)
    header = lines[0].split(",") if lines[0] else []
    return header, [line.count(",") + 1 if line else 0 for line in lines[1:]]


def read_csv_strict(path: Path, required: tuple[str, ...], order: str = "frame",
                    text_columns: tuple[str, ...] = (), only: tuple[str, ...] | None = None) -> pd.DataFrame:
    """Read a run CSV, raising ValueError with a reason if it is malformed or truncated.

    Checks: non-empty header with the ``required`` columns, every row with the header's field count,
    a final newline (a missing one means the last row was cut), numeric required columns, and strictly
    increasing ``order`` (``frame``; an offline run's ``update``). Columns other than ``text_columns`` are
    numbers (an unparsable value becomes NaN). ``only``: parse only these columns (those present) besides the
    required ones, after the same checks of every row's field count.
    """
    return pd.DataFrame(read_columns_strict(path, required, order, text_columns, only))


def read_columns_strict(path: Path, required: tuple[str, ...], order: str = "frame",
                        text_columns: tuple[str, ...] = (), only: tuple[str, ...] | None = None
                        ) -> dict[str, np.ndarray]:
    """:func:`read_csv_strict`'s columns, one array each, without a frame: a text of plain numbers (what the runs
    write; analysis/plaincsv.py) read by NumPy, any other text by pandas; the same checks, numbers and problems
    either way (tests/test_plaincsv.py)."""
    text = path.read_text(encoding="utf-8", errors="strict")
    if not text.strip():
        raise ValueError("empty file (no header)")
    if not text.endswith("\n"):
        raise ValueError("truncated: the last line has no newline")
    plain = plain_columns(text, None if only is None else {*required, *only}, words=text_columns)
    if plain is None:
        df = _read_csv_pandas(text, required, order, text_columns, only)
        return {col: df[col].to_numpy() for col in df.columns}
    header, arrays = plain
    _check_required(header, required)
    for col in required:
        if arrays[col].dtype.kind == "f":
            _check_filled(col, np.isnan(arrays[col]))
    _check_order(order, arrays[order])
    return arrays


def _check_required(header: list[str], required: tuple[str, ...]) -> None:
    missing = [c for c in required if c not in header]
    if missing:
        raise ValueError(f"missing column(s) {', '.join(missing)}")


def _check_filled(col: str, empty: np.ndarray) -> None:
    """ValueError naming the first line (the header is line 1) where the required column ``col`` has no number."""
    if empty.any():
        raise ValueError(f"non-numeric or empty {col!r} at line {int(empty.argmax()) + 2}")


def _check_order(order: str, values: pd.Series | np.ndarray) -> None:
    if not _strictly_increasing(values):
        raise ValueError(f"{order} is not strictly increasing (duplicated or reordered rows)")


def _read_csv_pandas(text: str, required: tuple[str, ...], order: str, text_columns: tuple[str, ...],
                     only: tuple[str, ...] | None) -> pd.DataFrame:
    header, counts = _field_counts(text)
    _check_required(header, required)
    for lineno, count in enumerate(counts, start=2):
        if count != len(header):
            raise ValueError(f"line {lineno} has {count} fields, header has {len(header)}")
    keep = None
    if only is not None and len(set(header)) == len(header):
        keep = [c for c in header if c in required or c in only]
    # correctly rounded, as the plain reader (pandas' default parser is off in the last bit for many numbers)
    df = pd.read_csv(io.StringIO(text), usecols=keep, float_precision="round_trip")
    dtypes = df.dtypes
    for col in required:
        # a column pandas parsed as numbers is what to_numeric returns; only the others are converted (and set)
        numeric = is_numeric_dtype(dtypes[col])
        converted = df[col] if numeric else pd.to_numeric(df[col], errors="coerce")
        _check_filled(col, converted.isna().to_numpy())
        if not numeric:
            df[col] = converted
    for col in df.columns:
        if col not in required and col not in text_columns and is_object_dtype(dtypes[col]):
            df[col] = pd.to_numeric(df[col], errors="coerce")
    _check_order(order, df[order])
    return df


def _strictly_increasing(values: pd.Series | np.ndarray) -> bool:
    """Every value above the one before (a NaN is not; pandas' ``is_monotonic_increasing`` and no duplicates),
    compared as arrays for integer and float columns."""
    if values.dtype.kind in "if":
        a = np.asarray(values)
        return bool((a[1:] > a[:-1]).all())
    series = pd.Series(values)
    return not (len(series) > 1 and not series.is_monotonic_increasing or series.duplicated().any())


def read_config(path: Path) -> Any:
    """The run's resolved config as plain containers, in today's format (repro/runs/migrate.py; libyaml when
    available; OmegaConf resolves any interpolation left in the file)."""
    text = path.read_text(encoding="utf-8")
    data = yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    if "${" in text and isinstance(data, dict):
        data = OmegaConf.to_container(OmegaConf.create(data), resolve=True)
    return migrate_config(data, owned=True) if isinstance(data, dict) else data  # parsed here: no copy


def budget_end_rows(at: np.ndarray, cfg: dict[str, Any], run_dir: Path, offline: bool) -> np.ndarray:
    """Which eval rows (their frames ``at``; an offline run's updates) only the end of a shorter budget produced: at
    a budget the run reached before it was extended (meta.json ``budgets``), off the evaluation grid, below the
    run's budget now. A run trained to the larger budget in one go has every other row, equal; analysis at a budget
    uses such a row only at exactly that budget."""
    every, budget = (("offline.eval_every_updates", "offline.updates") if offline
                     else ("train.eval_every_frames", "train.frames"))
    step, now = _int_or_none(_get(cfg, every)), _int_or_none(_get(cfg, budget))
    ends = [b for b in reached_budgets(run_dir) if now is None or b < now]
    if not ends or not step or not len(at):
        return np.zeros(len(at), dtype=bool)
    return np.isin(at, ends) & (at % step != 0)


def _read_json(path: Path) -> dict[str, Any]:
    data = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(data, dict):
        raise ValueError("not a JSON object")
    return data


def _provenance(meta: dict[str, Any]) -> dict[str, Any]:
    """Flatten the provenance fields of meta.json that the report shows."""
    git_field = meta.get("git")
    git: dict[str, Any] = git_field if isinstance(git_field, dict) else {}
    versions = meta.get("versions") or meta.get("package_versions") or {}
    return {
        "git_sha": meta.get("git_sha") or git.get("sha"),
        "git_dirty": meta.get("git_dirty", git.get("dirty")),
        "host": meta.get("host"),
        "device": meta.get("device"),
        "cpu": meta.get("cpu"),
        "python": meta.get("python"),
        "versions": json.dumps(versions, sort_keys=True) if isinstance(versions, dict) else str(versions),
        "resumes": len(meta.get("resumes") or []),
    }


def _fps_summary(train: pd.DataFrame | dict[str, np.ndarray]) -> float:
    """Median FPS over training episodes once updates have started (all episodes if none did), of train.csv's
    columns (a frame, or :func:`read_columns_strict`'s arrays)."""
    fps = np.asarray(pd.to_numeric(train["fps"], errors="coerce"), dtype=float)
    if "critic_loss" in train:
        updating = ~np.isnan(np.asarray(pd.to_numeric(train["critic_loss"], errors="coerce"), dtype=float))
        if updating.any():
            fps = fps[updating]
    fps = fps[~np.isnan(fps)]
    return float(np.median(fps)) if len(fps) else math.nan


def find_run_dirs(root: Path) -> list[Path]:
    """Every folder under ``root`` holding a ``config.yaml`` (replay folders are not entered)."""
    found = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if d not in _SKIP_DIRS)
        if Path(dirpath) == root and "bench" in dirnames:
            dirnames.remove("bench")
        if CONFIG in filenames:
            found.append(Path(dirpath))
            dirnames[:] = []  # a run directory has no nested runs
        elif EVAL in filenames:
            found.append(Path(dirpath))  # reported below: a run without its config
    return found


def _resolved(run_dir: Path, cfg: dict[str, Any]) -> tuple[dict[str, Any], str, Problem | None]:
    """(resolved values, where they came from, a warning if not from resolved.json)."""
    path = run_dir / RESOLVED
    try:
        return read_resolved(run_dir), RESOLVED_FROM_FILE, None
    except FileNotFoundError:
        why = f"no {RESOLVED} (a run written before runs recorded their resolved values)"
    except (ResolvedError, OSError, UnicodeDecodeError) as exc:
        why = f"malformed {RESOLVED} ({exc})"
    fields = ", ".join(RESOLVED_FIELDS)
    return resolved_from_config(cfg), RESOLVED_FROM_CONFIG, Problem(
        str(path), f"{why}; {fields} taken from {CONFIG} as written (a null latent_action_dim stays unknown)",
        "warning")


def load_run(run_dir: Path, root: Path) -> tuple[dict[str, Any] | None, dict[str, np.ndarray] | None, list[Problem]]:
    """Load one run directory: (run row, its eval rows as one array per column, problems). Run row is None if the
    run is unusable."""
    problems: list[Problem] = []
    rel = str(run_dir.relative_to(root))
    cfg_path = run_dir / CONFIG
    if not cfg_path.exists():
        return None, None, [Problem(str(run_dir / EVAL), f"run directory without {CONFIG}; skipped")]
    try:
        cfg = read_config(cfg_path)
    except (OmegaConfBaseException, yaml.YAMLError, OSError, ValueError, UnicodeDecodeError) as exc:
        return None, None, [Problem(str(cfg_path), f"unreadable config: {exc}; run skipped")]
    if not isinstance(cfg, dict):
        return None, None, [Problem(str(cfg_path), "config is not a mapping; run skipped")]
    ident = identity_from_config(cfg)
    missing = [IDENTITY_KEYS[k] for k in ("agent", "task", "seed") if ident[k] is None]  # the config's keys
    if missing:
        return None, None, [Problem(str(cfg_path), f"config lacks {', '.join(missing)}; run skipped")]
    values, source, problem = _resolved(run_dir, cfg)
    if problem is not None:
        problems.append(problem)
    ident.update(resolved_columns(values, ident["agent"]))
    offline = ident["dataset"] is not None or _get(cfg, RESOLVED_CONFIG_KEYS["dataset"]) is not None
    if offline:  # the run's own budget (analysis/claim_budgets.csv: offline claims judge each run at it)
        ident["offline_updates"] = _int_or_none(_get(cfg, "offline.updates"))
    ident["run_id"] = rel
    ident["status"] = run_state(run_dir)

    row: dict[str, Any] = dict(ident)
    row["resolved_from"] = source
    # the speed-up path it trained with (repro/bench/results.py: the bench's vocabulary, agent.fast's FastPlan first)
    row["speedup"] = path_of(_get(cfg, "agent") or {}, values.get("fast"))
    row.update(_provenance(_read_meta(run_dir / META, problems)))

    x = "update" if offline else "frame"
    evals = _read_eval(run_dir / EVAL, offline, problems,
                       lambda cols: {"run_id": np.full(len(cols[x]), rel, dtype=object),
                                     "budget_end": budget_end_rows(cols[x], cfg, run_dir, offline)})
    row["eval_rows"] = 0 if evals is None else len(evals[x])
    row["last_frame"] = row["last_update"] = math.nan
    if evals is not None and len(evals[x]):
        row["last_update" if offline else "last_frame"] = float(evals[x].max())

    row.update(_train_speed(run_dir / TRAIN, offline, problems))
    return row, evals, problems


def _read_meta(meta_path: Path, problems: list[Problem]) -> dict[str, Any]:
    """A run's meta.json ({} with a warning recorded when it is missing or unreadable)."""
    if not meta_path.exists():
        problems.append(Problem(str(meta_path), "missing meta.json (no provenance)", "warning"))
        return {}
    try:
        return _read_json(meta_path)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        problems.append(Problem(str(meta_path), f"unreadable meta.json: {exc}", "warning"))
        return {}


def _train_speed(train_path: Path, offline: bool, problems: list[Problem]) -> dict[str, float]:
    """fps (online: from train.csv) and updates_per_s (offline: the median of train.csv's), NaN when unknown (a
    problem recorded when train.csv is malformed)."""
    speed = {"fps": math.nan, "updates_per_s": math.nan}
    if train_path.exists():
        try:
            if offline:
                train = read_csv_strict(train_path, OFFLINE_TRAIN_REQUIRED, order="update", only=())
                rates = pd.to_numeric(train["updates_per_s"], errors="coerce").dropna()
                speed["updates_per_s"] = float(rates.median()) if len(rates) else math.nan
            else:
                speed["fps"] = _fps_summary(read_columns_strict(train_path, TRAIN_REQUIRED, only=("critic_loss",)))
        except (ValueError, OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
            problems.append(Problem(str(train_path), f"malformed train.csv ({exc}); its speed not used"))
    return speed


def _read_eval(path: Path, offline: bool, problems: list[Problem],
               extra: Callable[[dict[str, np.ndarray]], dict[str, np.ndarray]] | None = None
               ) -> dict[str, np.ndarray] | None:
    """A run's eval.csv on the eval table's columns (EVAL_TABLE_COLUMNS, one array each; columns a learner adds
    beyond its format are left out) followed by the columns ``extra(those columns)`` gives, or None (a problem
    recorded) if it is missing or malformed."""
    if not path.exists():
        problems.append(Problem(str(path), "missing eval.csv; run has no scores", "warning"))
        return None
    try:
        if offline:
            read = read_columns_strict(path, OFFLINE_EVAL_REQUIRED, order="update", text_columns=OFFLINE_EVAL_TEXT)
        else:
            read = read_columns_strict(path, EVAL_REQUIRED)
    except (ValueError, OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        problems.append(Problem(str(path), f"malformed eval.csv ({exc}); skipped"))
        return None
    rows = len(next(iter(read.values())))
    columns = {col: read[col] if col in read else np.full(rows, math.nan) for col in EVAL_TABLE_COLUMNS}
    if extra is not None:
        columns.update(extra(columns))
    return columns


def _concat_columns(parts: list[dict[str, np.ndarray]]) -> pd.DataFrame:
    """The frame ``pd.concat`` of one frame per part (``ignore_index``) gives, built one column at a time: arrays of
    one type, of integers and floats (float64) or with an object one among them (object) joined by NumPy, any other
    mix (booleans with numbers) by pandas, as frames (whose rules are not a Series')."""
    numbers = {np.dtype(np.int64), np.dtype(np.float64)}
    out: dict[str, Any] = {}
    for col in parts[0]:
        arrays = [part[col] for part in parts]
        kinds = {a.dtype for a in arrays}
        if len(kinds) == 1 or kinds <= numbers or np.dtype(object) in kinds:
            out[col] = np.concatenate(arrays)
        else:
            out[col] = pd.concat([pd.DataFrame({col: a}) for a in arrays], ignore_index=True)[col]
    return pd.DataFrame(out)


def load_benches(root: Path) -> tuple[list[BenchFile], list[Problem]]:
    """Read ``{root}/bench/*.json`` speed benchmarks of any version (repro/bench/results.py, their one reader)."""
    out, problems = [], []
    for path in sorted((root / "bench").glob("*.json")):
        try:
            out.append(read_bench(path))
        except BenchFormatError as exc:
            problems.append(Problem(str(path), f"malformed benchmark JSON ({exc}); skipped"))
    return out, problems


def load_results(root: Path | str) -> Results:
    """Load every run under ``root``. Raises :class:`ResultsRootError` only if ``root`` is not a folder."""
    root = Path(root)
    if not root.is_dir():
        raise ResultsRootError(f"results root {root} does not exist or is not a directory")
    rows, evals, problems = [], [], []
    for run_dir in find_run_dirs(root):
        row, columns, probs = _load_run_cached(run_dir, root)
        problems.extend(probs)
        if row is not None:
            rows.append(row)
        if columns is not None and len(columns["run_id"]):
            evals.append(columns)
    benches, bench_problems = load_benches(root)
    problems.extend(bench_problems)
    runs = pd.DataFrame(rows)
    if runs.empty:
        runs = pd.DataFrame(columns=[*IDENTITY, "resolved_from", "speedup", "eval_rows", "last_frame", "last_update",
                                     "fps", "updates_per_s"])
    else:
        dup = runs.duplicated(["experiment", "agent", "variant", "task", "dataset", "seed"], keep=False)
        for run_id in runs.loc[dup, "run_id"]:
            problems.append(Problem(str(root / run_id),
                                    "same experiment/agent/variant/task/dataset/seed as another run", "warning"))
    if evals and not runs.empty:
        eval_all = _concat_columns(evals).merge(runs[list(IDENTITY)], on="run_id", how="left")
    else:
        eval_all = pd.DataFrame(columns=[*IDENTITY, *EVAL_TABLE_COLUMNS, "budget_end"])
    runs["source"] = SOURCE_RUNS
    eval_all["source"] = SOURCE_RUNS
    return Results(root=root, runs=runs, eval=eval_all, problems=problems, benches=benches)


def _load_run_cached(run_dir: Path, root: Path
                     ) -> tuple[dict[str, Any] | None, dict[str, np.ndarray] | None, list[Problem]]:
    """:func:`load_run`, reused from the command's cache (analysis/cache.py) while none of the run's files changed
    in size or modification time."""
    key = (str(root.resolve()), str(run_dir.relative_to(root)), file_signature(run_dir))
    return lookup("runs", key, lambda: load_run(run_dir, root), process=False)


def _published_file(path: Path) -> pd.DataFrame:
    """One ``dmc_{task}.csv`` of the published curves, checked like a run's eval.csv (ValueError with a reason):
    the required columns, numbers where numbers belong, agent DrQ-v2, the task of the file name, frames
    strictly increasing within each seed."""
    text = path.read_text(encoding="utf-8")
    if not text.endswith("\n"):
        raise ValueError("truncated: the last line has no newline")
    df = pd.read_csv(io.StringIO(text), index_col=0)
    missing = [c for c in PUBLISHED_REQUIRED if c not in df.columns]
    if missing:
        raise ValueError(f"missing column(s) {', '.join(missing)}")
    for col in ("seed", "frame", "episode_reward"):
        df[col] = pd.to_numeric(df[col], errors="coerce")
        if df[col].isna().any():
            raise ValueError(f"non-numeric or empty {col!r}")
    task = path.stem.removeprefix("dmc_")
    if set(df["agent"]) != {"DrQ-v2"} or set(df["task"]) != {task}:
        raise ValueError(f"expected agent DrQ-v2 and task {task} on every row")
    if not df.groupby("seed")["frame"].apply(lambda f: bool(f.is_monotonic_increasing and f.is_unique)).all():
        raise ValueError("frame is not strictly increasing within a seed")
    return df


def load_published(root: Path | str = PUBLISHED_DIR) -> Results:
    """The DrQ-v2 authors' published learning curves (``repro_data/reference/drqv2_curves``) as a
    :class:`Results` of their own: one "run" per task and seed, with the identity and eval columns of
    :func:`load_results` (agent ``drqv2``, method ``DrQ-v2``, experiment ``published``, action repeat 2, status
    done, ``run_id`` ``published/{task}/seed{n}``) and ``source`` = ``published``, so every function of the
    analysis that reads a Results (scores, learning curves) reads them unchanged. They are never merged with
    a user's runs: callers keep the two Results apart. A malformed file is a :class:`Problem` and skipped."""
    root = Path(root)
    if not root.is_dir():
        raise ResultsRootError(f"published curves folder {root} does not exist or is not a directory")
    rows: list[dict[str, Any]] = []
    evals: list[dict[str, np.ndarray]] = []  # each run's eval columns (one frame of them all at the end)
    problems: list[Problem] = []
    for path in sorted(root.glob("dmc_*.csv")):
        try:
            df = _published_file(path)
        except (ValueError, OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
            problems.append(Problem(str(path), f"malformed published curves ({exc}); skipped"))
            continue
        task = path.stem.removeprefix("dmc_")
        for seed, part in df.groupby("seed", sort=True):
            run_id = f"{PUBLISHED_EXPERIMENT}/{task}/seed{int(seed)}"
            ident: dict[str, Any] = {k: None for k in IDENTITY}
            ident.update(run_id=run_id, experiment=PUBLISHED_EXPERIMENT, variant="base", agent="drqv2",
                         method="DrQ-v2", task=task, suite="dmc", seed=int(seed), objectives="",
                         action_repeat=PUBLISHED_ACTION_REPEAT, distracting_dims=0,
                         train_frames=int(part["frame"].max()), status="done")
            frames = part["frame"].to_numpy(dtype=float)
            n = len(part)
            ev = {k: (np.full(n, v, dtype=np.int64) if isinstance(v, int) and not isinstance(v, bool)
                      else np.full(n, v, dtype=object)) for k, v in ident.items()}
            ev.update({c: np.full(n, math.nan) for c in EVAL_TABLE_COLUMNS})
            ev["frame"] = frames
            ev["step"] = frames // PUBLISHED_ACTION_REPEAT
            ev["episode"] = np.arange(n, dtype=np.int64)
            ev["episode_reward"] = part["episode_reward"].to_numpy(dtype=float)
            if "hour" in part.columns:
                ev["total_time"] = pd.to_numeric(part["hour"], errors="coerce").to_numpy(dtype=float) * 3600.0
            evals.append(ev)
            rows.append({**ident, "resolved_from": str(path.name), "eval_rows": len(part),
                         "last_frame": float(frames.max()), "last_update": math.nan, "fps": math.nan,
                         "updates_per_s": math.nan})
    runs = pd.DataFrame(rows) if rows else pd.DataFrame(columns=[*IDENTITY, "resolved_from", "eval_rows",
                                                                   "last_frame", "last_update", "fps",
                                                                   "updates_per_s"])
    eval_all = (pd.DataFrame({c: np.concatenate([ev[c] for ev in evals]) for c in [*IDENTITY, *EVAL_TABLE_COLUMNS]})
                if evals else pd.DataFrame(columns=[*IDENTITY, *EVAL_TABLE_COLUMNS]))
    runs["source"] = SOURCE_PUBLISHED
    eval_all["source"] = SOURCE_PUBLISHED
    return Results(root=root, runs=runs, eval=eval_all, problems=problems)
