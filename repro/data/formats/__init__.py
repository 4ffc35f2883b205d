"""External dataset layouts, each with ``scan`` (check the layout, count episodes), ``read`` and ``write``."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from repro.data.dataset import DatasetError, Episode
from repro.data.formats import drqv2, vd4rl64, vd4rl84
from repro.data.formats.common import Scan


@dataclass(frozen=True)
class Format:
    name: str
    size: int  # the documented frame size (H = W) of the layout; other sizes need --resize
    scan: Callable[[Path], Scan]
    read: Callable[[Scan, int | None], Iterator[Episode]]  # (scan, resize to or None)
    write: Callable[[Iterable[Episode], Path], list[Path]]


FORMATS: dict[str, Format] = {m.NAME: Format(m.NAME, m.SIZE, m.scan, m.read, m.write)
                              for m in (vd4rl84, vd4rl64, drqv2)}


def get_format(name: str) -> Format:
    try:
        return FORMATS[name]
    except KeyError:
        raise DatasetError(f"unknown format '{name}' (known: {', '.join(FORMATS)})") from None


__all__ = ["FORMATS", "Format", "Scan", "get_format"]
