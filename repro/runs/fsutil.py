"""The one atomic writer (:func:`atomic_output`: a temporary file in the same folder, fsync, then rename over
the target), the one flock-with-holder lock (:func:`try_flock`) and the one check of an output folder
(:func:`writable_folder`).

Files get the ordinary mode a plain ``open()`` would give them (0666 less the process umask), not
mkstemp's private 0600, so a dataset or run made by one user can be read by another. A write that fails
(a full disk, a file size limit) raises an ``OSError`` naming the target file and leaves the target as it
was; the temporary file is removed.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO

from repro.config.errors import UserError


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


@contextmanager
def atomic_output(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """The one atomic writer: yield the path of a new temporary file beside ``path`` (``.NAME.XXXXXXXX`` +
    ``suffix``, with :func:`file_mode`) for the block to fill (by name: an encoder, a hard link); when the
    block ends, fsync it, atomically replace ``path`` with it and fsync the folder. When the block raises,
    the temporary file is removed and ``path`` is left as it was; an ``OSError`` names ``path``."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
        try:
            os.fchmod(fd, file_mode())
        finally:
            os.close(fd)
    except OSError as exc:
        raise named_os_error(exc, path) from None
    try:
        yield Path(tmp)
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.lexists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise named_os_error(exc, path) from None
        raise
    dir_fd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dir_fd)
    finally:
        os.close(dir_fd)


def atomic_write(path: str | os.PathLike, write: Callable[[IO[bytes]], object]) -> None:
    """Call ``write(f)`` on a temporary binary file, then atomically replace ``path`` with it
    (:func:`atomic_output`)."""
    with atomic_output(path) as tmp, open(tmp, "wb") as f:
        write(f)


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


class OutputPathError(UserError, ValueError):
    """An output folder a command cannot write (one line, exit 2), said before anything is written."""


def writable_folder(path: str | os.PathLike, what: str) -> Path:
    """The one rule for every output folder a command writes (``--out``, ``-r``, ``runtime.results_root``): ``path``
    (absolute, ``~`` expanded) when it is a folder this process can write, or one it can create (its nearest
    existing parent is a writable folder); otherwise :class:`OutputPathError` naming ``what`` (the option), checked
    before anything is written. Creates nothing."""
    path = Path(path).expanduser().absolute()
    parent = path
    while not os.path.lexists(parent) and parent != parent.parent:
        parent = parent.parent
    where = "" if parent == path else f" cannot be made: {parent}"
    if not parent.is_dir():
        kind = "a file, not a folder" if parent.is_file() else "not a folder"
        raise OutputPathError(f"{what} {path}{where} is {kind}")
    if not os.access(parent, os.W_OK | os.X_OK):
        read_only = os.statvfs(parent).f_flag & os.ST_RDONLY
        why = "is on a read-only filesystem" if read_only else "is not writable by this user"
        raise OutputPathError(f"{what} {path}{where} {why}")
    return path


FULL = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)  # a full disk, a file size limit, a quota


def write_error_message(exc: OSError) -> str:
    """One line for an OSError: for a full disk, file size limit or quota, the file, the reason and that
    re-running the command resumes; otherwise the file and the reason."""
    where = f"{exc.filename}: " if exc.filename else ""
    if exc.errno not in FULL:
        return f"{where}{exc.strerror or exc}"
    return (f"cannot write {where}{exc.strerror or exc}; nothing written before is lost: free space (or raise "
            "the limit) and re-run the same command to resume")


# ---------------------------------------------------------------------------------------------- flock with holder
@dataclass
class HolderLock:
    """An exclusive ``flock`` on a small file that names its holder (JSON: pid, host, ...), taken by
    :func:`try_flock`. The kernel releases it when the holder exits in any way (SIGKILL included), so a dead
    holder never blocks the next one (its file stays and names it). :meth:`release` removes the file, while still
    holding the lock, then unlocks: a process that opened the old file meanwhile finds it gone once it gets the
    lock and tries again on a new one (:func:`try_flock`), so a lock that ended leaves no file behind."""

    path: Path
    fd: int

    def release(self) -> None:
        if self.fd >= 0:
            try:
                if _same_file(self.fd, self.path):
                    self.path.unlink()
            except OSError:
                pass  # a read-only folder: the file stays, as after a kill
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> HolderLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def _same_file(fd: int, path: Path) -> bool:
    """Whether ``path`` still names the file open as ``fd`` (not removed, not replaced by a new file)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return False
    mine = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (mine.st_dev, mine.st_ino)


def try_flock(file: str | os.PathLike, holder: dict[str, object]) -> HolderLock | None:
    """Take the exclusive ``flock`` on ``file`` now (created if missing) and write ``holder`` into it as JSON;
    None when another process holds it (never waits). A lock taken on a file that its last holder removed on
    release is dropped and taken again on a new file. A filesystem without locks raises an ``OSError`` naming
    ``file``: an error, never a silent second holder."""
    file = Path(file)
    while True:
        fd = os.open(file, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return None
        except OSError as exc:
            os.close(fd)
            raise named_os_error(exc, file) from None
        if _same_file(fd, file):
            break
        fcntl.flock(fd, fcntl.LOCK_UN)  # the holder removed this file before releasing it: open the new one
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(holder).encode(), 0)
    except OSError as exc:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        raise named_os_error(exc, file) from None
    return HolderLock(file, fd)


def holder_words(file: str | os.PathLike) -> str:
    """Who last held (or holds) the lock ``file``, in words: ``pid P on HOST`` (``(since T)`` when it says),
    or ``another process`` when the file does not say."""
    try:
        info = json.loads(Path(file).read_text())
        since = f" (since {info['since']})" if "since" in info else ""
        return f"pid {info['pid']} on {info['host']}{since}"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


def flock_holder(file: str | os.PathLike) -> str | None:
    """Who holds the lock ``file`` now, in words (:func:`holder_words`); None when nobody does (writes nothing)."""
    try:
        fd = os.open(file, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return holder_words(file)
    finally:
        os.close(fd)  # closing drops a shared lock taken just now
    return None
