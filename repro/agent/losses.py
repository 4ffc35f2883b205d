"""DrQ-v2's actor-critic losses (Yarats et al. 2021), pure functions of tensors: the online agent and the offline
learners on the DrQ-v2 backbone (``repro/agent/backbone.py``) all use these.

    target = r + discount * min_i Qtarget_i(h', u(a'))        a' a clipped-noise policy sample at h'
    critic = sum_i mse(Q_i(h, u(a)), target)
    actor  = -mean min_i Q_i(sg(h), u(a~))                   a~ a clipped-noise policy sample at sg(h)

The backbone computes Q in float32 (``agent.amp`` autocasts the encoder only: repro/agent/backbone.py); the casts to
float32 below keep the losses float32 for any caller. Metrics are detached 0-d tensors (no host sync).
"""

from __future__ import annotations

import torch
from torch import nn

Metrics = dict[str, torch.Tensor]  # an update's metrics: detached 0-d tensors, keyed by train.csv column

CRITIC_METRICS = ("critic_loss", "critic_q1", "critic_q2", "critic_target_q")
# The actor's health (issue 49): the share of the batch's action-mean entries (state x action dimension) whose tanh is
# exactly +-1 in float32, where the policy gradient through the tanh is exactly zero, and the mean |pre-tanh| of the
# policy (float32's tanh reaches +-1 from |x| ~ 9.01 on). For a one-dimensional action the share is of states.
SATURATION_METRICS = ("actor_saturated", "actor_pretanh")
ACTOR_METRICS = ("actor_loss", "actor_logprob", "actor_ent", *SATURATION_METRICS)


def critic_target(reward: torch.Tensor, discount: torch.Tensor, target_q1: torch.Tensor,
                  target_q2: torch.Tensor) -> torch.Tensor:
    """r + discount x min(Qtarget_1, Qtarget_2), in float32."""
    return (reward + discount * torch.min(target_q1, target_q2)).float()


def critic_loss(q1: torch.Tensor, q2: torch.Tensor, target: torch.Tensor
                ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
    """sum_i mse(Q_i, target), and (Q1, Q2) in float32."""
    q1, q2 = q1.float(), q2.float()
    return nn.functional.mse_loss(q1, target) + nn.functional.mse_loss(q2, target), (q1, q2)


def critic_metrics(loss: torch.Tensor, q1: torch.Tensor, q2: torch.Tensor, target: torch.Tensor) -> Metrics:
    """The critic's train.csv columns (``CRITIC_METRICS``)."""
    return {"critic_loss": loss.detach(), "critic_q1": q1.detach().mean(), "critic_q2": q2.detach().mean(),
            "critic_target_q": target.detach().mean()}


def actor_loss(q1: torch.Tensor, q2: torch.Tensor) -> torch.Tensor:
    """-mean min(Q1, Q2) at the policy's actions, in float32."""
    return -torch.min(q1, q2).float().mean()


def saturation_metrics(mean: torch.Tensor, pre_tanh: torch.Tensor) -> Metrics:
    """``SATURATION_METRICS`` of a tanh policy: the share of entries of ``mean`` (its tanh, (B, |A|)) exactly at +-1,
    and the mean |``pre_tanh``|."""
    at_bound = mean.detach().abs() >= 1.0
    return {"actor_saturated": at_bound.float().mean(), "actor_pretanh": pre_tanh.detach().abs().float().mean()}


def actor_metrics(loss: torch.Tensor, log_prob: torch.Tensor, entropy: torch.Tensor, mean: torch.Tensor,
                  pre_tanh: torch.Tensor) -> Metrics:
    """The actor's train.csv columns (``ACTOR_METRICS``): its loss, the mean log-probability of its samples, the
    mean entropy of its distribution (``log_prob``, ``entropy``: summed over action dimensions) and its saturation
    (:func:`saturation_metrics` of the policy's ``mean`` and ``pre_tanh``)."""
    return {"actor_loss": loss.detach(), "actor_logprob": log_prob.detach().mean(),
            "actor_ent": entropy.detach().mean(), **saturation_metrics(mean, pre_tanh)}
