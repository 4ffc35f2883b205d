"""A-LIX (Cetin et al., ICML 2022, "Stabilizing Off-Policy Deep RL from Pixels"): DrQ-v2 whose encoder mixes each
feature map with its neighbours after every convolution (local signal mixing, LIX), by a strength S learned through
its own gradient rule and its own optimizer settings. Online learner ``alix`` (``repro/config/alix.py``): the online
agent (``agent.py``) on the DrQ-v2 backbone (``backbone.py``) given A-LIX's parts (:func:`alix_parts`: the encoder,
the critic, its loss, the encoder's parameter groups and the input augmentation below).

Written from the paper's equations and the facts of the authors' code (Aladoro/Stabilizing-Off-Policy-RL @ 34665c8:
``analysis_layers.py``, ``analysis_custom_autograd_functions.py``, ``analysis_modules.py``, ``analysis_optimizers.py``,
``drqv2.py``, ``cfgs/algo/ALIX.yaml``); ``tests/test_alix.py`` checks the update against recorded values of that code.

* **Local signal mixing** (:func:`local_signal_mixing`), in training mode only: with d = max_shift and p = ceil(d) + 1,
  the feature map is replicate-padded by p and resampled bilinearly (``grid_sample``, zeros outside, corners not
  aligned) at every cell moved by one random offset per axis, uniform in [-(d + 1/2) S, (d + 1/2) S]; with
  ``fixed_batch`` one offset for the whole batch (per layer and pass), else one per sample. The grid is computed in
  the authors' order of operations, so the same uniform draws give the same features bit for bit.
* **The encoder** (:class:`ALIXEncoder`): DrQ-v2's four convolutions, LIX after each ReLU, one strength S for the four
  (clamped to [0, 1] before every pass, as the authors' ``ParameterizedReg``); only the last LIX passes the gradient
  rule (``AllFeatTiedRegularizedEncoder``). Acting never mixes (the authors act in eval mode).
* **The strength's rule** (:class:`StrengthRule`): identity forward; backward passes the features' gradient on and
  gives S the gradient  target - mean log(1 + ND),  ND = noise / (signal + eps) per channel and cell of the
  batch-mean gradient g: with the N x N neighbourhood (replicate-padded) of g, signal = (sum of the squares over the
  neighbourhood - g^2) / (N^2 - 1) and noise = sum of (neighbour - g)^2 / (N^2 - 1). High discontinuity (ND above
  the target) gives a negative gradient, so S grows.
* **Its optimizer** (:func:`strength_apart`): S is a parameter group of the encoder's Adam with its own lr and betas.
* **The critic** (:class:`ParallelCritic`): the authors' twin Q heads as batched (2, in, out) weights, orthogonal
  with the ReLU gain (``utils.DenseParallel``), and their loss form sum over the two heads then mean
  (:func:`parallel_critic_loss`).
* **The input** (:func:`input_aug`): the frames as they are (the authors' NoShiftAug), or DrQ-v2's shift.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Any, cast

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from repro.agent import fast
from repro.agent.agent import Agent
from repro.agent.aug import RandomShift
from repro.agent.backbone import Augment, BackboneParts, ParamGroup
from repro.agent.losses import Metrics, critic_metrics
from repro.agent.networks import Encoder, orthogonal_init, trunk
from repro.config.alix import ALIXConfig
from repro.config.schema import AgentConfig, learner_section

STRENGTH_METRIC = "lix_strength"  # train.csv column: S after the update, as the next pass uses it (clamped)


def local_signal_mixing(x: torch.Tensor, strength: torch.Tensor, max_shift: float, fixed_batch: bool = True
                        ) -> torch.Tensor:
    """LIX of the feature maps ``x`` (N, C, H, H) at ``strength`` S in [0, 1] (a 0-d tensor without gradient); draws
    one ``torch.rand`` of shape (1, 1, 1, 2) (``fixed_batch``) or (N, 1, 1, 2). Float32 whatever autocast is on
    around it (``agent.amp`` / ``agent.fast``: repro/agent/numerics.py): the draw, the shift and the sampling grid in
    bf16 (8 bits) move every sampled cell, so S = 0 was no longer the identity; the result is float32 (the next
    convolution's autocast rounds it to bf16, the strength rule reads it in float32). On float32 input without
    autocast (the plain path) the same ops as before, bit for bit."""
    with torch.autocast(x.device.type, enabled=False):
        return _mix(x.float(), strength.float(), max_shift, fixed_batch)


def _mix(x: torch.Tensor, strength: torch.Tensor, max_shift: float, fixed_batch: bool) -> torch.Tensor:
    """:func:`local_signal_mixing` of float32 ``x``, without autocast (the authors' order of operations)."""
    n, _, h, w = x.shape
    if h != w:
        raise ValueError(f"local signal mixing needs square feature maps (got {h} x {w})")
    pad = int(math.ceil(max_shift)) + 1  # +1: the sampled cells never reach the zeros outside the padding
    s = strength * ((2 * max_shift + 1) / (2 * pad + 1))  # S as a fraction of the padded window
    padded = F.pad(x, (pad,) * 4, mode="replicate")
    u = torch.rand(size=(1 if fixed_batch else n, 1, 1, 2), device=x.device, dtype=x.dtype)
    shift = (u * s + (1 - s) / 2) * (2 * pad + 1)  # the window's start in padded cells, centred at pad + 1/2
    cells = torch.arange(h, device=x.device, dtype=x.dtype)
    base = torch.stack([cells.expand(h, h), cells[:, None].expand(h, h)], dim=-1).expand(n, h, h, 2)  # (x, y)
    grid = (base + shift) * 2.0 / (h + 2 * pad) - 1  # in grid_sample's [-1, 1] (corners not aligned)
    return F.grid_sample(padded, grid, padding_mode="zeros", align_corners=False)


class StrengthRule(torch.autograd.Function):
    """Identity on the features; the gradient of the strength S is ``target - mean log(1 + ND)`` of the features'
    incoming gradient (the module docstring)."""

    @staticmethod
    def forward(ctx: Any, features: torch.Tensor, strength: torch.Tensor, kernel: int, target: float,
                eps: float) -> torch.Tensor:
        ctx.kernel, ctx.target, ctx.eps = kernel, target, eps
        ctx.strength_shape = strength.shape
        return features.view_as(features)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor | None, ...]:
        return grad, strength_gradient(grad, ctx.kernel, ctx.target, ctx.eps).reshape(ctx.strength_shape), \
            None, None, None


def discontinuity(grad: torch.Tensor, kernel: int, eps: float) -> torch.Tensor:
    """ND per channel and cell of the batch mean of ``grad`` (N, C, H, W): noise / (signal + eps), shape (C, H, W)."""
    g = grad.mean(0)  # (C, H, W)
    c, h, w = g.shape
    left = (kernel - 1) // 2
    padded = F.pad(g[:, None], (left, kernel - 1 - left, left, kernel - 1 - left), mode="replicate")
    patches = F.unfold(padded, kernel).view(c, kernel * kernel, h, w)  # each cell's neighbourhood, itself included
    others = kernel * kernel - 1
    signal = (patches.square().sum(1) - g.square()) / others  # mean square of the neighbours
    noise = (patches - g[:, None]).square().sum(1) / others  # mean square difference neighbour - cell
    return noise / (signal + eps)


def strength_gradient(grad: torch.Tensor, kernel: int, target: float, eps: float) -> torch.Tensor:
    """The rule's gradient of S: ``target - mean log(1 + ND)`` (0-d)."""
    return target - torch.log1p(discontinuity(grad, kernel, eps)).mean()


class ALIXEncoder(Encoder):
    """DrQ-v2's encoder (its convolutions, initialisation and ``repr_dim``: :class:`repro.agent.networks.Encoder`)
    with LIX after each convolution's ReLU, in training mode, at the shared strength ``strength`` (a parameter,
    trained by :class:`StrengthRule` through the last LIX only)."""

    def __init__(self, obs_shape: tuple[int, int, int], own: ALIXConfig):
        super().__init__(obs_shape)
        self.strength = nn.Parameter(torch.tensor(float(own.strength_init)))
        self.own = own
        self.relus = frozenset(i for i, layer in enumerate(self.convnet) if isinstance(layer, nn.ReLU))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            self.strength.clamp_(0.0, 1.0)  # S in [0, 1] wherever it is read (the authors clamp before each use)
        own, h = self.own, obs / 255.0 - 0.5
        for i, layer in enumerate(self.convnet):
            h = layer(h)
            if i in self.relus and self.training:
                h = local_signal_mixing(h, self.strength.detach(), own.max_shift, own.fixed_batch)
        h = StrengthRule.apply(h, self.strength, own.kernel, own.target, own.eps)
        return h.flatten(1)


class ParallelLinear(nn.Module):
    """``n`` linear layers applied to one input at once: weight (n, in, out), bias (n, 1, out); x @ W + b gives
    (n, B, out) (the authors' ``utils.DenseParallel``)."""

    def __init__(self, in_features: int, out_features: int, n: int):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(n, in_features, out_features))
        self.bias = nn.Parameter(torch.zeros(n, 1, out_features))

    def reset(self, gain: float) -> None:
        """Each layer's weight orthogonal (times ``gain``), biases zero."""
        with torch.no_grad():
            for w in self.weight:
                nn.init.orthogonal_(w, gain)
            self.bias.zero_()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.matmul(x, self.weight) + self.bias


