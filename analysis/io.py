"""Atomic file writing: every output is written to a temporary file in the same folder, then renamed; figures are
not drawn again when their content and their files are unchanged (:func:`save_figure_files`)."""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import types
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from repro.runs.fsutil import atomic_write

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def _atomic_replace(path: Path, write) -> Path:
    path = Path(path)
    atomic_write(path, write)
    return path


def atomic_write_text(path: Path | str, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    return _atomic_replace(Path(path), lambda fh: fh.write(text.encode("utf-8")))


def atomic_savefig(fig: Figure, path: Path | str, **kwargs) -> Path:
    """Save a matplotlib figure atomically; the format comes from the suffix of ``path``."""
    path = Path(path)
    fmt = path.suffix.lstrip(".")
    return _atomic_replace(path, lambda fh: fig.savefig(fh, format=fmt, **kwargs))


class _ContentPickler(pickle.Pickler):
    """Pickles a figure as its content: without what differs between two drawings of the same figure (the ids
    that key a transform's parents, the pyplot figure number, an array's memory order) and with functions (tick
    formatters) as their name, defaults and captured values (their code is the analysis code, which the cache's code
    version holds). The two names left out are matplotlib internals: a pinned, tested exception (docs/deviations.md,
    "Third-party internals still used"; if matplotlib renames them, keys hold ids and every figure is drawn again,
    never a stale one)."""

    def reducer_override(self, obj: Any) -> Any:
        kind = _KINDS.get(type(obj))
        if kind is None:
            kind = _KINDS[type(obj)] = _kind(type(obj))
        if kind == "state":
            reduced = obj.__reduce_ex__(5)
            if isinstance(reduced, tuple) and len(reduced) >= 3 and isinstance(reduced[2], dict):
                state = {k: v for k, v in reduced[2].items() if k not in ("_parents", "_number")}
                return (reduced[0], reduced[1], state, *reduced[3:])
        elif kind == "function":
            cells = tuple(c.cell_contents for c in obj.__closure__ or ())
            return (str, (repr((obj.__module__, obj.__qualname__, obj.__code__.co_firstlineno)),),
                    (obj.__defaults__, obj.__kwdefaults__, cells))
        elif kind == "set":
            return (type(obj), (sorted(obj, key=repr),))
        elif kind == "masked" and not obj.dtype.hasobject:
            return (str, (f"masked {obj.dtype.str} {obj.shape}",),
                    (np.ascontiguousarray(obj.data).tobytes(), np.ascontiguousarray(np.ma.getmaskarray(obj)).tobytes(),
                     repr(obj.fill_value)))
        elif kind == "array" and not obj.dtype.hasobject:
            # its values, not its memory layout (a computed array may be Fortran-ordered, the same one unpickled not)
            return (str, (f"ndarray {obj.dtype.str} {obj.shape}",), np.ascontiguousarray(obj).tobytes())
        return NotImplemented


_KINDS: dict[type, str] = {}  # an object's type -> how _ContentPickler reduces it (decided once per type)


def _kind(cls: type) -> str:
    from matplotlib.figure import Figure
    from matplotlib.transforms import TransformNode

    if issubclass(cls, (TransformNode, Figure)):
        return "state"
    if cls is types.FunctionType:
        return "function"
    if issubclass(cls, (set, frozenset)):
        return "set"
    if cls is np.ma.MaskedArray:
        return "masked"
    if cls is np.ndarray:
        return "array"
    return ""


def figure_key(fig: Figure, **savefig_kwargs: Any) -> str | None:
    """A digest of the figure's content, the save options and matplotlib's settings: equal digests draw equal
    files. None when the figure holds something that cannot be serialised (then it is always drawn)."""
    import matplotlib

    buf = io.BytesIO()
    try:
        _ContentPickler(buf, protocol=pickle.HIGHEST_PROTOCOL).dump(
            (fig, sorted(savefig_kwargs.items()), sorted((k, repr(v)) for k, v in matplotlib.rcParams.items())))
    except (pickle.PicklingError, TypeError, AttributeError, ValueError, RecursionError):
        return None
    return hashlib.sha1(buf.getvalue()).hexdigest()


def _signatures(paths: Sequence[Path]) -> tuple[tuple[int, int], ...] | None:
    try:
        return tuple((st.st_size, st.st_mtime_ns) for st in (os.stat(p) for p in paths))
    except OSError:
        return None


def save_figure_files(fig: Figure, paths: Sequence[Path], **savefig_kwargs: Any) -> list[Path]:
    """Save ``fig`` atomically to each of ``paths`` (format from the suffix), unless the command's cache
    (analysis/cache.py, section ``figures``) holds this figure's content key for these paths and the files are on
    disk as it wrote them (same size and modification time): then nothing is drawn."""
    from analysis import cache

    paths = [Path(p) for p in paths]
    active = cache.current() if cache.active() else None
    key = figure_key(fig, **savefig_kwargs) if active is not None else None
    entry = (tuple(str(p.resolve()) for p in paths), key)
    if active is not None and key is not None:
        if active.reuse("figures", entry, lambda sig: sig is not None and sig == _signatures(paths)) is not None:
            return paths
    for path in paths:
        atomic_savefig(fig, path, **savefig_kwargs)
    if active is not None and key is not None:
        active.put("figures", entry, _signatures(paths))
    return paths
