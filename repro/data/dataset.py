"""Offline datasets on disk: one npz file per episode plus a ``manifest.json`` written last.

Layout of a dataset folder::

    manifest.json              written last, atomically: a folder without it is never a dataset
    .incomplete.json           present while a write is in progress (what is being written)
    episodes/ep_0000000.npz    frames (T+1, 3, H, W) uint8, actions (T, A) float32 (taken at frame t),
                               rewards (T,) float32 (after action t), discounts (T,) float32, ep_id

The episode arrays are the replay's ``end_episode()`` arrays, so a dataset episode and a recorded training
episode are interchangeable. Every problem is a :class:`DatasetError` with a one-line message.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import zipfile
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import numpy as np

from repro import __version__
from repro.config.compose import is_folder_value
from repro.config.errors import UserError
from repro.runs.fsutil import atomic_write, atomic_write_text

FORMAT = 1
MANIFEST = "manifest.json"
PENDING = ".incomplete.json"
EPISODES = "episodes"
KEYS = ("frames", "actions", "rewards", "discounts", "ep_id")
_EP_NAME = re.compile(r"^ep_(\d{7})\.npz$")

Episode = dict[str, np.ndarray]
EpisodeSource = Union[Mapping[str, np.ndarray], Callable[[], Mapping[str, np.ndarray]]]


class DatasetError(UserError, ValueError):
    """A dataset or an input file that cannot be used; the message is one line."""


@dataclass(frozen=True)
class EpisodeEntry:
    file: str
    sha256: str
    transitions: int
    return_: float


@dataclass(frozen=True)
class Manifest:
    task: str
    action_dim: int
    frame_shape: tuple[int, int, int]
    kind: str
    transitions: int
    episodes: tuple[EpisodeEntry, ...]
    source: dict[str, Any] = field(default_factory=dict)
    rule: dict[str, Any] = field(default_factory=dict)
    created_by: str = f"repro {__version__}"
    format: int = FORMAT

    @property
    def returns(self) -> np.ndarray:
        return np.array([e.return_ for e in self.episodes], dtype=np.float64)

    def to_json(self) -> dict[str, Any]:
        return {"format": self.format, "task": self.task, "action_dim": self.action_dim,
                "frame_shape": list(self.frame_shape), "kind": self.kind, "transitions": self.transitions,
                "episodes": [{"file": e.file, "sha256": e.sha256, "transitions": e.transitions,
                              "return": e.return_} for e in self.episodes],
                "source": self.source, "rule": self.rule, "created_by": self.created_by}

    @classmethod
    def from_json(cls, data: Any, where: str) -> Manifest:
        if not isinstance(data, dict):
            raise DatasetError(f"wrong format: {where} is not a JSON object")
        if data.get("format") != FORMAT:
            raise DatasetError(f"wrong format: {where} has format {data.get('format')!r}, this tool reads {FORMAT}")
        try:
            episodes = tuple(EpisodeEntry(str(e["file"]), str(e["sha256"]), int(e["transitions"]),
                                          float(e["return"])) for e in data["episodes"])
            shape = tuple(int(s) for s in data["frame_shape"])
            if len(shape) != 3:
                raise ValueError("frame_shape")
            return cls(task=str(data["task"]), action_dim=int(data["action_dim"]),
                       frame_shape=shape, kind=str(data["kind"]),
                       transitions=int(data["transitions"]), episodes=episodes,
                       source=dict(data.get("source") or {}), rule=dict(data.get("rule") or {}),
                       created_by=str(data.get("created_by", "")), format=FORMAT)
        except (KeyError, TypeError, ValueError) as exc:
            raise DatasetError(f"wrong format: {where} lacks or mistypes field {exc}") from None


# ---------------------------------------------------------------------------------------------- reading
def load_manifest(directory: str | Path) -> Manifest:
    """The manifest of a complete dataset; :class:`DatasetError` for a missing, partial or foreign folder."""
    d = Path(directory)
    if not d.is_dir():
        raise DatasetError(f"no dataset at {d} (not a folder)")
    path = d / MANIFEST
    if not path.exists():
        if (d / PENDING).exists():
            raise DatasetError(f"incomplete dataset at {d}: no {MANIFEST} (its write was interrupted; "
                               "re-run the command that made it)")
        if (d / EPISODES).is_dir():
            raise DatasetError(f"incomplete dataset at {d}: {EPISODES}/ but no {MANIFEST} and no record of "
                               "what was being written; remove it and make it again")
        raise DatasetError(f"no dataset at {d} (no {MANIFEST})")
    try:
        data = json.loads(path.read_text())
    except PermissionError:
        raise DatasetError(f"cannot read {path}: permission denied (made by another user with a private mode? "
                           "its owner can `chmod -R a+rX` the dataset folder)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DatasetError(f"corrupt {path}: {exc}") from None
    return Manifest.from_json(data, str(path))


SHA256_MISMATCH = "sha256 differs from the manifest"  # an episode file whose bytes are not those its manifest names


def episode_digest(source: bytes | Path) -> str:
    """The sha256 (hex) a manifest records for an episode file: of ``source``'s bytes, or of the file at ``source``
    read in 1 MiB chunks (`repro doctor` checks whole datasets without holding a file in memory). OSError as
    reading raises it."""
    if isinstance(source, bytes):
        return hashlib.sha256(source).hexdigest()
    digest = hashlib.sha256()
    with open(source, "rb") as fh:
        while chunk := fh.read(1 << 20):
            digest.update(chunk)
    return digest.hexdigest()


def read_episode_file(path: Path, sha256: str | None = None) -> Episode:
    """The arrays of one episode file; a sha256 mismatch or an unreadable file is a :class:`DatasetError`."""
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DatasetError(f"missing or unreadable episode file {path}: {exc.strerror}") from None
    if sha256 is not None and episode_digest(raw) != sha256:
        raise DatasetError(f"corrupt episode file {path}: {SHA256_MISMATCH}")
    return _load_npz(raw, path)


def _load_npz(raw: bytes, path: Path) -> Episode:
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, KeyError, zlib.error) as exc:
        raise DatasetError(f"corrupt or truncated episode file {path}: {type(exc).__name__}") from None


def iter_episodes(directory: str | Path, *, verify: bool = True) -> Iterator[Episode]:
    """Yield every episode of a complete dataset in order.

    With ``verify`` (training and export read this way), what ``check_dataset`` checks is checked on the way,
    each first problem a :class:`DatasetError`: the listing (names inside ``episodes/``, no unlisted episode
    file, totals) before the first file is read, then each file's sha256, arrays, transitions and return
    against the manifest. A file whose size, mtime and manifest hash equal those of a file already verified
    (a per-user cache, :func:`verified_cache_file`) is not hashed again; everything else is checked each time.
    """
    d = Path(directory)
    m = load_manifest(d)
    if verify:
        problems = listing_problems(d, m)
        if problems:
            raise DatasetError(f"{d}: {problems[0]}")
    cache = _read_cache(d) if verify else {}
    seen: dict[str, list[Any]] = {}
    for i, entry in enumerate(m.episodes):
        path = d / entry.file
        stat = _stat(path) if verify else None
        known = cache.get(entry.file)
        hashed = not (stat is not None and known == [*stat, entry.sha256])
        ep = read_episode_file(path, entry.sha256 if verify and hashed else None)
        if verify:
            problems = entry_problems(ep, entry, i, m)
            if problems:
                raise DatasetError(f"{path}: {problems[0]}")
            if stat is not None:
                seen[entry.file] = [*stat, entry.sha256]
            if i == len(m.episodes) - 1 and seen != cache:  # before the last yield: a reader may stop there
                _write_cache(d, seen)
        yield ep


def verified_cache_file(directory: str | Path) -> Path:
    """Where the hashes verified for the dataset at ``directory`` are remembered (sizes, mtimes, sha256):
    ``$XDG_CACHE_HOME/repro/verified/`` (default ``~/.cache``), one file per dataset folder (its real path)."""
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    key = hashlib.sha256(os.path.realpath(directory).encode()).hexdigest()[:32]
    return root / "repro" / "verified" / f"{key}.json"


def _stat(path: Path) -> tuple[int, int] | None:
    try:
        st = path.stat()
    except OSError:
        return None
    return int(st.st_size), int(st.st_mtime_ns)


def _read_cache(d: Path) -> dict[str, list[Any]]:
    try:
        data = json.loads(verified_cache_file(d).read_text())
        return {str(k): list(v) for k, v in data["files"].items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _write_cache(d: Path, files: dict[str, list[Any]]) -> None:
    try:
        atomic_write_text(verified_cache_file(d), json.dumps({"dataset": os.path.realpath(d), "files": files}))
    except OSError:
        pass  # a cache only: without it the next load hashes again


def ep_transitions(ep: Mapping[str, np.ndarray]) -> int:
    return int(len(ep["frames"]) - 1)


def episode_return(ep: Mapping[str, np.ndarray]) -> float:
    return float(np.sum(np.asarray(ep["rewards"], dtype=np.float64)))


def episode_problems(ep: Mapping[str, np.ndarray], *, action_dim: int | None = None,
                     frame_shape: tuple[int, ...] | None = None, ep_id: int | None = None) -> list[str]:
    """What is wrong with one episode's arrays (empty when nothing): keys, dtypes, shapes, finiteness."""
    missing = [k for k in KEYS if k not in ep]
    if missing:
        return [f"missing arrays {', '.join(missing)}"]
    frames, actions, rewards, discounts = (np.asarray(ep[k]) for k in KEYS[:4])
    out: list[str] = []
    if frames.dtype != np.uint8 or frames.ndim != 4 or frames.shape[1] != 3:
        return [f"frames must be (T+1, 3, H, W) uint8, got {frames.shape} {frames.dtype}"]
    if frame_shape is not None and tuple(frames.shape[1:]) != tuple(frame_shape):
        out.append(f"frame shape {list(frames.shape[1:])}, the dataset's is {list(frame_shape)}")
    t = len(frames) - 1
    if t < 1:
        return out + ["an episode needs at least 2 frames (1 transition)"]
    if actions.dtype != np.float32 or actions.ndim != 2 or len(actions) != t:
        out.append(f"actions must be ({t}, A) float32 for {t + 1} frames, got {actions.shape} {actions.dtype}")
    elif action_dim is not None and actions.shape[1] != action_dim:
        out.append(f"action dim {actions.shape[1]}, the dataset's is {action_dim}")
    elif not np.all(np.isfinite(actions)):
        out.append("non-finite actions")
    for name, arr in (("rewards", rewards), ("discounts", discounts)):
        if arr.dtype != np.float32 or arr.shape != (t,):
            out.append(f"{name} must be ({t},) float32 for {t + 1} frames, got {arr.shape} {arr.dtype}")
        elif not np.all(np.isfinite(arr)):
            out.append(f"non-finite {name}")
    if discounts.shape == (t,) and np.all(np.isfinite(discounts)) and (
            discounts.min() < 0 or discounts.max() > 1):
        out.append("discounts outside [0, 1]")
    ep_arr = np.asarray(ep["ep_id"])
    if ep_arr.shape != () or not np.issubdtype(ep_arr.dtype, np.integer):
        out.append(f"ep_id must be an integer scalar, got {ep_arr.shape} {ep_arr.dtype}")
    elif ep_id is not None and int(ep_arr) != ep_id:
        out.append(f"ep_id {int(ep_arr)}, its position in the dataset is {ep_id}")
    return out


