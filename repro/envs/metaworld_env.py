"""Meta-world v3 from pixels (``metaworld`` is imported lazily inside :class:`MetaWorldEnv`).

Setup (see "Meta-world setup" in docs/deviations.md): ``metaworld.MT1("<name>-v3", seed)`` provides 50 train
tasks (object and goal positions); the environment class renders ``camera_name`` at ``image_size``. Each
``reset(seed)`` picks one of the train tasks deterministically from ``seed``, calls ``set_task`` and
``env.seed(seed)`` (``reset(seed=...)`` is ignored by Meta-world). Episodes end after 500 environment steps
(truncation: ``last=True``, discount 1.0); there is no terminal state.

The ``corner``/``corner2``/``corner3``/``corner4`` cameras are defined upside down (their up axis points
down in the world), so their frames come out rotated by 180 degrees: such frames are rotated back, which
gives the upright, non-mirrored view. The rule is generic: any camera whose up axis has a negative world
z component is rotated.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from repro.config.schema import Suite
from repro.envs.base import TimeStep
from repro.envs.suite import SuiteEnv


class MetaWorldEnv(SuiteEnv):
    """A Meta-world v3 MT1 task as a pixel :class:`repro.envs.base.Env`; ``info['success']`` is 0.0/1.0.

    ``info['success']`` is the environment's success flag after the last environment step of the agent
    step (a function of the current state, like ``evaluate_state``).
    """

    SUITES = (Suite.metaworld,)
    SUITE_NAME = "Meta-world"
    HAS_SUCCESS = True

    def _build(self, seed: int) -> int:
        import metaworld

        self._benchmark = metaworld.MT1(self.info.task, seed=seed)
        self._tasks = list(self._benchmark.train_tasks)
        camera_kwargs: dict[str, Any] = (
            {"camera_id": self._camera} if isinstance(self._camera, int) else {"camera_name": self._camera}
        )
        self._env = self._benchmark.train_classes[self.info.task](
            render_mode="rgb_array", width=self._image_size, height=self._image_size, **camera_kwargs
        )
        self._env.set_task(self._tasks[0])
        self._rotate: bool | None = None  # decided after the first reset (needs camera poses)
        self._state: np.ndarray | None = None
        self._viewer: Any = None  # mujoco.Renderer for render_view, made on first use
        self.task_index = 0
        action_shape = self._env.action_space.shape
        assert action_shape is not None  # a Box space
        return int(action_shape[0])

    @property
    def raw_env(self) -> Any:
        """The underlying Meta-world environment (for tests and scripted policies)."""
        return self._env

    @property
    def state_observation(self) -> np.ndarray:
        """The current Meta-world state vector (39-d); not part of the pixel observation."""
        if self._state is None:
            raise RuntimeError("call reset(seed) first")
        return self._state.copy()

    @property
    def frames_rotated(self) -> bool:
        """Whether rendered frames are rotated by 180 degrees (camera defined upside down)."""
        return bool(self._rotate)

    def _camera_upside_down(self) -> bool:
        """Whether the render camera's up axis points downwards in the world."""
        model, data = self._env.model, self._env.data
        cam_id = self._camera if isinstance(self._camera, int) else model.camera(self._camera).id
        up_axis = data.cam_xmat[cam_id].reshape(3, 3)[:, 1]
        return bool(up_axis[2] < 0.0)

    def _render(self) -> np.ndarray:
        frame = self._env.render()
        if self._rotate:
            frame = frame[::-1, ::-1]
        return frame

    def render_view(self, size: int) -> np.ndarray:
        """The observation camera at ``size`` pixels through a separate MuJoCo renderer (same rotation rule)."""
        import mujoco

        if self._viewer is None or self._viewer.height != size:
            if self._viewer is not None:
                self._viewer.close()
            self._viewer = mujoco.Renderer(self._env.model, height=size, width=size)
        camera = self._camera if isinstance(self._camera, int) else self._env.model.camera(self._camera).id
        self._viewer.update_scene(self._env.data, camera=camera)
        frame = self._viewer.render()
        return frame[::-1, ::-1].copy() if self._rotate else frame

    def reset(self, seed: int) -> TimeStep:
        self.task_index = int(np.random.default_rng(seed).integers(len(self._tasks)))
        self._env.set_task(self._tasks[self.task_index])
        self._env.seed(seed)
        self._state, _ = self._env.reset()
        if self._rotate is None:
            self._rotate = self._camera_upside_down()
        obs = self._first_observation()
        return TimeStep(
            observation=obs, reward=0.0, discount=1.0, first=True, last=False, info={"success": 0.0}
        )

    def step(self, action: np.ndarray) -> TimeStep:
        action = self._step_action(action, np.float32)
        reward = 0.0
        discount = 1.0
        last = False
        success = 0.0
        for _ in range(self._action_repeat):
            self._state, r, terminated, truncated, env_info = self._env.step(action)
            reward += float(r)
            success = float(bool(env_info["success"]))
            if terminated or truncated:
                last = True
                discount = 0.0 if terminated else 1.0
                break
        obs = self._next_observation(last)
        return TimeStep(
            observation=obs,
            reward=reward,
            discount=discount,
            first=False,
            last=last,
            info={"success": success},
        )

    def close(self) -> None:
        if self._viewer is not None:
            self._viewer.close()
        self._env.close()
