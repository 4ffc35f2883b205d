"""`repro bench --e2e`: a short real training loop, timed per phase (docs/performance.md).

The loop is the online loop's (repro/train/online_loop.py) without evaluation, logging, checkpoints and the episode
files: the environment, agent and replay are built as a run builds them (repro/train/build.py, api.py), the seed
frames are stepped untimed, then ``frames`` frames are timed phase by phase. The phases:

* ``act``: ``agent.act`` (one observation to one action).
* ``replay_sample``: ``buffer.sample`` of one batch.
* ``update``: ``agent.update`` on that batch.
* ``env_step``: ``env.step`` and the episode resets, less the rendering inside them.
* ``render``: the observation camera's render (the suite env's ``_render``, timed in place).
* ``other``: ``buffer.add`` and the episode bookkeeping (``end_episode``/``start_episode``).

On CUDA the device is synchronized before each clock reading (here only: training never waits), so a phase owns
the device work it queued. The phases are timed one by one and the loop's wall clock separately; their sum falls
short of the wall clock only by the loop's own overhead (tests/test_bench.py bounds it).

``phase_sync=False`` (``--e2e --overlap``) times the loop as it trains: the phases' clocks no longer wait for the device
(an update's phase is then the time to queue it, and its kernels run on while the environment steps and renders),
only the wall clock's two readings do. Its FPS against the synchronized entry's is what the overlap of the
environment with the queued update gains (nothing on the CPU, where every kernel runs before its call returns).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

from repro.bench import SPEEDUP_FLAGS
from repro.bench.clock import now

PHASES = ("env_step", "render", "replay_sample", "update", "act", "other")
TINY = "tiny"  # the main job's profile (repro/conf/profile/tiny.yaml): what --e2e times without --batch


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


def run_e2e(algo: str, batch_size: int | None, device: str, speedup: str = "plain", frames: int = 100,
            task: str = "cheetah_run", warmup: int = 1, seed_frames: int | None = None,
            phase_sync: bool = True) -> dict[str, Any]:
    """Build a run of ``algo`` on ``task`` (the tiny profile when ``batch_size`` is None, else the agent's own
    settings at that batch), step its seed frames untimed, run ``warmup`` untimed updates, then time ``frames``
    frames of training (``phase_sync``: see the module docstring). Returns the e2e entry (docs/plan.md, "The bench
    JSON `repro plan` reads")."""
    import numpy as np
    import torch

    from repro.config.compose import compose, typed
    from repro.data.replay import ReplayBuffer
    from repro.learners import OnlineLearner
    from repro.runs.rundir import _cpu_model
    from repro.train.build import build_agent, build_env
    from repro.train.common import episode_seed

    overrides = [f"agent={algo}", f"task={task}", *SPEEDUP_FLAGS[speedup]]
    overrides += [f"profile={TINY}"] if batch_size is None else [f"agent.batch_size={batch_size}"]
    rc = typed(compose(overrides))
    cuda = device.startswith("cuda")
    timer = PhaseTimer(device if phase_sync else "cpu")  # "cpu": the phases' clocks do not wait for the device
    env = build_env(rc, rc.seed)
    try:
        spec = env.spec
        agent = build_agent(rc, spec.obs_shape, spec.action_dim, device)
        assert isinstance(agent, OnlineLearner)
        buffer = ReplayBuffer(rc.replay.capacity, (3, *spec.obs_shape[1:]), spec.action_dim, rc.env.frame_stack,
                              rc.agent.nstep, rc.agent.K, rc.agent.discount, seed=rc.seed, device="cpu",
                              sample_device=device)
        renders = _time_render(env, timer)
        repeat, every = rc.env.action_repeat, rc.train.update_every_steps
        seed_steps = (rc.train.seed_frames if seed_frames is None else seed_frames) // repeat
        seed_steps = max(seed_steps, rc.agent.nstep + rc.agent.K + 1)  # enough steps ahead to sample from
        timed_steps = max(1, frames // repeat)
        episode = 0
        ts = env.reset(seed=episode_seed(rc.seed, 0, episode))
        buffer.start_episode(ts.observation[-3:])
        updates, wall0 = 0, 0.0
        if cuda:
            torch.cuda.reset_peak_memory_stats()
        for step in range(seed_steps + timed_steps):
            if step == seed_steps:
                for _ in range(warmup):  # untimed: the first update allocates optimizer state (and compiles)
                    agent.update(buffer.sample(rc.agent.batch_size, **agent.sample_options), step)
                timer.on = True
                renders.clear()
                wall0 = now(device)
            with timer.phase("act"):
                action = agent.act(ts.observation, step, eval_mode=False)
            if step >= seed_steps and step % every == 0:
                with timer.phase("replay_sample"):
                    batch = buffer.sample(rc.agent.batch_size, **agent.sample_options)
                with timer.phase("update"):
                    agent.update(batch, step)
                updates += 1
            with timer.phase("env_step"):
                ts = env.step(action)
            with timer.phase("other"):
                buffer.add(action, ts.reward, ts.discount, ts.observation[-3:])
                if ts.last:
                    buffer.end_episode()
                    episode += 1
            if ts.last:
                with timer.phase("env_step"):
                    ts = env.reset(seed=episode_seed(rc.seed, 0, episode))
                with timer.phase("other"):
                    buffer.start_episode(ts.observation[-3:])
        wall = now(device) - wall0
    finally:
        env.close()
    seconds = dict(timer.seconds)
    seconds["render"] = float(np.sum(renders))
    seconds["env_step"] -= seconds["render"]  # the renders ran inside env.step / env.reset
    timed_frames = timed_steps * repeat
    entry: dict[str, Any] = {
        "algo": algo, "batch_size": rc.agent.batch_size, "profile": TINY if batch_size is None else None,
        "speedup": speedup, "phase_sync": phase_sync, "device": device, "task": task, "frames": timed_frames,
        "seed_frames": seed_steps * repeat,
        "updates": updates, "warmup": warmup, "seconds": round(wall, 4),
        "phases": {k: round(v, 4) for k, v in seconds.items()}, "fps": round(timed_frames / wall, 3),
        "cpu": f"{_cpu_model()} ({torch.get_num_threads()} threads)"}
    if cuda:
        entry["peak_device_bytes"] = int(torch.cuda.max_memory_allocated())
        entry["gpu"] = torch.cuda.get_device_name(0)
    return entry