MIN_FRAME = 15  # the smallest frame side the DrQ-v2 encoder accepts ((S - 3) // 2 + 1 - 6 >= 1)


def usable_problems(m: Manifest) -> list[str]:
    """What no run could use: an unknown task, fewer action dims than the task has (a run may add
    distracting dims, never remove any), frames that are not square RGB of at least MIN_FRAME pixels."""
    from repro.envs.registry import TASKS

    info = TASKS.get(m.task)
    if info is None:
        return [f"unknown task '{m.task}' in {MANIFEST} (known: {', '.join(sorted(TASKS))})"]
    out = []
    if m.action_dim < info.action_dim:
        out.append(f"action dim {m.action_dim}: task {m.task} has {info.action_dim} (another task's data?)")
    c, h, w = m.frame_shape
    if c != 3 or h != w or h < MIN_FRAME:
        out.append(f"frame shape {list(m.frame_shape)}: a run renders square RGB frames (3, S, S) with S >= "
                   f"{MIN_FRAME} (env.image_size)")
    return out


def listing_problems(d: Path, m: Manifest) -> list[str]:
    """What is wrong with the manifest's listing of episode files, found without reading one: names (each
    episode at ``episodes/ep_{i:07d}.npz``, so nothing outside the folder), duplicates, totals, unlisted files."""
    problems: list[str] = []
    listed: set[str] = set()
    for i, entry in enumerate(m.episodes):
        if entry.file in listed:
            problems.append(f"{entry.file} is listed twice in {MANIFEST}")
            continue
        listed.add(entry.file)
        if entry.file != f"{EPISODES}/ep_{i:07d}.npz":
            problems.append(f"episode {i} is stored as {entry.file}, expected {EPISODES}/ep_{i:07d}.npz")
    total = sum(e.transitions for e in m.episodes)
    if total != m.transitions:
        problems.append(f"{MANIFEST} says {m.transitions} transitions, its episodes hold {total}")
    if not m.episodes:
        problems.append(f"{MANIFEST} lists no episode")
    if (d / EPISODES).is_dir():
        for p in sorted((d / EPISODES).iterdir()):
            rel = f"{EPISODES}/{p.name}"
            if _EP_NAME.match(p.name) and rel not in listed:
                problems.append(f"{rel} is not listed in {MANIFEST}")
    return problems


