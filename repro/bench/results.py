"""The one owner of `repro bench`'s files: what an entry holds, where the files lie, how a file of any version is
read, which speed-up path a run trains with, and one FPS per (agent, batch size, path) for every reader (`repro plan`,
the speed tables T4/T5 and the claim `speed`, so `repro report` too). Documented in docs/plan.md and
docs/performance.md.

Files, under ``{results_root}/bench/``: ``bench-<host>-<device>.json`` (the online update entries, ``results``, and
the end-to-end entries, ``e2e``), ``bench-offline-<host>-<device>.json`` (one update of each offline learner),
``bench-offline-data-<host>.json`` (a dataset's load and sampling) and ``bench-roofline-<host>-<device>.json``.
Each file written now says its ``kind`` and ``format`` (:data:`FORMAT`), names the agent of every entry ``agent`` and
its speed-up path ``path`` (typed: :class:`UpdateEntry`, :class:`E2EEntry`, :class:`OfflineEntry`, :class:`DataEntry`),
and records beside each timed entry the machine's 1-minute load average and its cores (``load``, ``cores``: an entry
with load > cores was timed under load, :func:`under_load`). A new bench merges into the file of its host and device:
its entries replace those of the same setting (:meth:`BenchFile.merge`) and the others stay. The files of earlier
versions (format 2: the path under ``speedup``; format 1: no ``kind``, the online agent under ``algo``, no path at all,
``fps`` or ``fps_estimate`` instead of the frames per update, ``hardware`` as an object) are read as they are and
written in today's format.

One FPS (:func:`rate`): frames / seconds of the end-to-end entry of the agent, batch size and path (the one timed as
the loop trains, ``phase_sync`` false, where there is one: it is what a run sees), else update-bound, frames per
update / seconds per update of the update entry, with the run's frames per update (``train.update_every_steps x
env.action_repeat``) where the reader knows the run, else the bench config's (recorded in the entry).

This module imports nothing heavy (no torch): `repro plan` and the analysis read it.
"""

from __future__ import annotations

import json
import math
import os
import socket
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from repro.config.errors import UserError

FORMAT = 3  # 2: the path under "speedup"; 1: files without ``kind``/``format`` (the online agent under ``algo``)
ONLINE, OFFLINE, DATA, ROOFLINE = "online", "offline", "data", "roofline"
KINDS = (ONLINE, OFFLINE, DATA, ROOFLINE)
# The speed-up paths: what a run trains with (:func:`path_of`) and the config overrides that turn each on
PATHS = ("plain", "amp", "compile", "fast")
PATH_FLAGS: dict[str, list[str]] = {"plain": [], "amp": ["agent.amp=true"], "compile": ["agent.compile=true"],
                                    "fast": ["agent.fast=true"]}
BENCH_FRAMES_PER_UPDATE = 4.0  # an entry of a file that recorded none: update_every_steps 2 x action_repeat 2
E2E, UPDATE_BOUND = "e2e", "update-bound"  # where a rate comes from


class BenchFormatError(UserError, ValueError):
    """A bench file that cannot be read (one line, with its path)."""


def _flag(section: Any, key: str) -> bool:
    value = section.get(key, False) if isinstance(section, Mapping) else getattr(section, key, False)
    return bool(value)


def path_of(agent: Any, fast: Mapping[str, Any] | None = None) -> str:
    """The speed-up path a run trains with, from its agent section (``agent.fast``, ``agent.compile``,
    ``agent.amp``; a mapping or a typed section) or from the ``FastPlan`` its resolved.json records (``fast``,
    repro/agent/fast.py): ``fast`` when ``agent.fast`` is on (whatever else it turns on: the plan is resolved from
    the device, so the bench's ``fast`` entry of that device is what the run trains), else ``compile``, ``amp``,
    ``plain``."""
    if fast or _flag(agent, "fast"):
        return "fast"
    if _flag(agent, "compile"):
        return "compile"
    return "amp" if _flag(agent, "amp") else "plain"


# ---------------------------------------------------------------- entries
def _positive(value: Any, what: str) -> float:
    x = float(value)
    if not math.isfinite(x) or x <= 0:
        raise ValueError(f"{what} must be positive (got {value!r})")
    return x


def _path(r: Mapping[str, Any]) -> str:
    path = str(r.get("path", r.get("speedup")) or "plain")  # format 2 and earlier: "speedup"
    if path not in PATHS:
        raise ValueError(f"unknown speed-up path {path!r} (one of {', '.join(PATHS)})")
    return path


