"""One update of the online agent, timed (``repro bench update``), and the pieces every update benchmark shares
(``repro bench roofline``, repro/bench/agreement.py): a learner built from its agent file and timed updates of several
paths alternated; their batches come from repro/bench/batches.py, drawn from a replay as training draws them."""

from __future__ import annotations

import functools
import statistics
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from repro.bench.clock import timed
from repro.bench.results import PATH_FLAGS

if TYPE_CHECKING:
    import torch


def compose_learner(agent: str, batch_size: int, task: str, device: str, flags: list[str], image: int = 84
                    ) -> tuple[Any, Any]:
    """The online learner of agent file ``agent`` at ``batch_size`` for ``task`` with the overrides ``flags``, seeded
    0, for stacks of 3 RGB frames of ``image`` pixels square, and its typed run config."""
    import torch

    from repro.config.compose import compose, typed
    from repro.envs import get_task
    from repro.learners import OnlineLearner, build_learner

    rc = typed(compose([f"agent={agent}", f"task={task}", f"agent.batch_size={batch_size}", *flags]))
    torch.manual_seed(0)
    learner = build_learner(rc.agent, (9, image, image), get_task(task).action_dim, device)
    if not isinstance(learner, OnlineLearner):
        raise ValueError(f"agent {agent} does not train online")
    return learner, rc


def alternated_times(agents: dict[str, Any], batch: dict[str, torch.Tensor], warmup: int, repeats: int,
                     device: str) -> dict[str, list[float]]:
    """Seconds of each timed update per path (``agents`` by path, all on ``batch``): ``warmup`` untimed updates
    of each, then ``repeats`` rounds of one timed update of each path in turn (on CUDA synchronized before each
    clock reading)."""
    for agent in agents.values():
        for _ in range(warmup):
            agent.update(batch, step=10**6)
    times: dict[str, list[float]] = {path: [] for path in agents}
    for _ in range(repeats):
        for path in agents:
            times[path].append(timed(functools.partial(agents[path].update, batch, step=10**6), device)[1])
    return times


def replay_batch(agent: Any, rc: Any, batch_size: int, device: str, image: int = 84) -> dict[str, torch.Tensor]:
    """A batch of ``batch_size`` drawn as training draws the agent's batches (repro/bench/batches.py): from a
    ReplayBuffer of synthetic episodes, with what its objectives need (``agent.sample_options``)."""
    from repro.bench.batches import synthetic_episodes, training_batch

    episodes = synthetic_episodes(action_dim=agent.action_dim, frame_shape=(3, image, image))
    return training_batch(agent, rc.agent, rc.env.frame_stack, episodes, device, batch_size)[0]


def time_update(agent: str, batch_size: int, task: str = "cheetah_run", repeats: int = 2,
                device: str = "cpu", paths: tuple[str, ...] = (), warmup: int = 1,
                overrides: Sequence[str] = ()) -> list[dict]:
    """Median wall-clock seconds of one full agent update on the plain path and on each of ``paths``, over
    ``repeats`` timed updates after ``warmup`` untimed ones (same batch every time, drawn as training draws it:
    :func:`replay_batch`). The paths' agents live side by side and their timed updates alternate (plain, path 1,
    ..., plain, path 1, ...), so background load falls on every path alike. One row per path, plain first.
    ``overrides``: more config overrides (a test's ``profile=tiny``)."""
    paths = ("plain", *paths)
    agents = {}
    for path in paths:
        agents[path], rc = compose_learner(agent, batch_size, task, device, [*overrides, *PATH_FLAGS[path]])
    batch = replay_batch(agents["plain"], rc, batch_size, device)
    times = alternated_times(agents, batch, warmup, repeats, device)
    rows = []
    for path in paths:
        seconds = statistics.median(times[path])
        # one update every 2 agent steps at action repeat 2 = 4 frames per update (update-bound estimate)
        per_update = rc.train.update_every_steps * rc.env.action_repeat
        fps = per_update / seconds
        rows.append({"agent": agent, "batch_size": batch_size, "path": path, "update_seconds": round(seconds, 4),
                     "frames_per_update": per_update, "fps_estimate": round(fps, 3), "repeats": repeats,
                     "warmup": warmup, "alternated": True,
                     "seconds_each": [round(t, 4) for t in times[path]]})
    return rows
