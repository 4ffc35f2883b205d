"""Wrappers around :class:`repro.envs.base.Env`, plus the frame-stack buffer the suite envs share."""

from __future__ import annotations

import dataclasses
from collections import deque

import numpy as np

from repro.envs.base import Env, EnvSpec, TimeStep, checked_action


class FrameStack:
    """Keeps the last ``num_frames`` RGB frames and returns them stacked channels-first.

    Frames go in as ``(H, W, 3)`` uint8; :meth:`observation` returns ``(3 * num_frames, H, W)`` uint8
    with the newest frame in the last three channels.
    """

    def __init__(self, num_frames: int) -> None:
        if num_frames < 1:
            raise ValueError(f"frame_stack must be >= 1, got {num_frames}")
        self._frames: deque[np.ndarray] = deque(maxlen=num_frames)

    def reset(self, frame: np.ndarray) -> np.ndarray:
        """Fill the stack with copies of ``frame`` (the first frame of an episode)."""
        chw = self._to_chw(frame)
        for _ in range(self._frames.maxlen or 0):
            self._frames.append(chw)
        return self.observation()

    def push(self, frame: np.ndarray) -> np.ndarray:
        """Append the newest frame (dropping the oldest) and return the stacked observation."""
        self._frames.append(self._to_chw(frame))
        return self.observation()

    def observation(self) -> np.ndarray:
        return np.concatenate(list(self._frames), axis=0)

    @staticmethod
    def _to_chw(frame: np.ndarray) -> np.ndarray:
        if frame.ndim != 3 or frame.shape[-1] != 3:
            raise ValueError(f"expected an (H, W, 3) frame, got shape {frame.shape}")
        return np.ascontiguousarray(frame.transpose(2, 0, 1), dtype=np.uint8)


class DistractingActionDims:
    """Appends ``n`` action dimensions that the wrapped environment ignores."""

    def __init__(self, env: Env, n: int) -> None:
        if n < 0:
            raise ValueError(f"distracting dims must be >= 0, got {n}")
        self.env = env
        self.n = n
        self._inner_dim = env.spec.action_dim
        self.spec: EnvSpec = dataclasses.replace(env.spec, action_dim=env.spec.action_dim + n)

    def reset(self, seed: int) -> TimeStep:
        return self.env.reset(seed)

    def step(self, action: np.ndarray) -> TimeStep:
        return self.env.step(checked_action(action, self.spec.action_dim, np.float32)[: self._inner_dim])

    def render_view(self, size: int) -> np.ndarray:
        return self.env.render_view(size)

    def close(self) -> None:
        self.env.close()


class TimeLimit:
    """Ends an episode after ``max_agent_steps`` agent steps (``last=True``; discount is left as is)."""

    def __init__(self, env: Env, max_agent_steps: int) -> None:
        if max_agent_steps < 1:
            raise ValueError(f"max_agent_steps must be >= 1, got {max_agent_steps}")
        self.env = env
        self.max_agent_steps = max_agent_steps
        self.spec: EnvSpec = env.spec
        self._steps = 0
        self._done = True

    def reset(self, seed: int) -> TimeStep:
        self._steps = 0
        self._done = False
        return self.env.reset(seed)

    def step(self, action: np.ndarray) -> TimeStep:
        if self._done:
            raise RuntimeError("episode is over: call reset(seed) first")
        ts = self.env.step(action)
        self._steps += 1
        if self._steps >= self.max_agent_steps:
            ts.last = True
        self._done = ts.last
        return ts

    def render_view(self, size: int) -> np.ndarray:
        return self.env.render_view(size)

    def close(self) -> None:
        self.env.close()
