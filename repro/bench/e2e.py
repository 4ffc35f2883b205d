"""`repro bench e2e`: a short real training run, timed per phase (docs/performance.md).

The run is built as ``repro train`` builds one (environment and learner by repro/train/build.py, the replay as
repro/train/api.py makes it, its frames on the CPU: replay.device's default) and trained by the online loop itself,
:class:`repro.train.online_loop.OnlineLoop`, without evaluation or checkpoints (its logs and episode files go to a
temporary folder): no copy of the loop to drift from what training does. The loop is
instrumented in place (:func:`instrument`, as tests/helpers.watch_loop watches one): the seed frames run untimed,
then ``frames`` frames are timed phase by phase. The phases:

* ``act``: ``agent.act`` (one observation to one action).
* ``replay_sample``: ``buffer.sample`` of one batch.
* ``update``: ``agent.update`` on that batch.
* ``env_step``: ``env.step`` and the episode resets, less the rendering inside them.
* ``render``: the observation camera's render (the suite env's ``_render``, timed in place).
* ``other``: ``buffer.add``, ``start_episode``/``end_episode``, the episode file and the train.csv row.

On CUDA the device is synchronized before each clock reading (here only: training never waits), so a phase owns
the device work it queued. The phases are timed one by one and the loop's wall clock separately; their sum falls
short of the wall clock only by the loop's own overhead (tests/test_bench_e2e.py bounds it).

``phase_sync=False`` (``repro bench e2e --overlap``) times the loop as it trains: the phases' clocks no longer wait for
the device (an update's phase is then the time to queue it, and its kernels run on while the environment steps and
renders), only the wall clock's two readings do. Its FPS against the synchronized entry's is what the overlap of the
environment with the queued update gains (nothing on the CPU, where every kernel runs before its call returns).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from repro.bench.clock import now
from repro.bench.results import PATH_FLAGS

PHASES = ("env_step", "render", "replay_sample", "update", "act", "other")
TINY = "tiny"  # the main job's profile (repro/conf/profile/tiny.yaml): what `repro bench e2e` times without --batch


class PhaseTimer:
    """Seconds per phase on the benchmarks' clock (repro/bench/clock.py: ``device`` synchronized before every
    reading)."""

    def __init__(self, device: str = "cpu"):
        self.seconds = dict.fromkeys(PHASES, 0.0)
        self.device = device
        self.on = False  # off during the seed frames and warm-up updates

    def clock(self) -> float:
        return now(self.device)

    @contextmanager
    def phase(self, name: str) -> Iterator[None]:
        if not self.on:
            yield
            return
        t0 = self.clock()
        try:
            yield
        finally:
            self.seconds[name] += self.clock() - t0


def _inner_env(env: Any) -> Any:
    """The suite environment under the wrappers (TimeLimit, DistractingActionDims hold theirs in ``env``)."""
    while not hasattr(env, "_render") and hasattr(env, "env"):
        env = env.env
    return env


def _time_render(env: Any, timer: PhaseTimer) -> list[float]:
    """Time the suite env's ``_render`` in place (this instance only); returns the list its times go to."""
    inner = _inner_env(env)
    render = inner._render
    spent: list[float] = []

    def timed() -> Any:
        if not timer.on:
            return render()
        t0 = timer.clock()
        try:
            return render()
        finally:
            spent.append(timer.clock() - t0)

    inner._render = timed
    return spent


def _timed(timer: PhaseTimer, name: str, fn: Callable[..., Any], calls: list[int] | None = None) -> Callable[..., Any]:
    """``fn`` charged to phase ``name`` (and counted in ``calls`` while the timer is on)."""

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        if calls is not None and timer.on:
            calls[0] += 1
        with timer.phase(name):
            return fn(*args, **kwargs)

    return wrapper


def instrument(loop: Any, timer: PhaseTimer) -> list[int]:
    """Time the phases of one :class:`repro.train.online_loop.OnlineLoop` in place, on this loop's objects only (as
    tests/helpers.watch_loop watches a loop): its agent's ``act`` and ``update``, its replay's ``sample``, its
    environment's ``step`` and ``reset``, and the bookkeeping (``buffer.add``, ``start_episode``, ``end_episode``, the
    episode file, the train.csv row). Returns the list whose one item counts the timed updates."""
    updates = [0]
    loop.agent.act = _timed(timer, "act", loop.agent.act)
    loop.agent.update = _timed(timer, "update", loop.agent.update, updates)
    loop.buffer.sample = _timed(timer, "replay_sample", loop.buffer.sample)
    loop.env.step = _timed(timer, "env_step", loop.env.step)
    loop.env.reset = _timed(timer, "env_step", loop.env.reset)
    for name in ("add", "start_episode", "end_episode"):
        setattr(loop.buffer, name, _timed(timer, "other", getattr(loop.buffer, name)))
    loop.episodes.save = _timed(timer, "other", loop.episodes.save)
    loop.logger.log_train = _timed(timer, "other", loop.logger.log_train)
    return updates


