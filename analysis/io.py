"""Atomic file writing: every output is written to a temporary file in the same folder, then renamed."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

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
