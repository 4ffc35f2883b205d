"""Networks of DrQ-v2 / TACO with the upstream shapes and initialisation."""

from __future__ import annotations

import math

import torch
from torch import nn

from repro.config.schema import LatentRounding


def orthogonal_init(module: nn.Module) -> None:
    """Orthogonal weights and zero biases; convolutions use the ReLU gain (as upstream)."""
    if isinstance(module, nn.Linear):
        nn.init.orthogonal_(module.weight.data)
        if module.bias is not None:
            module.bias.data.fill_(0.0)
    elif isinstance(module, (nn.Conv2d, nn.ConvTranspose2d)):
        nn.init.orthogonal_(module.weight.data, nn.init.calculate_gain("relu"))
        if module.bias is not None:
            module.bias.data.fill_(0.0)


class Encoder(nn.Module):
    """Pixels (uint8 as float) -> flat conv features. 84x84 input gives 32*35*35 = 39200 features."""

    def __init__(self, obs_shape: tuple[int, int, int]):
        super().__init__()
        channels, height, width = obs_shape
        self.convnet = nn.Sequential(
            nn.Conv2d(channels, 32, 3, stride=2), nn.ReLU(),
            nn.Conv2d(32, 32, 3, stride=1), nn.ReLU(),
            nn.Conv2d(32, 32, 3, stride=1), nn.ReLU(),
            nn.Conv2d(32, 32, 3, stride=1), nn.ReLU(),
        )
        side_h = (height - 3) // 2 + 1 - 6
        side_w = (width - 3) // 2 + 1 - 6
        self.repr_dim = 32 * side_h * side_w
        self.apply(orthogonal_init)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        h = self.convnet(obs / 255.0 - 0.5)
        return h.flatten(1)


def trunk(repr_dim: int, feature_dim: int) -> nn.Sequential:
    """Linear -> LayerNorm -> Tanh projection of conv features to the state representation."""
    return nn.Sequential(nn.Linear(repr_dim, feature_dim), nn.LayerNorm(feature_dim), nn.Tanh())


def mlp(in_dim: int, hidden_dim: int, out_dim: int, depth: int = 2) -> nn.Sequential:
    """ReLU MLP with ``depth`` hidden layers."""
    layers: list[nn.Module] = [nn.Linear(in_dim, hidden_dim), nn.ReLU(inplace=True)]
    for _ in range(depth - 1):
        layers += [nn.Linear(hidden_dim, hidden_dim), nn.ReLU(inplace=True)]
    layers.append(nn.Linear(hidden_dim, out_dim))
    return nn.Sequential(*layers)


class TruncatedNormal(torch.distributions.Normal):
    """Normal clipped to [-1+eps, 1-eps] with a straight-through gradient (DrQ-v2's policy noise)."""

    def __init__(self, loc: torch.Tensor, scale: torch.Tensor, low: float = -1.0, high: float = 1.0,
                 eps: float = 1e-6):
        super().__init__(loc, scale, validate_args=False)
        self.low, self.high, self.eps = low, high, eps

    def _clamp(self, x: torch.Tensor) -> torch.Tensor:
        clamped = torch.clamp(x, self.low + self.eps, self.high - self.eps)
        return x - x.detach() + clamped.detach()

    # DrQ-v2's signature: clip first, unlike torch's Distribution.sample(sample_shape)
    def sample(self, clip: float | None = None,  # type: ignore[override]
               sample_shape: torch.Size = torch.Size()) -> torch.Tensor:
        shape = self._extended_shape(sample_shape)
        eps = torch.randn(shape, dtype=self.loc.dtype, device=self.loc.device) * self.scale
        if clip is not None:
            eps = torch.clamp(eps, -clip, clip)
        return self._clamp(self.loc + eps)


class Policy(TruncatedNormal):
    """The actor's action distribution: a :class:`TruncatedNormal` around tanh(``pre_tanh``) with std ``std``, keeping
    ``pre_tanh`` (the policy's output before its tanh), which the actor's health metrics read (losses.py)."""

    def __init__(self, pre_tanh: torch.Tensor, std: float | torch.Tensor):
        mu = torch.tanh(pre_tanh)
        super().__init__(mu, torch.ones_like(mu) * std)
        self.pre_tanh = pre_tanh


class Actor(nn.Module):
    """Actor trunk + policy MLP; tanh mean, std given by the schedule."""

    def __init__(self, repr_dim: int, action_dim: int, feature_dim: int, hidden_dim: int):
        super().__init__()
        self.trunk = trunk(repr_dim, feature_dim)
        self.policy = mlp(feature_dim, hidden_dim, action_dim)
        self.apply(orthogonal_init)

    def forward(self, h: torch.Tensor, std: float | torch.Tensor) -> Policy:
        return Policy(self.policy(self.trunk(h)), std)


class Critic(nn.Module):
    """Critic trunk + twin Q heads over (state feature, action or latent action)."""

    def __init__(self, repr_dim: int, action_in_dim: int, feature_dim: int, hidden_dim: int):
        super().__init__()
        self.trunk = trunk(repr_dim, feature_dim)
        self.q1 = mlp(feature_dim + action_in_dim, hidden_dim, 1)
        self.q2 = mlp(feature_dim + action_in_dim, hidden_dim, 1)
        self.apply(orthogonal_init)

    def forward(self, h: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = torch.cat([self.trunk(h), action], dim=-1)
        return self.q1(x), self.q2(x)


def default_latent_action_dim(action_dim: int, rounding: str) -> int:
    """Latent action size: upstream ``int(1.25|A|) + 1``, paper ``ceil(1.25|A|)`` (a :class:`LatentRounding`)."""
    if rounding == LatentRounding.paper:
        return math.ceil(1.25 * action_dim)
    return int(1.25 * action_dim) + 1


class ActionEncoder(nn.Module):
    """Per-step action encoder ``step`` (|A| -> 64 -> d_u) and sequence encoder ``seq`` (K d_u -> K d_u)."""

    def __init__(self, action_dim: int, latent_dim: int, K: int, hidden_dim: int = 64):
        super().__init__()
        self.latent_dim, self.K = latent_dim, K
        self.step = nn.Sequential(nn.Linear(action_dim, hidden_dim), nn.Tanh(), nn.Linear(hidden_dim, latent_dim))
        self.seq = nn.Sequential(nn.Linear(K * latent_dim, K * latent_dim), nn.LayerNorm(K * latent_dim), nn.Tanh())
        self.apply(orthogonal_init)

    def forward(self, action: torch.Tensor) -> torch.Tensor:
        """Latent of one action per row: (B, |A|) -> (B, d_u)."""
        return self.step(action)

    def encode_sequence(self, actions: torch.Tensor) -> torch.Tensor:
        """Latent of an action sequence: (B, K, |A|) -> (B, K d_u)."""
        return self.seq(self.step(actions).flatten(1))


class SharedHeads(nn.Module):
    """Heads shared by auxiliary objectives: the state projection H and the bilinear matrix W."""

    def __init__(self, repr_dim: int, feature_dim: int):
        super().__init__()
        self.state_proj = trunk(repr_dim, feature_dim)
        self.state_proj.apply(orthogonal_init)
        self.W = nn.Parameter(torch.rand(feature_dim, feature_dim))

    def logits(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Bilinear similarities x W y^T, minus each row's max (no temperature, as upstream)."""
        logits = x @ (self.W @ y.T)
        return logits - logits.max(dim=1, keepdim=True).values