def run_e2e(agent: str, batch_size: int | None, device: str, path: str = "plain", frames: int = 100,
            task: str = "cheetah_run", warmup: int = 1, seed_frames: int | None = None,
            phase_sync: bool = True) -> dict[str, Any]:
    """Build a run of agent file ``agent`` on ``task`` (the tiny profile when ``batch_size`` is None, else the agent
    file's own settings at that batch) as ``repro train`` builds it, and train it with the online loop itself
    (:class:`repro.train.online_loop.OnlineLoop`, instrumented by :func:`instrument`; no evaluation, no checkpoint):
    its seed frames untimed, ``warmup`` untimed updates, then ``frames`` frames timed (``phase_sync``: see the module
    docstring). Returns the e2e entry (docs/plan.md, "The bench files `repro plan` reads")."""
    import tempfile
    from pathlib import Path

    import numpy as np
    import torch

    from repro.config.compose import compose, typed
    from repro.data.episodes import EpisodeStore
    from repro.data.replay import ReplayBuffer
    from repro.learners import OnlineLearner
    from repro.runs.logger import RunLogger
    from repro.runs.rundir import cpu_model
    from repro.train.build import build_env, build_run_learner
    from repro.train.online_loop import OnlineLoop

    overrides = [f"agent={agent}", f"task={task}", *PATH_FLAGS[path]]
    overrides += [f"profile={TINY}"] if batch_size is None else [f"agent.batch_size={batch_size}"]
    rc = typed(compose(overrides))
    repeat = rc.env.action_repeat
    seed_steps = (rc.train.seed_frames if seed_frames is None else seed_frames) // repeat
    seed_steps = max(seed_steps, rc.agent.nstep + rc.agent.K + 1)  # enough steps ahead to sample from
    timed_steps = max(1, frames // repeat)
    # the loop trains to train.frames after train.seed_frames; no evaluation, no checkpoint
    rc = typed(compose([*overrides, f"train.seed_frames={seed_steps * repeat}",
                        f"train.frames={(seed_steps + timed_steps) * repeat}", "train.eval_episodes=0",
                        "train.checkpoint_every_episodes=1000000000", "train.save_frames=false"]))
    cuda = device.startswith("cuda")
    timer = PhaseTimer(device if phase_sync else "cpu")  # "cpu": the phases' clocks do not wait for the device
    env = build_env(rc, rc.seed)
    try:
        with tempfile.TemporaryDirectory(prefix="repro-bench-e2e-") as tmp:
            spec = env.spec
            learner = build_run_learner(rc, spec.obs_shape, spec.action_dim, device)
            assert isinstance(learner, OnlineLearner)
            buffer = ReplayBuffer(rc.replay.capacity, (3, *spec.obs_shape[1:]), spec.action_dim, rc.env.frame_stack,
                                  rc.agent.nstep, rc.agent.K, rc.agent.discount, seed=rc.seed, device="cpu",
                                  sample_device=device)
            logger = RunLogger(Path(tmp), learner.metric_names(), echo=lambda line: None)
            started: list[float] = []

            def start_timing(frame: int, last_eval: float | None) -> None:
                """At the first step past the seed frames: the warm-up updates, then the clocks start."""
                if started or loop.counters.step < seed_steps:
                    return
                for _ in range(warmup):  # untimed: the first update allocates optimizer state (and compiles)
                    loop.agent.update(loop.buffer.sample(loop.batch_size, **learner.sample_options), loop.counters.step)
                renders.clear()
                timer.on = True
                started.append(now(device))

            loop = OnlineLoop(rc.train, rc.seed, repeat, env, env, learner, buffer, logger,
                              EpisodeStore(Path(tmp) / "replay"), lambda state: None, progress=start_timing)
            renders = _time_render(env, timer)
            updates = instrument(loop, timer)
            if cuda:
                torch.cuda.reset_peak_memory_stats()
            loop.run()
            wall = now(device) - started[0]
    finally:
        env.close()
    seconds = dict(timer.seconds)
    seconds["render"] = float(np.sum(renders))
    seconds["env_step"] -= seconds["render"]  # the renders ran inside env.step / env.reset
    timed_frames = timed_steps * repeat
    entry: dict[str, Any] = {
        "agent": agent, "batch_size": rc.agent.batch_size, "profile": TINY if batch_size is None else None,
        "path": path, "phase_sync": phase_sync, "device": device, "task": task, "frames": timed_frames,
        "seed_frames": seed_steps * repeat,
        "updates": updates[0], "warmup": warmup, "seconds": round(wall, 4),
        "phases": {k: round(v, 4) for k, v in seconds.items()}, "fps": round(timed_frames / wall, 3),
        "cpu": f"{cpu_model()} ({torch.get_num_threads()} threads)"}
    if cuda:
        entry["peak_device_bytes"] = int(torch.cuda.max_memory_allocated())
        entry["gpu"] = torch.cuda.get_device_name(0)
    return entry
