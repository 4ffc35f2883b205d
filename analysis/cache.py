"""What one analysis computed, kept for the next: the incremental report.

A result is reused only when everything it depends on is unchanged; its key holds those inputs:

* ``runs``: one run directory as :func:`analysis.load.load_run` read it, keyed by the directory and the size and
  modification time (ns) of each of its files;
* ``intervals``: one bootstrap interval (:mod:`analysis.bootstrap`), keyed by its statistic, the values it was
  computed from (their bytes), the repetitions, the random state and the interval size: a table cell whose
  runs did not change reuses its CI however many other runs did;
* ``frames``: F13's random-action frames of a task (they depend on no run);
* ``tsne``: one of F6's embeddings, keyed by the points embedded (the raw panel depends on no run);
  ``tsne_result``: F6's embeddings and scores, keyed by the checkpoint's path, size and modification time;
* ``figures``: a figure's PNG and PDF as written, keyed by the figure's content (:func:`figure_key`): an unchanged
  figure whose files are still on disk as written is not drawn again;
* ``compose``: a sweep run's composed config (``repro plan --claims``), keyed by its overrides and the config files.

The file holds its format (:data:`FORMAT`: a file of another format is not read). Every key also holds the code
version (:func:`code_version`: the analysis code's sources, the registered method labels and the numeric libraries'
versions), so changed code recomputes everything. The file is
``<out>/.cache/analysis.pkl`` (one per output folder: ``repro report``, ``figures``, ``claims`` and ``plan --claims``
share the default one), written atomically at the end of a command. What a command did not use is kept for the next
(``repro claims`` after a report keeps the report's figures), except what it superseded: a run directory read
again drops its older entries, a figure drawn again its older entry, a new learning-curve table or published-curve
table the older one. A command that
prunes (``repro report``: it uses everything a report needs) also drops the unused entries of each section it used,
so the file holds one tree's results. ``--no-cache`` neither reads nor writes it.

Within one process the same cache (or, with none, a process-wide memo) serves every artifact, claim, the
calibration and the power table: nothing is computed twice.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import importlib.metadata
import os
import pickle
from collections.abc import Callable, Hashable, Iterator
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")

CACHE_DIR = ".cache"
CACHE_FILE = "analysis.pkl"
FORMAT = 2  # of the file (2: the runs table's agent column renamed to ``agent``, issue 51); another is not read
ROOT = Path(__file__).resolve().parents[1]
# the code whose output is cached: the analysis, the figures and the run-format readers and config it reads
CODE_DIRS = ("analysis", "paper_figures", "repro_app", "repro/runs", "repro/config", "repro_data")
LIBRARIES = ("numpy", "pandas", "scipy", "matplotlib", "seaborn", "scikit-learn", "rliable")
# sections holding one entry per tree: a newly computed one supersedes the stored ones
SINGLE = frozenset({"curves", "published"})
# sections whose entries a newer entry of the same subject supersedes (:func:`_subject`)
SUBJECTS = frozenset({"runs", "figures"})


@functools.cache
def code_version() -> str:
    """A digest of the analysis code (sources and packaged tables), the registered method labels (plugins
    included) and the libraries' versions."""
    h = hashlib.sha1()
    for folder in CODE_DIRS:
        for path in sorted((ROOT / folder).rglob("*")):
            if path.is_file() and path.suffix in (".py", ".csv", ".yaml", ".json") and "__pycache__" not in path.parts:
                h.update(str(path.relative_to(ROOT)).encode())
                h.update(path.read_bytes())
    for lib in LIBRARIES:
        try:
            h.update(f"{lib}={importlib.metadata.version(lib)}".encode())
        except importlib.metadata.PackageNotFoundError:
            h.update(lib.encode())
    from analysis.identity import agent_labels

    h.update(repr(sorted(agent_labels().items())).encode())
    return h.hexdigest()


def file_signature(folder: Path) -> tuple[tuple[str, int, int], ...]:
    """(name, size, mtime in ns) of every file directly in ``folder``, sorted by name."""
    out = []
    with os.scandir(folder) as entries:
        for entry in entries:
            if entry.is_file():
                st = entry.stat()
                out.append((entry.name, st.st_size, st.st_mtime_ns))
    return tuple(sorted(out))