def entry_problems(ep: Mapping[str, np.ndarray], entry: EpisodeEntry, i: int, m: Manifest) -> list[str]:
    """What is wrong with episode ``i``'s arrays against the dataset and its manifest entry."""
    found = episode_problems(ep, action_dim=m.action_dim, frame_shape=m.frame_shape, ep_id=i)
    if found:
        return found
    if ep_transitions(ep) != entry.transitions:
        found.append(f"{ep_transitions(ep)} transitions, the manifest says {entry.transitions}")
    if not math.isclose(episode_return(ep), entry.return_, rel_tol=1e-9, abs_tol=1e-9):
        found.append(f"return {episode_return(ep):.6g}, the manifest says {entry.return_:.6g}")
    return found


def check_dataset(directory: str | Path) -> list[str]:
    """Every problem found in a dataset folder, one line each (empty: the dataset is valid)."""
    d = Path(directory)
    try:
        m = load_manifest(d)
    except DatasetError as exc:
        return [str(exc)]
    problems = usable_problems(m) + listing_problems(d, m)
    listed: set[str] = set()
    for i, entry in enumerate(m.episodes):
        if entry.file in listed or entry.file != f"{EPISODES}/ep_{i:07d}.npz":
            listed.add(entry.file)
            continue  # reported by listing_problems; never read a file outside the folder
        listed.add(entry.file)
        try:
            ep = read_episode_file(d / entry.file, entry.sha256)
        except DatasetError as exc:
            problems.append(str(exc))
            continue
        problems += [f"{entry.file}: {p}" for p in entry_problems(ep, entry, i, m)]
    return problems


