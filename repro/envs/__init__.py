"""Pixel environments for TACO / DrQ-v2: DMC, dm_control manipulation and Meta-world v3.

``make_env`` is the one entry point. Simulator packages are imported only when an environment is built,
so ``import repro.envs`` stays cheap.
"""

from __future__ import annotations

from collections.abc import Callable

from repro.config.schema import RunConfig, Suite
from repro.envs.base import Env, EnvSpec, TimeStep
from repro.envs.registry import TASKS, TaskInfo, UnknownTaskError, get_task
from repro.envs.wrappers import DistractingActionDims, TimeLimit

__all__ = [
    "Env",
    "EnvSpec",
    "TimeStep",
    "TASKS",
    "TaskInfo",
    "UnknownTaskError",
    "get_task",
    "make_env",
    "run_action_dim",
    "DistractingActionDims",
    "TimeLimit",
]


def run_action_dim(rc: RunConfig) -> int:
    """|A| of a run's environment without building it (the task's plus any distracting dimensions)."""
    return get_task(rc.task.name).action_dim + rc.env.distracting_dims


def make_env(
    task: str,
    *,
    seed: int,
    action_repeat: int = 2,
    frame_stack: int = 3,
    image_size: int = 84,
    distracting_dims: int = 0,
    max_episode_frames: int | None = None,
    camera: str | int | None = None,
) -> Env:
    """Build the pixel environment for ``task`` (a key of :data:`TASKS`).

    Args:
        task: task name, e.g. ``"cheetah_run"`` or ``"hammer"``.
        seed: seed for building the environment (DMC task randomness, Meta-world MT1 task set). Each
            ``reset(seed)`` re-seeds the episode randomness.
        action_repeat: environment steps per agent step (rewards summed).
        frame_stack: number of stacked RGB frames in the observation.
        image_size: rendered frames are ``image_size x image_size``.
        distracting_dims: extra action dimensions the environment ignores.
        max_episode_frames: optional cap on the episode length in frames (agent steps x action_repeat),
            applied with :class:`TimeLimit` as ``max(1, max_episode_frames // action_repeat)`` agent steps.
        camera: override of the task's camera (id or name).
    """
    info = get_task(task)
    env_class: Callable[..., Env]
    if info.suite in (Suite.dmc, Suite.manipulation):
        from repro.envs.dmc import DMCEnv as env_class
    elif info.suite == Suite.metaworld:
        from repro.envs.metaworld_env import MetaWorldEnv as env_class
    else:  # pragma: no cover - the registry only holds the suites above
        raise ValueError(f"unsupported suite {info.suite!r} for task {task!r}")
    env: Env = env_class(info, seed=seed, action_repeat=action_repeat, frame_stack=frame_stack,
                         image_size=image_size, camera=camera)
    if distracting_dims:
        env = DistractingActionDims(env, distracting_dims)
    if max_episode_frames is not None:
        env = TimeLimit(env, max(1, max_episode_frames // action_repeat))
    return env
