"""Implicit Q-learning (Kostrikov et al. 2022): expectile value, critic target from V(s'), AWR actor.

    d          = min_i Qtarget_i(s, a) - V(s)
    value loss = mean |tau - 1(d < 0)| d^2                          (tau: the expectile, the paper's 0.7)
    target     = r + discount * V(s')                               (discount from the batch: gamma^n x not-done)
    critic     = sum_i mean (Q_i(s, a) - target)^2
    actor loss = -mean min(exp(beta * adv), max_weight) * log pi(a | s),   adv = min_i Qtarget_i(s, a) - V(s)

Everything that is a target is detached here: the target critic's Q values, V(s') in the critic target,
and the advantage weight (the actor's loss reaches only log pi). beta is an inverse temperature: 0.1 is
the TACO paper's value and the reference code's ``Learner`` default; the reference MuJoCo config
(ikostrikov/implicit_q_learning, ``configs/mujoco_config.py``) uses temperature 3, i.e. beta = 3.
The JAX reference order is value, actor, critic, the actor and the critic using V after the value step; the
learner owns the order and the optimizer steps. tau, beta and max_weight come from the config (``agent.iql``):
no defaults here.
"""

from __future__ import annotations

import math

import torch

from repro.learners.losses._checks import same_shape


def value_loss(target_q1: torch.Tensor, target_q2: torch.Tensor, v: torch.Tensor,
               expectile: float) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Expectile regression of V(s) onto min_i Qtarget_i(s, a); the target critic gets no gradient."""
    same_shape(target_q1=target_q1, target_q2=target_q2, v=v)
    if not 0.0 < expectile < 1.0:
        raise ValueError(f"expectile must be in (0, 1), got {expectile}")
    d = torch.min(target_q1, target_q2).detach() - v
    weight = torch.abs(expectile - (d < 0).to(d.dtype))
    loss = (weight * d.pow(2)).mean()
    return loss, {"value_loss": loss.detach(), "value_v": v.detach().mean()}


def critic_target(reward: torch.Tensor, discount: torch.Tensor, next_v: torch.Tensor) -> torch.Tensor:
    """r + discount * V(s'), detached (V(s') is a target)."""
    same_shape(reward=reward, discount=discount, next_v=next_v)
    return (reward + discount * next_v).detach()


def critic_loss(q1: torch.Tensor, q2: torch.Tensor, target: torch.Tensor
                ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Sum over the twin heads of the mean squared error to the (detached) target."""
    same_shape(q1=q1, q2=q2, target=target)
    target = target.detach()
    loss = (q1 - target).pow(2).mean() + (q2 - target).pow(2).mean()
    return loss, {"critic_loss": loss.detach(), "critic_q1": q1.detach().mean(), "critic_q2": q2.detach().mean(),
                  "critic_target_q": target.mean()}


def actor_loss(log_prob: torch.Tensor, target_q1: torch.Tensor, target_q2: torch.Tensor, v: torch.Tensor,
               beta: float, max_weight: float) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Advantage-weighted regression: -mean min(exp(beta * adv), max_weight) * log pi(a|s).

    ``log_prob``: log pi(a|s) of the dataset action, summed over action dimensions, same shape as ``v``.
    The weight (from the target critic and V) is detached: only log pi carries gradient.
    """
    same_shape(log_prob=log_prob, target_q1=target_q1, target_q2=target_q2, v=v)
    adv = (torch.min(target_q1, target_q2) - v).detach()
    weight = torch.clamp(torch.exp(beta * adv), max=max_weight)
    loss = -(weight * log_prob).mean()
    return loss, {"actor_loss": loss.detach(), "actor_adv": adv.mean(),
                  "actor_weight": weight.detach().mean(), "actor_logprob": log_prob.detach().mean()}


def cosine_lr(base_lr: float, update: int, decay_updates: int) -> float:
    """The JAX code's actor learning rate at 0-based update ``update``: optax's cosine_decay_schedule (alpha 0)
    over ``decay_updates``, base_lr * (1 + cos(pi * min(update, decay_updates) / decay_updates)) / 2."""
    if decay_updates <= 0:
        raise ValueError(f"actor_lr_cosine_updates must be positive, got {decay_updates}")
    progress = min(max(update, 0), decay_updates) / decay_updates
    return base_lr * 0.5 * (1.0 + math.cos(math.pi * progress))