# ---------------------------------------------------------------------------------------------- writing
def write_dataset(directory: str | Path, episodes: Iterable[EpisodeSource], *, task: str, kind: str,
                  source: Mapping[str, Any] | None = None, rule: Mapping[str, Any] | None = None,
                  created_by: str | None = None) -> Manifest:
    """Write a dataset folder, resumably: kill it at any moment, call it again, and it completes.

    ``episodes`` yields episode arrays (as ``end_episode()``), or zero-argument callables returning them:
    on a re-run, a callable whose episode file is already on disk and verifies is not called (so costly
    rollouts are not redone); a given episode replaces a file on disk unless the arrays are equal. Each
    file is written atomically, ``manifest.json`` last. ``ep_id`` is set to the episode's position.

    The folder must be new, empty, or a partial write of the same ``task``/``kind``/``source``/``rule``
    (recorded in ``.incomplete.json``); a complete dataset with those values is returned as it is.
    Anything else raises :class:`DatasetError` without touching the folder.
    """
    d = Path(directory)
    identity = _jsonable({"format": FORMAT, "task": task, "kind": kind, "source": dict(source or {}),
                          "rule": dict(rule or {})})
    try:
        _claim(d, identity)
    except _AlreadyComplete as done:
        (d / PENDING).unlink(missing_ok=True)
        return done.manifest
    ep_dir = d / EPISODES
    ep_dir.mkdir(parents=True, exist_ok=True)
    for tmp in ep_dir.glob(".*.tmp"):
        tmp.unlink(missing_ok=True)
    entries: list[EpisodeEntry] = []
    action_dim: int | None = None
    frame_shape: tuple[int, int, int] | None = None
    for i, item in enumerate(episodes):
        path = ep_dir / f"ep_{i:07d}.npz"
        ep, raw = _episode_for(path, item, i, action_dim, frame_shape)
        if action_dim is None:
            action_dim = int(ep["actions"].shape[1])
            frame_shape = tuple(int(s) for s in ep["frames"].shape[1:])  # type: ignore[assignment]
        entries.append(EpisodeEntry(f"{EPISODES}/{path.name}", hashlib.sha256(raw).hexdigest(),
                                    ep_transitions(ep), episode_return(ep)))
    if not entries or action_dim is None or frame_shape is None:
        raise DatasetError(f"no episode to write to {d}")
    for p in ep_dir.iterdir():  # files of a longer earlier attempt
        m = _EP_NAME.match(p.name)
        if m and int(m.group(1)) >= len(entries):
            p.unlink()
    manifest = Manifest(task=task, action_dim=action_dim, frame_shape=frame_shape, kind=kind,
                        transitions=sum(e.transitions for e in entries), episodes=tuple(entries),
                        source=identity["source"], rule=identity["rule"],
                        created_by=created_by or f"repro {__version__}")
    atomic_write_text(d / MANIFEST, json.dumps(manifest.to_json(), indent=1) + "\n")
    (d / PENDING).unlink(missing_ok=True)
    return manifest