def _agent(r: Mapping[str, Any]) -> str:
    name = r.get("agent", r.get("algo"))
    if not name:
        raise ValueError("an entry without 'agent'")
    return str(name)


def _num(x: float) -> int | float:
    """``x`` as an int where it is one (JSON ``100``, not ``100.0``)."""
    return int(x) if float(x).is_integer() else x


def _optional_int(value: Any) -> int | None:
    return int(value) if value else None


def _optional_float(value: Any) -> float | None:
    return None if value is None else float(value)


def machine_load() -> dict[str, Any]:
    """The machine's 1-minute load average and its cores, recorded beside each entry a bench times (``load``,
    ``cores``); empty where the system has no load average."""
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):
        return {}
    return {"load": round(load, 2), "cores": os.cpu_count() or 1}


def loaded(load: float | None, cores: int | None) -> bool:
    """Whether a load average of ``load`` on ``cores`` cores is a machine under load: above its cores, so other
    work shared them with what was timed (whose time is then too long)."""
    return load is not None and bool(cores) and load > (cores or 0)


def under_load(entry: Any) -> bool:
    """Whether ``entry`` (an entry with ``load`` and ``cores``) was timed under load (:func:`loaded`)."""
    return loaded(getattr(entry, "load", None), getattr(entry, "cores", None))


def _load_json(entry: Any) -> dict[str, Any]:
    return {} if entry.load is None else {"load": entry.load, "cores": entry.cores}


_LOAD_KEYS = {"load", "cores"}
_UPDATE_KEYS = {"agent", "algo", "batch_size", "path", "speedup", "update_seconds", "frames_per_update",
                "fps_estimate", "fps", "peak_device_bytes", *_LOAD_KEYS}
_E2E_KEYS = {"agent", "algo", "batch_size", "path", "speedup", "frames", "seconds", "phase_sync", "profile", "phases",
             "peak_device_bytes", "fps", *_LOAD_KEYS}
_OFFLINE_KEYS = {"agent", "algo", "batch_size", "update_seconds", *_LOAD_KEYS}


@dataclass(frozen=True)
class UpdateEntry:
    """One update timed (``repro bench update``): median seconds of an agent's update at a batch size on a path."""

    agent: str
    batch_size: int
    path: str
    update_seconds: float
    frames_per_update: float = BENCH_FRAMES_PER_UPDATE  # of the bench's config (a run may have its own)
    peak_device_bytes: int | None = None
    load: float | None = None  # the machine's 1-minute load average when it was timed (None: not recorded)
    cores: int | None = None  # the machine's cores then
    extra: dict[str, Any] = field(default_factory=dict, compare=False)  # repeats, seconds_each, ...

    @property
    def fps(self) -> float:
        return self.frames_per_update / self.update_seconds

    @property
    def key(self) -> tuple[str, int, str]:
        """What a later measurement of the same setting replaces: (agent, batch size, path)."""
        return (self.agent, self.batch_size, self.path)

    @classmethod
    def read(cls, r: Mapping[str, Any]) -> UpdateEntry:
        seconds = _positive(r["update_seconds"], "update_seconds")
        fpu = r.get("frames_per_update")
        if fpu is None:  # format 1: the update-bound estimate it printed, at its config's frames per update
            estimate = r.get("fps_estimate", r.get("fps"))
            fpu = float(estimate) * seconds if estimate else BENCH_FRAMES_PER_UPDATE
        return cls(_agent(r), int(r["batch_size"]), _path(r), seconds,
                   _positive(fpu, "frames per update"), _optional_int(r.get("peak_device_bytes")),
                   _optional_float(r.get("load")), _optional_int(r.get("cores")),
                   {k: v for k, v in r.items() if k not in _UPDATE_KEYS})

    def to_json(self) -> dict[str, Any]:
        out = {"agent": self.agent, "batch_size": self.batch_size, "path": self.path,
               "update_seconds": self.update_seconds, "frames_per_update": _num(self.frames_per_update),
               "fps_estimate": round(self.fps, 3), **_load_json(self), **self.extra}
        if self.peak_device_bytes:
            out["peak_device_bytes"] = self.peak_device_bytes
        return out


