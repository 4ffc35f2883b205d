"""Warm starts for the local launcher (`repro sweep --warm-start`): each run's ``repro train`` is forked from a
server process that has already imported torch, dm_control and the trainer, instead of a fresh interpreter.

A fresh ``python -m repro train`` spends about 4 s of CPU importing torch (and torch._dynamo, which the first
optimizer pulls in), dm_control and Hydra before its first step; a tiny run lasts 10 to 30 s, so on a sweep of
tiny runs that is a fifth of the work. The server is Python's own ``multiprocessing`` fork server
(``set_forkserver_preload``): it imports those modules once, single-threaded, and forks a clean child per run.
The child then does what the plain path's subprocess does: stdin from /dev/null, stdout and stderr appended to
the run's log, the children's environment, SIGTERM when its parent dies (PR_SET_PDEATHSIG; the server dies
with the launcher: repro/launch/warm_server.py), and ``python -m repro train OVERRIDES`` (``runpy``; an uncaught
exception prints its traceback and exits 1, as the interpreter does), so a run's files and logs are those of the
plain path (tests/test_sweeps.py compares them). Off by default: the plain path starts every run
from nothing, which is what a user debugging one run expects.
"""

from __future__ import annotations

import multiprocessing
import multiprocessing.forkserver
import os
import runpy
import subprocess
import sys
import traceback
from pathlib import Path

from repro.launch.runner import die_with_parent

# The server's imports, in order: its tie to the launcher, then the heavy part of what `python -m repro train`
# imports before its first step (the trainer and below; the child imports the command line itself, a fraction of a
# second). A module that fails to import is skipped by the server, and the child imports it itself.
PRELOAD = ["repro.launch.warm_server", "repro.train.api", "torch._dynamo", "dm_control.suite"]


def _child(args: list[str], log: str, env: dict[str, str]) -> None:
    """In the forked child: the plain path's subprocess setup, then ``python -m repro ARGS``."""
    die_with_parent()
    os.environ.clear()
    os.environ.update(env)
    out = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.dup2(out, 1)
    os.dup2(out, 2)
    os.close(out)
    os.close(null)
    sys.argv = ["repro", *args]
    try:
        runpy.run_module("repro", run_name="__main__", alter_sys=True)
    except Exception:  # noqa: BLE001  (what the interpreter does with an uncaught exception, not multiprocessing)
        traceback.print_exc()
        raise SystemExit(1) from None


class WarmProcess:
    """A forked run with the part of :class:`subprocess.Popen`'s interface the launcher uses."""

    def __init__(self, proc: multiprocessing.process.BaseProcess):
        self._proc = proc

    @property
    def pid(self) -> int:
        assert self._proc.pid is not None
        return self._proc.pid

    @property
    def returncode(self) -> int | None:
        return self._proc.exitcode  # like Popen: -N when ended by signal N

    def poll(self) -> int | None:
        return None if self._proc.is_alive() else self._proc.exitcode

    def terminate(self) -> None:
        self._proc.terminate()

    def kill(self) -> None:
        self._proc.kill()

    def wait(self, timeout: float | None = None) -> int:
        self._proc.join(timeout)
        if self._proc.exitcode is None:
            raise subprocess.TimeoutExpired(["repro", "train"], timeout or 0.0)
        return self._proc.exitcode


class WarmStarter:
    """Starts runs from the fork server, which is started (with the children's environment, so that libraries
    reading it at import see what a plain child would) on first use. One server per launcher process: a second
    launcher in the same process reuses it, with the environment it started with."""

    def __init__(self, env: dict[str, str]):
        self.env = env
        self._ctx = multiprocessing.get_context("forkserver")
        self._ctx.set_forkserver_preload(PRELOAD)
        saved = dict(os.environ)
        os.environ.update(env)
        try:
            multiprocessing.forkserver.ensure_running()
        finally:
            os.environ.clear()
            os.environ.update(saved)

    def start(self, args: list[str], log: Path) -> WarmProcess:
        """Fork ``repro ARGS`` (e.g. ``train OVERRIDES``) with its output appended to ``log``."""
        proc = self._ctx.Process(target=_child, args=(args, str(log), self.env), daemon=False)
        proc.start()
        return WarmProcess(proc)