def _jsonable(value: dict[str, Any]) -> dict[str, Any]:
    """``value`` as it reads back from JSON (tuples become lists), so identities compare equal."""
    try:
        return json.loads(json.dumps(value, sort_keys=True))
    except (TypeError, ValueError) as exc:
        raise DatasetError(f"dataset fields must be JSON values: {exc}") from None


def _claim(d: Path, identity: dict[str, Any]) -> None:
    """Make ``d`` ours to write: new, empty, or a partial write of the same identity."""
    if (d / MANIFEST).exists():
        m = load_manifest(d)
        have = _jsonable({"format": m.format, "task": m.task, "kind": m.kind, "source": m.source, "rule": m.rule})
        if have != identity:
            raise DatasetError(f"{d} already holds a dataset ({m.task}, {m.kind}) made from other inputs; "
                               "remove it or choose another folder")
        raise _AlreadyComplete(m)
    if (d / PENDING).exists():
        try:
            pending = json.loads((d / PENDING).read_text())
        except (OSError, json.JSONDecodeError):
            pending = None
        if pending != identity:
            raise DatasetError(f"{d} holds a partial dataset made from other inputs; remove it or choose "
                               "another folder")
        return
    if d.exists() and (not d.is_dir() or any(d.iterdir())):
        raise DatasetError(f"{d} exists and is not a dataset being written; choose a new or empty folder")
    d.mkdir(parents=True, exist_ok=True)
    atomic_write_text(d / PENDING, json.dumps(identity, sort_keys=True) + "\n")