@dataclass(frozen=True)
class E2EEntry:
    """A short training loop timed end to end (``repro bench e2e``): frames trained over their wall clock."""

    agent: str
    batch_size: int
    path: str
    frames: float
    seconds: float
    phase_sync: bool = True  # False: timed as it trains (the phases do not wait for the device)
    profile: str | None = None  # "tiny": the main job's profile, else the agent's own settings
    phases: dict[str, float] = field(default_factory=dict)
    peak_device_bytes: int | None = None
    load: float | None = None  # as UpdateEntry's
    cores: int | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False)  # task, updates, cpu, gpu, ...

    @property
    def fps(self) -> float:
        return self.frames / self.seconds

    @property
    def key(self) -> tuple[str, int, str | None, str, bool]:
        """What a later measurement of the same setting replaces."""
        return (self.agent, self.batch_size, self.profile, self.path, self.phase_sync)

    @classmethod
    def read(cls, r: Mapping[str, Any]) -> E2EEntry:
        return cls(_agent(r), int(r["batch_size"]), _path(r), _positive(r["frames"], "e2e frames"),
                   _positive(r["seconds"], "e2e seconds"), bool(r.get("phase_sync", True)), r.get("profile"),
                   {str(k): float(v) for k, v in (r.get("phases") or {}).items()},
                   _optional_int(r.get("peak_device_bytes")), _optional_float(r.get("load")),
                   _optional_int(r.get("cores")), {k: v for k, v in r.items() if k not in _E2E_KEYS})

    def to_json(self) -> dict[str, Any]:
        out = {"agent": self.agent, "batch_size": self.batch_size, "profile": self.profile, "path": self.path,
               "phase_sync": self.phase_sync, "frames": _num(self.frames), "seconds": self.seconds,
               "phases": self.phases, "fps": round(self.fps, 3), **_load_json(self), **self.extra}
        if self.peak_device_bytes:
            out["peak_device_bytes"] = self.peak_device_bytes
        return out


@dataclass(frozen=True)
class OfflineEntry:
    """One update of an offline learner's agent (or the online reference) timed (``repro bench offline``)."""

    agent: str
    batch_size: int
    update_seconds: float
    load: float | None = None  # as UpdateEntry's
    cores: int | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False)  # learner, own_batch, over_drqv2, ...

    @property
    def key(self) -> tuple[str, int]:
        """What a later measurement replaces: (agent, batch size)."""
        return (self.agent, self.batch_size)

    @classmethod
    def read(cls, r: Mapping[str, Any]) -> OfflineEntry:
        return cls(_agent(r), int(r["batch_size"]), _positive(r["update_seconds"], "update_seconds"),
                   _optional_float(r.get("load")), _optional_int(r.get("cores")),
                   {k: v for k, v in r.items() if k not in _OFFLINE_KEYS})

    def to_json(self) -> dict[str, Any]:
        return {"agent": self.agent, "batch_size": self.batch_size, "update_seconds": self.update_seconds,
                **_load_json(self), **self.extra}


DATA_KEYS = ("transitions", "batch_size", "load_seconds", "offline_batches_per_s", "online_batches_per_s")


@dataclass(frozen=True)
class DataEntry:
    """A dataset's load and sampling timed (``repro bench data``): its size, load seconds and batches per second of
    the offline and the online buffer at one batch size (``extra``: the rest, its ratios and memory)."""

    transitions: int
    batch_size: int | None = None
    load_seconds: float | None = None
    offline_batches_per_s: float | None = None
    online_batches_per_s: float | None = None
    extra: dict[str, Any] = field(default_factory=dict, compare=False)

    @classmethod
    def read(cls, r: Mapping[str, Any]) -> DataEntry:
        def num(key: str) -> float | None:
            return None if r.get(key) is None else float(r[key])

        return cls(int(r["transitions"]), _optional_int(r.get("batch_size")), num("load_seconds"),
                   num("offline_batches_per_s"), num("online_batches_per_s"),
                   {k: v for k, v in r.items() if k not in DATA_KEYS})

    def to_json(self) -> dict[str, Any]:
        fields = dict(zip(DATA_KEYS, (self.transitions, self.batch_size, self.load_seconds,
                                       self.offline_batches_per_s, self.online_batches_per_s)))
        return {**{k: v for k, v in fields.items() if v is not None}, **self.extra}


