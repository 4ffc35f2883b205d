"""What the suite environments (:class:`~repro.envs.dmc.DMCEnv`, :class:`~repro.envs.metaworld_env.MetaWorldEnv`)
share: the constructor's checks and settings, the frame stack, the episode-over guard and the action check.

A suite class names its suites and sets :meth:`SuiteEnv._build` (make the simulator, return its action
dimension), ``_render``, ``reset``, ``step``, ``render_view`` and ``close``.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
import numpy.typing as npt

from repro.config.schema import Suite
from repro.envs.base import EnvSpec, checked_action
from repro.envs.registry import TaskInfo
from repro.envs.wrappers import FrameStack


class SuiteEnv:
    """A pixel environment of one simulator suite, built from a :class:`TaskInfo`."""

    SUITES: ClassVar[tuple[Suite, ...]]  # the TaskInfo.suite values the class builds
    SUITE_NAME: ClassVar[str]  # for the error on another suite's task: "... is not a {SUITE_NAME} task"
    HAS_SUCCESS: ClassVar[bool]  # EnvSpec.has_success

    def __init__(
        self,
        info: TaskInfo,
        *,
        seed: int,
        action_repeat: int = 2,
        frame_stack: int = 3,
        image_size: int = 84,
        camera: int | str | None = None,
    ) -> None:
        if info.suite not in self.SUITES:
            raise ValueError(f"{info.name} is not a {self.SUITE_NAME} task (suite {info.suite!r})")
        if action_repeat < 1:
            raise ValueError(f"action_repeat must be >= 1, got {action_repeat}")
        self.info = info
        self._action_repeat = action_repeat
        self._image_size = image_size
        self._camera = info.camera if camera is None else camera
        self._frames = FrameStack(frame_stack)
        self._done = True
        self.spec = EnvSpec(
            action_dim=self._build(seed),
            obs_shape=(3 * frame_stack, image_size, image_size),
            has_success=self.HAS_SUCCESS,
        )

    def _build(self, seed: int) -> int:
        """Make the simulator (``self.info``, ``self._image_size`` and ``self._camera`` are set); its |A|."""
        raise NotImplementedError

    def _render(self) -> np.ndarray:
        """The observation camera's frame, (H, W, 3) uint8."""
        raise NotImplementedError

    def _first_observation(self) -> np.ndarray:
        """After the simulator's reset: the episode is on and the stack holds the first frame."""
        self._done = False
        return self._frames.reset(self._render())

    def _step_action(self, action: np.ndarray, dtype: npt.DTypeLike) -> np.ndarray:
        """``action`` as ``dtype``, clipped to [-1, 1]; refused after the episode's last step or with another shape."""
        if self._done:
            raise RuntimeError("episode is over: call reset(seed) first")
        return np.clip(checked_action(action, self.spec.action_dim, dtype), -1.0, 1.0)

    def _next_observation(self, last: bool) -> np.ndarray:
        """After the simulator's steps: the stack with the new frame; ``last`` ends the episode."""
        self._done = last
        return self._frames.push(self._render())
