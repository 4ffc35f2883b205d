"""Pluggable auxiliary objectives: each gets the batch and the encoders, returns a loss and metrics."""

from __future__ import annotations

import abc
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import torch
from torch import nn

from repro.agent.networks import SharedHeads
from repro.config.schema import RewardTarget


@dataclass
class ObjectiveContext:
    """What an objective may use when it builds its parameters."""

    repr_dim: int
    feature_dim: int
    hidden_dim: int
    action_dim: int
    K: int
    seq_dim: int  # size of the encoded action sequence (K d_u, or K |A| without action encoder)
    step_dim: int = 0  # size of one encoded action (d_u, or |A| without action encoder)
    # agent.objective_params.<name> typed: an instance of the objective's registered ``params`` dataclass (None: it
    # registers none, or the context was built by hand; ``common.typed_params`` then gives the defaults)
    params: Any = None
    encoder: nn.Module | None = None  # the online conv encoder (read-only reference, e.g. to copy an EMA target)
    _shared: SharedHeads | None = None

    def shared(self) -> SharedHeads:
        """The state projection H and bilinear W shared between objectives (created on first use)."""
        if self._shared is None:
            self._shared = SharedHeads(self.repr_dim, self.feature_dim)
        return self._shared


# encode_with(encoder, frames): another encoder run as the agent's own (its autocast, float32 features)
EncodeWith = Callable[[Callable[[torch.Tensor], torch.Tensor], torch.Tensor], torch.Tensor]


class AuxBatch:
    """One update's data for the auxiliary objectives, with encoder passes computed once and shared.

    Each view applies a fresh random shift: ``anchor`` (gradients flow into the encoder),
    ``positive`` (same observation, other augmentation, no gradient) and ``future`` (the observation
    K steps ahead, no gradient).
    """

    def __init__(self, batch: dict[str, torch.Tensor], encoder: Callable[[torch.Tensor], torch.Tensor], aug: Callable,
                 encode_actions: Callable[[torch.Tensor], torch.Tensor], reward_target: str,
                 encode_action_steps: Callable[[torch.Tensor], torch.Tensor] | None = None,
                 encode_with: EncodeWith | None = None):
        self.batch = batch
        self.encoder = encoder
        self._encode_with = encode_with
        self.aug = aug
        self._encode_actions = encode_actions
        self._encode_steps = encode_action_steps
        self.reward_target = reward_target
        self._cache: dict[str, torch.Tensor] = {}

    def memo(self, key: str, fn: Callable[[], torch.Tensor]) -> torch.Tensor:
        if key not in self._cache:
            self._cache[key] = fn()
        return self._cache[key]

    def anchor(self) -> torch.Tensor:
        return self.memo("anchor", lambda: self.encoder(self.aug(self.batch["obs"])))

    def positive(self) -> torch.Tensor:
        def fn() -> torch.Tensor:
            with torch.no_grad():
                return self.encoder(self.aug(self.batch["obs"]))
        return self.memo("positive", fn)

    def future(self) -> torch.Tensor:
        def fn() -> torch.Tensor:
            with torch.no_grad():
                return self.encoder(self.aug(self.batch["future_obs"]))
        return self.memo("future", fn)

    def encode_by(self, encoder: Callable[[torch.Tensor], torch.Tensor], frames: torch.Tensor) -> torch.Tensor:
        """``encoder`` (another encoder than the agent's, e.g. a momentum target) on augmented ``frames``, as the
        agent's own encoder runs: under its autocast (``agent.amp``/``agent.fast``: the frames may be bf16), the
        features in float32 (repro/agent/numerics.py)."""
        return encoder(frames) if self._encode_with is None else self._encode_with(encoder, frames)

    def encode_actions(self, actions: torch.Tensor) -> torch.Tensor:
        """Encode any (B, K, |A|) action sequence with the agent's action (sequence) encoder."""
        return self._encode_actions(actions)

    def action_steps(self) -> torch.Tensor:
        """Each action a_t..a_{t+K-1} encoded on its own (no sequence encoder): (B, K, step_dim)."""
        if self._encode_steps is None:
            raise ValueError("this AuxBatch was built without a per-step action encoder")
        encode_steps = self._encode_steps
        return self.memo("u_steps", lambda: encode_steps(self.batch["action_seq"]))

    def future_at(self, k: int) -> torch.Tensor:
        """encoder(aug(obs_{t+k})) for k in 1..K, no gradient (needs a batch sampled with future_seq)."""
        if "future_obs_seq" not in self.batch:
            raise ValueError("the batch has no future_obs_seq: sample it with future_seq=True")

        def fn() -> torch.Tensor:
            with torch.no_grad():
                return self.encoder(self.aug(self.batch["future_obs_seq"][:, k - 1]))
        return self.memo(f"future_{k}", fn)

    def action_sequence(self) -> torch.Tensor:
        """Encoded actions a_t..a_{t+K-1}: (B, seq_dim)."""
        return self.memo("u_seq", lambda: self._encode_actions(self.batch["action_seq"]))

    def reward(self) -> torch.Tensor:
        """Reward target: n-step discounted return (upstream) or the sum of the K rewards (paper)."""
        return self.batch["reward"] if self.reward_target == RewardTarget.nstep else self.batch["reward_ksum"]


class Objective(nn.Module, abc.ABC):
    """Base class: subclasses build parameters from the context and implement ``forward``."""

    name: ClassVar[str] = ""  # its registered name (repro/agent/objectives/__init__.py sets it from the registration)
    needs_future_seq: bool = False  # whether batches must carry obs_{t+1}..obs_{t+K} (future_obs_seq)
    extra_metrics: ClassVar[tuple[str, ...]] = ()  # metric suffixes besides "loss", e.g. ("acc",)

    @classmethod
    def metric_keys(cls) -> list[str]:
        """Column names of this objective's metrics in train.csv."""
        return [f"{cls.name}_loss"] + [f"{cls.name}_{m}" for m in cls.extra_metrics]

    def __init__(self, ctx: ObjectiveContext):
        super().__init__()
        self.ctx = ctx

    @abc.abstractmethod
    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """The objective's loss on this batch and its metrics (detached 0-d tensors, no host sync; keys from
        ``metric_keys``)."""

    def after_update(self) -> None:
        """Called after the auxiliary optimizer step (e.g. to move an EMA target). Default: nothing."""


def info_nce(logits: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Cross-entropy against the diagonal, and the accuracy of picking the diagonal (a 0-d tensor)."""
    labels = torch.arange(logits.shape[0], device=logits.device)
    loss = nn.functional.cross_entropy(logits, labels)
    acc = (logits.detach().argmax(dim=1) == labels).float().mean()
    return loss, acc