@dataclass
class BenchFile:
    """One bench file: its kind, device and hardware, and its typed entries (``rest``: what else it holds, kept as
    it is: ratios, replay memory, the data bench's measurements, the roofline's)."""

    kind: str
    device: str
    hardware: str = ""
    path: Path | None = None
    device_memory_bytes: int | None = None
    updates: list[UpdateEntry] = field(default_factory=list)
    e2e: list[E2EEntry] = field(default_factory=list)
    offline: list[OfflineEntry] = field(default_factory=list)
    data: DataEntry | None = None
    rest: dict[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.path.name if self.path is not None else "(bench)"

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind, "format": FORMAT, "device": self.device, "hardware": self.hardware,
                               **self.rest}
        if self.device_memory_bytes:
            out["device_memory_bytes"] = self.device_memory_bytes
        if self.kind == ONLINE:
            out["results"] = [e.to_json() for e in self.updates]
            if self.e2e:
                out["e2e"] = [e.to_json() for e in self.e2e]
        elif self.kind == OFFLINE:
            out["results"] = [e.to_json() for e in self.offline]
        elif self.data is not None:
            out.update(self.data.to_json())
        return out

    def merge(self, updates: Iterable[UpdateEntry] = (), e2e: Iterable[E2EEntry] = (),
              offline: Iterable[OfflineEntry] = ()) -> None:
        """Add the entries of a new bench, each replacing the entry of the same setting (its ``key``: agent, batch
        size and path; an e2e entry also its profile and phase timing; the device is the file's), the others kept."""
        self.updates = _merged(self.updates, updates)
        self.e2e = _merged(self.e2e, e2e)
        self.offline = _merged(self.offline, offline)

    def under_load(self) -> list[UpdateEntry | E2EEntry | OfflineEntry]:
        """The entries timed under load (:func:`under_load`)."""
        entries: list[UpdateEntry | E2EEntry | OfflineEntry] = [*self.updates, *self.e2e, *self.offline]
        return [e for e in entries if under_load(e)]


def _merged(old: list[Any], new: Iterable[Any]) -> list[Any]:
    """``old`` with ``new`` added, an old entry of the same ``key`` replaced in its place."""
    fresh = {e.key: e for e in new}
    kept = [fresh.pop(e.key) if e.key in fresh else e for e in old]
    return kept + list(fresh.values())


def _hardware(value: Any) -> str:
    if isinstance(value, Mapping):  # format 1 of some writers: {"device": ..., "cpu": ...}
        device, cpu = str(value.get("device") or ""), str(value.get("cpu") or "")
        if device.startswith("cuda"):
            return f"{device.split(':', 1)[-1].strip()} (GPU)"
        return f"CPU: {cpu}" if cpu else device
    return str(value or "")


def _kind(data: Mapping[str, Any], name: str) -> str:
    kind = data.get("kind")
    if kind is not None:
        if kind not in KINDS:
            raise ValueError(f"unknown kind {kind!r}")
        return str(kind)
    if "roofline" in data:
        return ROOFLINE
    if name.startswith("bench-offline-data") or "offline_batches_per_s" in data:
        return DATA
    if name.startswith("bench-offline") or any(isinstance(r, Mapping) and "learner" in r
                                               for r in data.get("results", []) or []):
        return OFFLINE  # format 1's offline entries name their learner
    return ONLINE


def _device_of(data: Mapping[str, Any], name: str) -> str:
    device = data.get("device")
    if device:
        return str(device).split(":")[0]
    stem = name[:-5] if name.endswith(".json") else name
    return stem.rsplit("-", 1)[-1] if stem.startswith("bench-") else "unknown"


def parse(data: Any, path: Path | None = None) -> BenchFile:
    """A :class:`BenchFile` from a bench JSON object of any version; :class:`BenchFormatError` (one line, naming the
    file) for what is not one."""
    where = f"bench file {path}" if path is not None else "bench JSON"
    if not isinstance(data, Mapping):
        raise BenchFormatError(f"{where} is not a `repro bench` JSON (not an object)")
    name = path.name if path is not None else ""
    try:
        kind = _kind(data, name)
        results = data.get("results", [])
        if kind in (ONLINE, OFFLINE) and not isinstance(results, list):
            raise ValueError("no 'results' list")
        e2e = data.get("e2e") or []
        if not isinstance(e2e, list):
            raise ValueError("'e2e' is not a list")
        bench = BenchFile(kind, _device_of(data, name), _hardware(data.get("hardware")), path,
                          _optional_int(data.get("device_memory_bytes")))
        if kind == ONLINE:
            bench.updates = [UpdateEntry.read(r) for r in results]
            bench.e2e = [E2EEntry.read(r) for r in e2e]
        elif kind == OFFLINE:
            bench.offline = [OfflineEntry.read(r) for r in results]
        elif kind == DATA:
            bench.data = DataEntry.read({k: v for k, v in data.items() if k in DATA_KEYS})
        skip = {"kind", "format", "device", "hardware", "device_memory_bytes", "path", *(
            ("results", "e2e") if kind in (ONLINE, OFFLINE) else DATA_KEYS if kind == DATA else ())}
        bench.rest = {k: v for k, v in data.items() if k not in skip}
    except (KeyError, TypeError, ValueError) as exc:
        raise BenchFormatError(f"{where}: bad entry ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})"
                               ) from None
    return bench