class _AlreadyComplete(Exception):
    def __init__(self, manifest: Manifest):
        super().__init__("already complete")
        self.manifest = manifest


def _episode_for(path: Path, item: EpisodeSource, i: int, action_dim: int | None,
                 frame_shape: tuple[int, ...] | None) -> tuple[Episode, bytes]:
    """The episode at position ``i`` and its file bytes: reused from disk when it verifies, else written."""
    on_disk: tuple[Episode, bytes] | None = None
    if path.exists():
        raw = path.read_bytes()
        try:
            ep = _load_npz(raw, path)
        except DatasetError:
            ep = None
        if ep is not None and not episode_problems(ep, action_dim=action_dim, frame_shape=frame_shape, ep_id=i):
            on_disk = (ep, raw)
    if callable(item):
        if on_disk is not None:
            return on_disk
        item = item()
    ep = {k: np.asarray(v) for k, v in item.items()}
    ep["ep_id"] = np.array(i, dtype=np.int64)
    problems = episode_problems(ep, action_dim=action_dim, frame_shape=frame_shape)
    if problems:
        raise DatasetError(f"episode {i}: {problems[0]}")
    if on_disk is not None and all(np.array_equal(on_disk[0][k], ep[k]) for k in KEYS) \
            and set(on_disk[0]) == set(ep):
        return on_disk
    buf = io.BytesIO()
    np.savez_compressed(buf, **ep)  # type: ignore[arg-type]  # numpy stub matches **kwds against allow_pickle
    raw = buf.getvalue()
    atomic_write(path, lambda f: f.write(raw))
    return ep, raw


# ---------------------------------------------------------------------------------------------- locating
def dataset_path(value: str, results_root: str | Path, task: str) -> Path:
    """Where ``value`` points, existing or not: a kind -> ``{results_root}/datasets/{task}/{kind}``."""
    value = str(value or "").strip()
    if not value:
        raise DatasetError("no dataset given (set offline.dataset to a kind such as medium, or a folder)")
    if is_folder_value(value):
        return Path(value).expanduser()
    return Path(results_root) / "datasets" / task / value


def resolve_dataset(value: str, results_root: str | Path, task: str) -> Path:
    """``offline.dataset``: a kind name -> ``{results_root}/datasets/{task}/{kind}``; with a '/', a folder.

    The folder must exist (whether it holds a complete dataset is :func:`load_manifest`'s question).
    """
    path = dataset_path(value, results_root, task)
    if path.is_dir():
        return path
    if is_folder_value(str(value).strip()):
        raise DatasetError(f"unknown dataset: no folder {path}")
    base = path.parent
    known = sorted(p.name for p in base.iterdir() if p.is_dir()) if base.is_dir() else []
    hint = f"known for {task}: {', '.join(known)}" if known else f"none made for {task} yet"
    raise DatasetError(f"unknown dataset '{str(value).strip()}': no folder {path} ({hint}; `repro dataset make` "
                       "or `repro dataset import` makes one)")


def open_dataset(value: str, results_root: str | Path, task: str,
                 action_dim: int | None = None) -> tuple[Path, Manifest]:
    """Resolve ``value`` and load its manifest, refusing another task's or another action dim's dataset."""
    path = resolve_dataset(value, results_root, task)
    m = load_manifest(path)
    if m.task != task:
        raise DatasetError(f"dataset {path} is for task {m.task}, not {task}")
    if action_dim is not None and m.action_dim != action_dim:
        raise DatasetError(f"dataset {path} has action dim {m.action_dim}, the run needs {action_dim}")
    return path, m
