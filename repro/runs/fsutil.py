"""Atomic file writes: write a temporary file in the same folder, fsync, then rename over the target.

Files get the ordinary mode a plain ``open()`` would give them (0666 less the process umask), not
mkstemp's private 0600, so a dataset or run made by one user can be read by another. A write that fails
(a full disk, a file size limit) raises an ``OSError`` naming the target file and leaves the target as it
was; the temporary file is removed.
"""

from __future__ import annotations

import errno
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO


def current_umask() -> int:
    """The process umask, read without changing it where Linux allows (``/proc/self/status``)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The mode ``open(path, "w")`` gives a new file: 0666 less the umask."""
    return 0o666 & ~current_umask()


def named_os_error(exc: OSError, path: str | os.PathLike) -> OSError:
    """``exc`` with ``path`` as its file name (a failed ``write`` or ``fsync`` carries none)."""
    if exc.filename:
        return exc
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path))


def atomic_write(path: str | os.PathLike, write: Callable[[IO[bytes]], object]) -> None:
    """Call ``write(f)`` on a temporary binary file, then atomically replace ``path`` with it."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise named_os_error(exc, path) from None
    try:
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), file_mode())
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise named_os_error(exc, path) from None
        raise
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    atomic_write(path, lambda f: f.write(text.encode()))


def remove_torn_temporaries(folder: str | os.PathLike) -> list[Path]:
    """Remove ``.NAME.*.tmp`` files that a killed ``atomic_write`` left in ``folder`` (not recursive).

    Only call this while holding the folder's writer lock: another writer's temporary file is live."""
    removed: list[Path] = []
    folder = Path(folder)
    if not folder.is_dir():
        return removed
    for p in folder.glob(".*.tmp"):
        if p.is_file():
            p.unlink(missing_ok=True)
            removed.append(p)
    return removed


FULL = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)  # a full disk, a file size limit, a quota


def write_error_message(exc: OSError) -> str:
    """One line for an OSError: for a full disk, file size limit or quota, the file, the reason and that
    re-running the command resumes; otherwise the file and the reason."""
    where = f"{exc.filename}: " if exc.filename else ""
    if exc.errno not in FULL:
        return f"{where}{exc.strerror or exc}"
    return (f"cannot write {where}{exc.strerror or exc}; nothing written before is lost: free space (or raise "
            "the limit) and re-run the same command to resume")