class AnalysisCache:
    """Sections of key -> value; ``path`` None keeps them in memory only. Counts hits and misses per section."""

    def __init__(self, path: Path | None = None) -> None:
        self.path = path
        self.version = code_version() if path is not None else ""
        self._old: dict[str, dict[Hashable, Any]] = {}
        self._new: dict[str, dict[Hashable, Any]] = {}
        self.hits: dict[str, int] = {}
        self.misses: dict[str, int] = {}
        self.scratch: dict[str, Any] = {}  # values for this command only (never written)
        if path is not None and path.exists():
            try:
                with path.open("rb") as fh:
                    stored = pickle.load(fh)
            except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ImportError, ValueError):
                stored = None  # unreadable or from other code: start afresh
            if isinstance(stored, dict) and stored.get("format") == FORMAT and stored.get("version") == self.version:
                self._old = stored["sections"]

    def get(self, section: str, key: Hashable, compute: Callable[[], T]) -> T:
        """The value under ``key``, from this command, the stored cache, or ``compute()``."""
        new = self._new.setdefault(section, {})
        if key in new:
            self.hits[section] = self.hits.get(section, 0) + 1
            return new[key]
        old = self._old.get(section, {})
        if key in old:
            self.hits[section] = self.hits.get(section, 0) + 1
            new[key] = old[key]
            return new[key]
        self.misses[section] = self.misses.get(section, 0) + 1
        new[key] = value = compute()
        return value

    def peek(self, section: str, key: Hashable) -> Any | None:
        """The value under ``key`` if this command or the stored cache has it (counted as reused), else None."""
        return self.reuse(section, key, lambda _: True)

    def reuse(self, section: str, key: Hashable, check: Callable[[Any], bool]) -> Any | None:
        """The value under ``key`` if this command or the stored cache has it and ``check(value)`` holds (counted as
        reused), else None (not counted: the caller computes and :meth:`put` s it)."""
        for entries in (self._new.get(section, {}), self._old.get(section, {})):
            if key in entries and check(entries[key]):
                return self.get(section, key, lambda: None)
        return None

    def put(self, section: str, key: Hashable, value: Any) -> None:
        """Keep ``value`` under ``key`` (computed by the caller, e.g. several at once)."""
        self.misses[section] = self.misses.get(section, 0) + 1
        self._new.setdefault(section, {})[key] = value

    def summary(self) -> str:
        """``runs 1145 reused, 0 computed; intervals ...``."""
        names = sorted({*self.hits, *self.misses})
        return "; ".join(f"{n} {self.hits.get(n, 0)} reused, {self.misses.get(n, 0)} computed" for n in names)

    def kept(self, prune: bool = False) -> dict[str, dict[Hashable, Any]]:
        """What :meth:`save` writes: the entries this command used, and the stored ones it did not use unless
        superseded (see the module docstring); ``prune``: none of the unused entries of a section this command
        used."""
        out = {name: dict(entries) for name, entries in self._new.items()}
        for name, old in self._old.items():
            new = self._new.get(name, {})
            if prune and new:
                continue
            if name in SINGLE and new:
                continue
            superseded = {_subject(name, k) for k in new} if name in SUBJECTS else set()
            target = out.setdefault(name, {})
            for key, value in old.items():
                if key not in target and not (superseded and _subject(name, key) in superseded):
                    target[key] = value
        return out

    def save(self, prune: bool = False) -> None:
        """Write :meth:`kept` atomically; nothing without a path."""
        if self.path is None:
            return
        from repro.runs.fsutil import atomic_write

        self.path.parent.mkdir(parents=True, exist_ok=True)
        payload = {"format": FORMAT, "version": self.version, "sections": self.kept(prune)}
        atomic_write(self.path, lambda f: pickle.dump(payload, f, protocol=pickle.HIGHEST_PROTOCOL))


def _subject(section: str, key: Hashable) -> Hashable:
    """What an entry is of, without the version of it its key names: a ``runs`` key's (results root, run directory),
    a ``figures`` key's files."""
    if not isinstance(key, tuple):
        return key
    return key[:2] if section == "runs" else key[0]


_PROCESS = AnalysisCache()  # the memo when no command opened a cache
_active: AnalysisCache | None = None


def active() -> bool:
    """Whether a command opened a cache (:func:`opened`) in this process."""
    return _active is not None


def current() -> AnalysisCache:
    """The cache of the command running in this process, or the process-wide memo."""
    return _active if _active is not None else _PROCESS


@contextlib.contextmanager
def opened(out_dir: Path | None, prune: bool = False) -> Iterator[AnalysisCache]:
    """The cache of ``out_dir`` for the duration of a command (``None``: in memory only, e.g. ``--no-cache``),
    written back when the block ends without an exception (``prune``: see :meth:`AnalysisCache.kept`)."""
    global _active
    cache = AnalysisCache(out_dir / CACHE_DIR / CACHE_FILE if out_dir is not None else None)
    previous, _active = _active, cache
    try:
        yield cache
        cache.save(prune)
    finally:
        _active = previous


PROCESS_LIMIT = 100_000  # entries of the process-wide memo before it starts afresh (long test sessions)


def lookup(section: str, key: Hashable, compute: Callable[[], T], process: bool = True) -> T:
    """``compute()`` once per key for the current command (see :func:`current`). ``process`` False: without a
    command's cache, compute every time (results too large to keep for the life of the process)."""
    if _active is None:
        if not process:
            return compute()
        if sum(len(v) for v in _PROCESS._new.values()) > PROCESS_LIMIT:
            _PROCESS._new.clear()
    return current().get(section, key, compute)