class ParallelCritic(nn.Module):
    """Twin Q over (state feature, action): DrQ-v2's trunk, then both heads' MLPs as :class:`ParallelLinear` layers.
    ``values`` gives (B, 2); calling it gives (Q1, Q2), each (B, 1), as :class:`repro.agent.networks.Critic`."""

    def __init__(self, repr_dim: int, action_in_dim: int, feature_dim: int, hidden_dim: int, relu_gain: bool):
        super().__init__()
        self.trunk = trunk(repr_dim, feature_dim)
        self.heads = nn.Sequential(
            ParallelLinear(feature_dim + action_in_dim, hidden_dim, 2), nn.ReLU(inplace=True),
            ParallelLinear(hidden_dim, hidden_dim, 2), nn.ReLU(inplace=True),
            ParallelLinear(hidden_dim, 1, 2))
        self.trunk.apply(orthogonal_init)
        gain = nn.init.calculate_gain("relu") if relu_gain else 1.0
        for layer in self.heads:
            if isinstance(layer, ParallelLinear):
                layer.reset(gain)

    def values(self, h: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        qs = self.heads(torch.cat([self.trunk(h), action], dim=-1))  # (2, B, 1)
        return qs.transpose(0, 1).squeeze(-1)

    def forward(self, h: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        qs = self.values(h, action)
        return qs[:, 0:1], qs[:, 1:2]


def strength_apart(own: ALIXConfig, encoder: nn.Module) -> list[ParamGroup]:
    """The encoder's Adam groups (the parts' ``encoder_groups``): its convolutions at ``agent.lr`` first (also the
    auxiliary step's, with objectives), then S with its own lr and betas (the critic step's alone)."""
    strength = encoder.get_parameter("strength")
    convs = [p for p in encoder.parameters() if p is not strength]
    return [{"params": convs},
            {"params": [strength], "lr": own.strength_lr, "betas": (own.strength_beta1, own.strength_beta2)}]


def parallel_critic_loss(critic: nn.Module, critic_target: nn.Module, h: torch.Tensor, action: torch.Tensor,
                         reward: torch.Tensor, discount: torch.Tensor, next_h: torch.Tensor, next_action: torch.Tensor
                         ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor], Metrics]:
    """DrQ-v2's critic loss in the authors' form (the parts' ``critic_loss``, over :class:`ParallelCritic`): sum over
    the two heads of (Q_i - target)^2, mean over the batch; float32 always, as the backbone's."""
    critic_values, target_values = cast(ParallelCritic, critic).values, cast(ParallelCritic, critic_target).values
    with torch.no_grad():
        target_q = reward + discount * target_values(next_h, next_action).amin(dim=1, keepdim=True)
    qs = critic_values(h, action)
    loss = (qs - target_q).square().sum(1).mean()
    q1, q2 = qs[:, 0:1], qs[:, 1:2]
    return loss, (q1, q2), critic_metrics(loss, q1, q2, target_q)


def input_aug(input_shift: int, plan: fast.FastPlan) -> Augment:
    """The frames as float (the authors' NoShiftAug), or DrQ-v2's random shift by ``agent.alix.input_shift`` > 0;
    agent.fast's shift of uint8 frames is not used (``plan``: unread)."""
    return RandomShift(pad=input_shift) if input_shift > 0 else _as_float


def _as_float(x: torch.Tensor) -> torch.Tensor:
    return x.float()


def alix_parts(own: ALIXConfig) -> BackboneParts:
    """A-LIX's parts of the DrQ-v2 backbone: its encoder, critic, critic loss, encoder optimizer groups and input
    augmentation (the action encoder, actor, objectives and the other optimizers are the backbone's)."""
    return BackboneParts(encoder=partial(ALIXEncoder, own=own),
                         critic=partial(ParallelCritic, relu_gain=own.critic_relu_gain),
                         critic_loss=parallel_critic_loss, encoder_groups=partial(strength_apart, own),
                         aug=partial(input_aug, own.input_shift))


class ALIX(Agent):
    """Online learner ``alix``: DrQ-v2's online update (``agent.py``: critic with the encoder, actor on sg(h), target
    critic, then the auxiliary step if the agent file names objectives) on the backbone with A-LIX's parts
    (:func:`alix_parts`); S moves in the critic step, through the encoder's optimizer. Never recorded in a CUDA
    graph."""

    update_metrics = Agent.update_metrics + (STRENGTH_METRIC,)
    graphed = False

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        self.own: ALIXConfig = learner_section(cfg, ALIXConfig)
        super().__init__(cfg, obs_shape, action_dim, device, explore_steps, parts=alix_parts(self.own))

    @property
    def strength(self) -> torch.Tensor:
        """S as the next pass reads it (clamped to [0, 1]), detached."""
        return self.backbone.encoder.get_parameter("strength").detach().clamp(0.0, 1.0)

    def act(self, obs: np.ndarray, step: int, eval_mode: bool) -> np.ndarray:
        """The backbone's action, with the encoder in eval mode (no mixing), as the authors act."""
        encoder = self.backbone.encoder
        mode = encoder.training
        encoder.train(False)
        try:
            return super().act(obs, step, eval_mode)
        finally:
            encoder.train(mode)

    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        """One A-LIX update (the authors' ``DrQV2Agent.update``): the online agent's, then S after it. Detached 0-d
        metrics."""
        metrics = super().update(batch, step)
        metrics[STRENGTH_METRIC] = self.strength
        return metrics