def read(path: Path) -> BenchFile:
    """The bench file at ``path`` (:class:`BenchFormatError`, one line, when it cannot be read)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise BenchFormatError(f"cannot read bench file {path}: {str(exc).splitlines()[0]}") from None
    return parse(data, Path(path))


def read_or_new(path: Path, kind: str, device: str) -> BenchFile:
    """The file at ``path`` to add entries to, or a new one of ``kind`` (an unreadable file is replaced)."""
    if path.is_file():
        try:
            bench = read(path)
            if bench.kind == kind:
                return bench
        except BenchFormatError:
            pass
    return BenchFile(kind, device.split(":")[0], path=path)


# ---------------------------------------------------------------- where the files lie
def file_name(kind: str, device: str, host: str | None = None) -> str:
    """The bench file of ``kind`` for this host (or ``host``) and ``device``."""
    host = host or socket.gethostname()
    dev = device.split(":")[0]
    return {ONLINE: f"bench-{host}-{dev}.json", OFFLINE: f"bench-offline-{host}-{dev}.json",
            DATA: f"bench-offline-data-{host}.json", ROOFLINE: f"bench-roofline-{host}-{dev}.json"}[kind]


def _kind_of_name(name: str) -> str:
    for prefix, kind in (("bench-offline-data-", DATA), ("bench-offline-", OFFLINE), ("bench-roofline-", ROOFLINE)):
        if name.startswith(prefix):
            return kind
    return ONLINE


def files(folder: Path, kind: str = ONLINE, device: str | None = None) -> list[Path]:
    """The ``bench-*.json`` files of ``kind`` under ``folder`` (of ``device``, when given), newest first."""
    found = [p for p in folder.glob("bench-*.json") if _kind_of_name(p.name) == kind
             and (device is None or p.stem.endswith(f"-{device}"))]
    return sorted(found, key=lambda p: p.stat().st_mtime, reverse=True)


def newest_device(folder: Path) -> str | None:
    """The device of the newest online bench file under ``folder`` (None: there is none)."""
    found = files(folder)
    return found[0].stem.rsplit("-", 1)[-1] if found else None


# ---------------------------------------------------------------- one FPS
@dataclass(frozen=True)
class Rate:
    """A run's speed on a bench's device: frames per second and where it comes from."""

    fps: float
    source: str  # E2E or UPDATE_BOUND
    peak_device_bytes: int | None = None
    load: float | None = None  # the load average and cores when the entry was timed (under_load)
    cores: int | None = None


def rate(bench: BenchFile, agent: str, batch_size: int, path: str = "plain",
         frames_per_update: float | None = None) -> Rate | None:
    """The one FPS of (``agent``, ``batch_size``, ``path``) on ``bench`` (module docstring), None when the bench
    times neither its loop nor its update. ``frames_per_update``: the run's (None: the bench's own config's)."""
    loops = [e for e in bench.e2e if (e.agent, e.batch_size, e.path) == (agent, batch_size, path)]
    if loops:
        e2e = sorted(loops, key=lambda e: e.phase_sync)[0]  # as it trains, where timed so
        return Rate(e2e.fps, E2E, e2e.peak_device_bytes, e2e.load, e2e.cores)
    updates = [u for u in bench.updates if (u.agent, u.batch_size, u.path) == (agent, batch_size, path)]
    if not updates:
        return None
    upd = updates[-1]
    fpu = upd.frames_per_update if frames_per_update is None else frames_per_update
    return Rate(fpu / upd.update_seconds, UPDATE_BOUND, upd.peak_device_bytes, upd.load, upd.cores)


def settings(bench: BenchFile) -> list[tuple[str, int, str]]:
    """Every (agent, batch size, path) the online ``bench`` times, in the file's order."""
    seen: dict[tuple[str, int, str], None] = {}
    for u in bench.updates:
        seen[(u.agent, u.batch_size, u.path)] = None
    for e in bench.e2e:
        seen[(e.agent, e.batch_size, e.path)] = None
    return list(seen)


def offline_entry(bench: BenchFile | None, agent: str, batch_size: int) -> OfflineEntry | None:
    """The entry of ``agent`` at ``batch_size`` in an offline bench file."""
    if bench is None:
        return None
    found = [e for e in bench.offline if (e.agent, e.batch_size) == (agent, batch_size)]
    return found[-1] if found else None


def offline_seconds(bench: BenchFile | None, agent: str, batch_size: int) -> float | None:
    """Seconds of one update of ``agent`` at ``batch_size`` in an offline bench file."""
    entry = offline_entry(bench, agent, batch_size)
    return None if entry is None else entry.update_seconds
