"""Decision Transformer (offline learner ``dt``) on pixels: the model, loss, sampler and optimizer of
``repro/learners/dt_model.py`` and ``repro/learners/losses/dt.py`` wired to the learner protocol.

Training: ``make_sampler`` builds the window sampler from the dataset's episodes (the offline loop then
skips the replay); each update is AdamW on the masked action MSE, gradients clipped to ``dt.grad_clip``,
then one step of the linear warm-up schedule. No image augmentation (the Atari DT uses none).
Evaluation: ``set_target_return`` picks the return the next episodes are conditioned on; ``begin_episode``
starts an ``EvalContext`` at that target, ``act`` feeds the model the last ``dt.context`` steps and
``observe`` records the action taken and decrements the return-to-go by the scaled reward.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from repro.agent.losses import Metrics
from repro.agent.modules import LearnerBase, count_parameters
from repro.agent.protocol import EpisodeLimit
from repro.config.schema import AgentConfig, DTConfig, learner_section
from repro.learners.dt_model import DecisionTransformer, EvalContext, SequenceSampler, batch_to_tensors, make_optimizer
from repro.learners.losses.dt import action_loss

METRICS = ("dt_loss", "lr", "grad_norm")  # grad_norm: before clipping; lr: the rate this update used


class DT(LearnerBase):
    """Offline learner ``dt``."""

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        if obs_shape[0] % 3:
            raise ValueError(f"obs_shape {obs_shape}: channels must be 3 x frame_stack")
        self.cfg, self.dt = cfg, learner_section(cfg, DTConfig)
        self.device = torch.device(device)
        self.action_dim = action_dim
        self.frame_stack = obs_shape[0] // 3
        self.sample_options: dict[str, Any] = {}
        self.model = DecisionTransformer(obs_shape, action_dim, context=self.dt.context, embed_dim=self.dt.embed_dim,
                                         n_layers=self.dt.n_layers, n_heads=self.dt.n_heads, dropout=self.dt.dropout,
                                         max_timestep=self.dt.max_timestep, activation=self.dt.activation,
                                         init=self.dt.init, ff_dropout=self.dt.ff_dropout).to(self.device)
        self.optimizer, self.scheduler = make_optimizer(self.model, lr=self.dt.lr, weight_decay=self.dt.weight_decay,
                                                        warmup_steps=self.dt.warmup_steps)
        self.sampler: SequenceSampler | None = None
        self.target_return = 0.0
        self._episode: EvalContext | None = None
        self.train(True)

    # ----------------------------------------------------------------- protocol
    @staticmethod
    def max_episode_length(cfg: AgentConfig) -> EpisodeLimit | None:
        """``agent.dt.max_timestep``: the timestep embedding's size."""
        return EpisodeLimit(int(learner_section(cfg, DTConfig).max_timestep), "agent.dt.max_timestep")

    @property
    def batch_size(self) -> int:
        """Windows per update: ``agent.dt.batch_size`` (the offline loop and the bench read this)."""
        return int(self.dt.batch_size)

    @property
    def resolved(self) -> dict[str, object]:
        return {"batch_size": self.batch_size}

    def modules(self) -> dict[str, nn.Module]:
        """The model's parts, for the parameter table (``model`` holds them all)."""
        m = self.model
        embeddings = nn.ModuleList([m.embed_state, m.embed_return, m.embed_action, m.embed_timestep, m.embed_ln])
        return {"encoder": m.encoder, "embeddings": embeddings, "transformer": m.transformer,
                "head": m.predict_action}

    def parameter_counts(self) -> list[tuple[str, int]]:
        return count_parameters(self.modules())

    def metric_names(self) -> list[str]:
        return list(METRICS)

    def state_dict(self) -> dict:
        state: dict[str, Any] = {"modules": {"model": self.model.state_dict()},
                                 "optimizers": {"model": self.optimizer.state_dict()},
                                 "schedulers": {"model": self.scheduler.state_dict()}}
        if self.sampler is not None:
            state["sampler"] = self.sampler.state_dict()
        return state

    def load_state_dict(self, state: dict) -> None:
        self.model.load_state_dict(state["modules"]["model"])
        self.optimizer.load_state_dict(state["optimizers"]["model"])
        if "schedulers" in state:
            self.scheduler.load_state_dict(state["schedulers"]["model"])
        if self.sampler is not None and "sampler" in state:
            self.sampler.load_state_dict(state["sampler"])

    def train(self, training: bool = True) -> None:
        self.training = training
        self.model.train(training)

    # ----------------------------------------------------------------- training
    def make_sampler(self, episodes: Sequence[Mapping[str, np.ndarray]], seed: int) -> SequenceSampler:
        """The window sampler over ``episodes`` (kept: its RNG is part of ``state_dict``)."""
        self.sampler = SequenceSampler(episodes, context=self.dt.context, frame_stack=self.frame_stack,
                                       rtg_scale=self.dt.rtg_scale, seed=seed, max_timestep=self.dt.max_timestep,
                                       action_pad=self.dt.action_pad)
        return self.sampler

    def update(self, batch: Mapping[str, Any], step: int) -> Metrics:
        """One AdamW step on a sampler batch (numpy arrays or tensors, with the sampler's ``keep``); ``step`` is
        unused (the warm-up schedule counts its own steps and is checkpointed)."""
        b = batch_to_tensors(batch, self.device)
        pred = self.model(b["frames"], b["actions"], b["rtg"], b["timesteps"], b["mask"])
        loss = action_loss(pred, b["actions"], b["keep"])
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        norm = torch.nn.utils.clip_grad_norm_(self.model.parameters(), self.dt.grad_clip)
        lr = torch.tensor(self.optimizer.param_groups[0]["lr"], dtype=torch.float64)  # a host value: no sync
        self.optimizer.step()
        self.scheduler.step()
        return {"dt_loss": loss.detach(), "lr": lr, "grad_norm": norm.detach()}

    # ----------------------------------------------------------------- evaluation
    def set_target_return(self, value: float) -> None:
        """The (unscaled) return that the following episodes are conditioned on."""
        self.target_return = float(value)

    def begin_episode(self) -> None:
        self._episode = EvalContext(self.target_return, context=self.dt.context, rtg_scale=self.dt.rtg_scale)

    def observe(self, action: np.ndarray, reward: float) -> None:
        if self._episode is None:
            raise RuntimeError("observe() before begin_episode()")
        self._episode.record(action, reward)

    def model_inputs(self, obs: np.ndarray) -> dict[str, torch.Tensor]:
        """The batch of one window ending at ``obs`` (advances the episode's history). Timesteps past the
        embedding's last index reuse it (never the case for DMC: 500 steps < dt.max_timestep 1000)."""
        if self._episode is None:
            self.begin_episode()
        assert self._episode is not None
        window = self._episode.inputs(obs, self.action_dim)
        window["timesteps"] = np.minimum(window["timesteps"], self.dt.max_timestep - 1)
        return batch_to_tensors({k: v[None] for k, v in window.items()}, self.device)

    @torch.no_grad()
    def act(self, obs: np.ndarray, step: int, eval_mode: bool) -> np.ndarray:
        """The predicted action at the newest step (deterministic; ``eval_mode`` changes nothing)."""
        x = self.model_inputs(obs)
        pred = self.model(x["frames"], x["actions"], x["rtg"], x["timesteps"], x["mask"])
        return pred[0, -1].cpu().numpy().astype(np.float32)
