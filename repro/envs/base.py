"""The environment interface every suite wrapper implements."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt


@dataclass
class TimeStep:
    """One agent step of a pixel environment.

    ``observation`` is uint8 with shape ``(3 * frame_stack, H, W)``, the newest frame in the last three
    channels; on ``reset`` the first frame is repeated ``frame_stack`` times.
    ``reward`` is summed over the action repeat (0.0 on reset); ``discount`` is 1.0 except at a true
    terminal state (0.0). ``last`` is true on the final step of an episode (time limit or terminal).
    ``info`` holds suite extras, e.g. ``{"success": 0.0 or 1.0}`` for Meta-world.
    """

    observation: np.ndarray
    reward: float
    discount: float
    first: bool
    last: bool
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class EnvSpec:
    """Static facts about a built environment."""

    action_dim: int  # including distracting dimensions
    obs_shape: tuple[int, int, int]  # (3 * frame_stack, H, W)
    has_success: bool  # whether info["success"] is defined (Meta-world)


class Env(Protocol):
    """A pixel environment with actions in [-1, 1]^action_dim (float32)."""

    spec: EnvSpec

    def reset(self, seed: int) -> TimeStep:
        """Start a new episode. All task randomness is re-seeded from ``seed`` (deterministic)."""
        ...

    def step(self, action: np.ndarray) -> TimeStep: ...

    def render_view(self, size: int) -> np.ndarray:
        """The current scene from the observation camera at ``size`` x ``size`` pixels, (H, W, 3) uint8.

        For people (evaluation videos), not for the agent: it does not touch the observation stack."""
        ...

    def close(self) -> None: ...


def checked_action(action: np.ndarray, action_dim: int, dtype: npt.DTypeLike) -> np.ndarray:
    """``action`` as an array of ``dtype``; a ValueError unless its shape is ``(action_dim,)``."""
    action = np.asarray(action, dtype=dtype)
    if action.shape != (action_dim,):
        raise ValueError(f"expected action shape ({action_dim},), got {action.shape}")
    return action
