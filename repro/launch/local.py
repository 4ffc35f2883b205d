"""Local launcher: run a sweep's runs as parallel ``repro train`` subprocesses on this machine (fresh interpreters, or
forked from a warm server with ``warm_start``: repro/launch/warm.py)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rich.markup import escape

from repro.launch import lock
from repro.launch.runner import Claim, claim, die_with_parent, train_args, train_command
from repro.launch.spec import PlannedRun
from repro.launch.state import RunRecord, log_path, write_record
from repro.launch.waiting import waiting_lines
from repro.launch.warm import WarmProcess, WarmStarter

POLL_S = 0.2
TERM_GRACE_S = 10.0


def default_parallel() -> int:
    return max(1, (os.cpu_count() or 1) // 2)


@dataclass
class LaunchReport:
    """What a launch did, run key by run key."""

    started: list[str] = field(default_factory=list)
    finished: list[str] = field(default_factory=list)
    failed: list[tuple[str, str]] = field(default_factory=list)  # (key, log path)
    done: list[str] = field(default_factory=list)  # skipped: already DONE
    locked: list[tuple[str, str]] = field(default_factory=list)  # (key, owner) held by another launcher
    mismatch: list[str] = field(default_factory=list)
    moved: list[tuple[str, str]] = field(default_factory=list)  # (key, new location)
    waiting: list[tuple[str, str]] = field(default_factory=list)  # (key, reason): dataset not complete yet
    job_ids: list[str] = field(default_factory=list)
    interrupted: bool = False

    def to_launch(self, planned: Sequence[PlannedRun], say: Callable[[str], None]) -> list[PlannedRun]:
        """The runs a launcher should claim: neither done nor waiting for their dataset. Done runs and
        waiting runs are recorded here; one line per missing dataset says how many runs it holds back."""
        out = []
        for p in planned:
            if p.state == "done":
                self.done.append(p.key)
            elif p.waiting:
                self.waiting.append((p.key, p.waiting))
            else:
                out.append(p)
        for line in waiting_lines(self.waiting):
            say(f"[yellow]skip[/] {escape(line)}")
        return out

    def add_claim(self, c: Claim) -> None:
        if c.status == "done":
            self.done.append(c.planned.key)
        elif c.status == "locked":
            self.locked.append((c.planned.key, c.info.describe() if c.info else "unreadable lock"))
        elif c.status == "mismatch":
            self.mismatch.append(c.planned.key)
        if c.moved_to is not None:
            self.moved.append((c.planned.key, str(c.moved_to)))


class Interrupted(Exception):
    """SIGINT or SIGTERM reached the launcher."""


def child_env(max_parallel: int, gpu: int | None = None) -> dict[str, str]:
    """A child's environment: this process's, headless rendering, the CPU threads shared among ``max_parallel``
    runs, and with ``gpu`` (a physical GPU id, `repro sweep --gpus`) that GPU alone for CUDA
    (``CUDA_VISIBLE_DEVICES``, in nvidia-smi's order) and for MuJoCo's EGL rendering (``MUJOCO_EGL_DEVICE_ID``)."""
    env = dict(os.environ)
    env.setdefault("MUJOCO_GL", "egl")
    threads = str(max(1, (os.cpu_count() or 1) // max(1, max_parallel)))
    env.setdefault("OMP_NUM_THREADS", threads)
    env.setdefault("MKL_NUM_THREADS", threads)
    if gpu is not None:
        env["CUDA_DEVICE_ORDER"] = "PCI_BUS_ID"  # ids as nvidia-smi numbers them (CUDA's default is fastest first)
        env["CUDA_VISIBLE_DEVICES"] = str(gpu)
        env["MUJOCO_EGL_DEVICE_ID"] = str(gpu)
    return env


@dataclass(frozen=True)
class GpuPacking:
    """`repro sweep --gpus 0,1 --runs-per-gpu N`: the physical GPU ids and how many runs share each at once."""

    gpus: tuple[int, ...]
    per_gpu: int = 1

    @property
    def max_parallel(self) -> int:
        return len(self.gpus) * self.per_gpu

    def pick(self, running: Sequence[int | None]) -> int | None:
        """The GPU for the next run, given the GPUs of the running ones: the least busy (the first listed among
        equals), None when every GPU has ``per_gpu`` runs."""
        load = {g: sum(1 for r in running if r == g) for g in self.gpus}
        free = [g for g in self.gpus if load[g] < self.per_gpu]
        return min(free, key=lambda g: load[g]) if free else None


def parse_gpus(text: str, per_gpu: int) -> GpuPacking:
    """``--gpus 0,1`` and ``--runs-per-gpu N`` as a :class:`GpuPacking`; SweepError (one line) for bad input."""
    from repro.launch.spec import SweepError

    ids = [part.strip() for part in text.split(",")]
    if not ids or any(not part.isdigit() for part in ids):
        raise SweepError(f"--gpus takes comma-separated GPU ids (integers >= 0, e.g. 0,1), got '{text}'")
    gpus = tuple(int(part) for part in ids)
    if len(set(gpus)) != len(gpus):
        raise SweepError(f"--gpus lists a GPU twice ('{text}'); use --runs-per-gpu to share one")
    if per_gpu < 1:
        raise SweepError(f"--runs-per-gpu must be >= 1, got {per_gpu}")
    return GpuPacking(gpus, per_gpu)


# Run in a child with the runs' GPU environment: how many of the listed GPUs CUDA sees (0 without CUDA).
_CUDA_PROBE = "import torch; print(torch.cuda.device_count() if torch.cuda.is_available() else 0)"


def check_gpus(packing: GpuPacking) -> None:
    """SweepError (one line) unless CUDA sees every GPU of ``--gpus`` on this machine, as the runs will see them
    (asked of a child process with their ``CUDA_DEVICE_ORDER`` and ``CUDA_VISIBLE_DEVICES``, so the launcher itself
    starts no CUDA context): a run placed on a GPU that is not there would train on the CPU."""
    from repro.launch.spec import SweepError

    listed = ",".join(map(str, packing.gpus))
    env = {**os.environ, "CUDA_DEVICE_ORDER": "PCI_BUS_ID", "CUDA_VISIBLE_DEVICES": listed}
    probe = subprocess.run([sys.executable, "-c", _CUDA_PROBE], env=env, capture_output=True, text=True, timeout=300)
    lines = probe.stdout.split()
    seen = int(lines[-1]) if probe.returncode == 0 and lines and lines[-1].isdigit() else 0
    if seen == 0:
        raise SweepError(f"--gpus {listed}: torch sees no CUDA device {listed} on this machine; drop --gpus to run "
                         "on the CPU")
    if seen < len(packing.gpus):
        raise SweepError(f"--gpus {listed}: CUDA sees {seen} of these {len(packing.gpus)} GPUs (ids as nvidia-smi "
                         "numbers them); list only GPUs this machine has")


@dataclass
class _Active:
    claim: Claim
    proc: subprocess.Popen | WarmProcess
    log: Path
    record: RunRecord
    started: float
    gpu: int | None = None


def _start(c: Claim, sdir: Path, env: dict[str, str], warm: WarmStarter | None, gpu: int | None = None) -> _Active:
    p = c.planned
    log = log_path(sdir, p.key)
    log.parent.mkdir(parents=True, exist_ok=True)
    cmd = train_command(p.overrides)
    with open(log, "a") as fh:
        fh.write(f"\n=== {time.strftime('%Y-%m-%d %H:%M:%S')} {' '.join(cmd)}{' (warm start)' if warm else ''}\n")
        fh.flush()
        proc: subprocess.Popen | WarmProcess
        if warm is not None:
            proc = warm.start(train_args(p.overrides), log)
        else:
            proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=env,
                                    preexec_fn=die_with_parent)
    assert c.info is not None
    lock.update(c.lock_path, c.info.token, child_pid=proc.pid, child_start=lock.process_start(proc.pid))
    record = RunRecord(key=p.key, run_dir=str(p.run_dir), overrides=list(p.overrides), launcher="local",
                       status="running", log=str(log), stderr=str(log), pid=proc.pid, budget=p.budget)
    write_record(sdir, record)
    return _Active(c, proc, log, record, time.time(), gpu)


def _finish(a: _Active, sdir: Path, rc: int, report: LaunchReport, say: Callable[[str], None]) -> None:
    from repro.runs.rundir import run_state

    key = a.claim.planned.key
    done = run_state(a.claim.planned.run_dir, a.claim.planned.budget) == "done"
    a.record.returncode = rc
    a.record.status = "done" if (rc == 0 and done) else "failed"
    if rc == 0 and not done:
        a.record.error = "exited 0 without writing DONE"
    write_record(sdir, a.record)
    assert a.claim.info is not None
    lock.release(a.claim.lock_path, a.claim.info.token)
    minutes = (time.time() - a.started) / 60
    if a.record.status == "done":
        report.finished.append(key)
        say(f"[green]done[/] {key} ({minutes:.1f} min)")
    else:
        report.failed.append((key, str(a.log)))
        say(f"[red]FAILED[/] {key} (exit {rc}); log: {escape(str(a.log))}")


def _stop_all(active: dict[str, _Active], sdir: Path) -> None:
    for a in active.values():
        if a.proc.poll() is None:
            a.proc.terminate()
    deadline = time.time() + TERM_GRACE_S
    for a in active.values():
        try:
            a.proc.wait(timeout=max(0.1, deadline - time.time()))
        except subprocess.TimeoutExpired:
            a.proc.kill()
            a.proc.wait()
        a.record.status = "interrupted"
        a.record.returncode = a.proc.returncode
        write_record(sdir, a.record)
        assert a.claim.info is not None
        lock.release(a.claim.lock_path, a.claim.info.token)


def run_local(planned: Sequence[PlannedRun], sweep: str, sdir: Path, max_parallel: int, force: bool,
              say: Callable[[str], None], warm_start: bool = False, gpus: GpuPacking | None = None) -> LaunchReport:
    """Run every not-yet-done run, at most ``max_parallel`` at a time; keep going past failures.

    Each run is claimed (locked, state re-read) just before it starts, so a concurrent launcher on
    the same grid never runs it twice. SIGINT/SIGTERM stop the children and release their locks; the
    runs resume from their checkpoints on the next launch. ``warm_start`` forks each run from a server that has
    imported torch and the trainer already (repro/launch/warm.py) instead of starting a fresh interpreter.
    ``gpus`` places each run on a GPU (its environment: :func:`child_env`), at most ``gpus.per_gpu`` runs per GPU
    at once (``max_parallel`` is then ``gpus.max_parallel``; a warm start is refused by the command line, since its
    server would set up one EGL display for every run).
    """
    report = LaunchReport()
    if gpus is not None:
        max_parallel = gpus.max_parallel
    env = child_env(max_parallel)
    queue = report.to_launch(planned, say)
    warm = WarmStarter(env) if warm_start and queue else None
    active: dict[str, _Active] = {}

    def on_term(signum: int, frame: object) -> None:
        raise Interrupted()

    old = signal.signal(signal.SIGTERM, on_term)
    try:
        while queue or active:
            while queue and len(active) < max_parallel:
                p = queue.pop(0)
                c = claim(p, "local", sweep, force)
                report.add_claim(c)
                if c.status == "locked":
                    say(f"[yellow]skip[/] {p.key}: held by {report.locked[-1][1]}")
                if c.status != "claimed":
                    continue
                if c.moved_to is not None:
                    say(f"[yellow]moved[/] old run dir of {p.key} to {escape(str(c.moved_to))}")
                gpu = gpus.pick([a.gpu for a in active.values()]) if gpus is not None else None
                active[p.key] = _start(c, sdir, env if gpu is None else child_env(max_parallel, gpu), warm, gpu)
                report.started.append(p.key)
                on = "" if gpu is None else f" on GPU {gpu}"
                say(f"[cyan]start[/] {p.key}{on} ({len(active)} running, {len(queue)} queued)")
            for key, a in list(active.items()):
                rc = a.proc.poll()
                if rc is not None:
                    del active[key]
                    _finish(a, sdir, rc, report, say)
            time.sleep(POLL_S)
    except (KeyboardInterrupt, Interrupted):
        report.interrupted = True
        say(f"[red]interrupted[/]: stopping {len(active)} run(s); they resume on the next launch")
        _stop_all(active, sdir)
    finally:
        signal.signal(signal.SIGTERM, old)
    return report
