"""TD3+BC actor loss (Fujimoto & Gu 2021) in V-D4RL's DrQ+BC form on the DrQ-v2 backbone.

    loss = -lambda * mean_b Q(sg(h_b), u(a~_b)) + mean_{b,j} (a~_bj - a_bj)^2
    lambda = alpha / mean_b |Q(sg(h_b), u(a~_b))|   (a constant: no gradient flows through it)

with a~ the clipped-noise policy sample and a the dataset action (the BC term stays in raw action space).
``lambda_from="min"`` (V-D4RL's DrQ+BC) takes Q = min(Q1, Q2); ``lambda_from="q1"`` is the original paper's
form, where both lambda and the Q term come from Q1 alone. Both values come from the config
(``agent.td3bc.alpha``, ``agent.td3bc.lambda_from``): no defaults here.

The learner computes the Q values (the critic, the encoder's detach and the action encoder are its job)
and steps the optimizer; this module only turns tensors into a loss.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from repro.config.schema import LambdaFrom
from repro.learners.losses._checks import same_shape


def actor_loss(q1: torch.Tensor, q2: torch.Tensor, policy_action: torch.Tensor, data_action: torch.Tensor,
               alpha: float, lambda_from: LambdaFrom | str) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """TD3+BC actor loss and its metrics.

    ``q1``, ``q2``: the critic's heads at (sg(h), u(policy_action)), same shape (e.g. (B, 1)).
    ``policy_action``: the policy sample a~ (B, A), carrying the actor's gradient.
    ``data_action``: the dataset action (B, A); detached here, so no gradient ever reaches it.
    Metrics: ``actor_loss``, ``actor_lambda``, ``actor_bc`` (the BC term), ``actor_q`` (mean Q term).
    """
    same_shape(q1=q1, q2=q2)
    same_shape(policy_action=policy_action, data_action=data_action)
    if lambda_from == LambdaFrom.min:
        q = torch.min(q1, q2)
    elif lambda_from == LambdaFrom.q1:
        q = q1
    else:
        raise ValueError(f"lambda_from must be one of {', '.join(LambdaFrom)}, got {lambda_from!r}")
    lam = alpha / q.detach().abs().mean()
    q_term = q.mean()
    bc = F.mse_loss(policy_action, data_action.detach())
    loss = -lam * q_term + bc
    metrics = {"actor_loss": loss.detach(), "actor_lambda": lam.detach(), "actor_bc": bc.detach(),
               "actor_q": q_term.detach()}
    return loss, metrics
