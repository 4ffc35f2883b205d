"""DeepMind Control from pixels: ``dm_control.suite`` tasks and the ``reach_duplo`` manipulation task.

One agent step = ``action_repeat`` control steps (rewards summed, stopping early at the episode end),
then one render with the task camera. ``dm_control`` is imported lazily inside :class:`DMCEnv`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from repro.config.schema import Suite
from repro.envs.base import TimeStep
from repro.envs.registry import TaskInfo
from repro.envs.suite import SuiteEnv


class DMCEnv(SuiteEnv):
    """A DMC task as a pixel :class:`repro.envs.base.Env` with actions in [-1, 1].

    For ``reach_duplo`` the composer environment's own ``front_close`` camera observable is disabled and
    the same camera is rendered by this class once per agent step instead of once per control step
    (the pixels are identical: same camera, same physics, same default render settings).
    """

    SUITES = (Suite.dmc, Suite.manipulation)
    SUITE_NAME = "DMC"
    HAS_SUCCESS = False

    def _build(self, seed: int) -> int:
        self._env = self._load(self.info, seed)
        aspec = self._env.action_spec()
        self._action_dtype = aspec.dtype
        self._low = np.asarray(aspec.minimum, dtype=np.float64)
        self._high = np.asarray(aspec.maximum, dtype=np.float64)
        return int(aspec.shape[0])

    @staticmethod
    def _load(info: TaskInfo, seed: int) -> Any:
        if info.suite == Suite.dmc:
            from dm_control import suite

            return suite.load(info.domain, info.task, task_kwargs={"random": seed})
        from dm_control import manipulation

        env = manipulation.load(info.task, seed=seed)
        camera_observable = env.task.observables.get(str(info.camera))
        if camera_observable is not None:
            camera_observable.enabled = False  # rendered by DMCEnv._render once per agent step
        return env

    def _reseed(self, seed: int) -> None:
        """Re-seed every source of task randomness in place."""
        if self.info.suite == Suite.dmc:
            self._env.task.random.seed(seed)
        else:
            self._env.random_state.seed(seed)

    def _render(self) -> np.ndarray:
        return self.render_view(self._image_size)

    def render_view(self, size: int) -> np.ndarray:
        return self._env.physics.render(height=size, width=size, camera_id=self._camera)

    def _to_env_action(self, action: np.ndarray) -> np.ndarray:
        """[-1, 1] -> the action spec's [minimum, maximum], in its dtype."""
        scaled = self._low + (action + 1.0) * 0.5 * (self._high - self._low)
        return scaled.astype(self._action_dtype)

    def reset(self, seed: int) -> TimeStep:
        self._reseed(seed)
        self._env.reset()
        obs = self._first_observation()
        return TimeStep(observation=obs, reward=0.0, discount=1.0, first=True, last=False)

    def step(self, action: np.ndarray) -> TimeStep:
        env_action = self._to_env_action(self._step_action(action, np.float64))
        reward = 0.0
        discount = 1.0
        last = False
        for _ in range(self._action_repeat):
            ts = self._env.step(env_action)
            reward += float(ts.reward or 0.0)
            if ts.last():
                last = True
                discount = 1.0 if ts.discount is None else float(ts.discount)
                break
        obs = self._next_observation(last)
        return TimeStep(observation=obs, reward=reward, discount=discount, first=False, last=last)

    def close(self) -> None:
        self._env.close()


def random_policy_returns(info: TaskInfo, episodes: int, seed: int = 0, action_repeat: int = 2) -> list[float]:
    """Returns of ``episodes`` episodes of uniform random actions in [-1, 1] on a ``dm_control.suite`` task, as
    :class:`DMCEnv` sums them (``action_repeat`` control steps per action), without rendering: the reward does not
    depend on the pixels, so this is the random-policy reference of ``repro verify`` at a fraction of a second per
    episode. Episode ``i`` has task seed ``i`` and the actions come from ``numpy.random.default_rng(seed)``."""
    if info.suite != Suite.dmc:
        raise ValueError(f"{info.name} is not a dm_control.suite task")
    rng = np.random.default_rng(seed)
    out: list[float] = []
    for episode in range(episodes):
        env = DMCEnv._load(info, episode)
        spec = env.action_spec()
        low, high = np.asarray(spec.minimum, dtype=np.float64), np.asarray(spec.maximum, dtype=np.float64)
        ts = env.reset()
        total = 0.0
        while not ts.last():
            action = rng.uniform(-1.0, 1.0, size=spec.shape)
            env_action = (low + (action + 1.0) * 0.5 * (high - low)).astype(spec.dtype)
            for _ in range(action_repeat):
                ts = env.step(env_action)
                total += float(ts.reward or 0.0)
                if ts.last():
                    break
        out.append(total)
    return out
