"""CQL's conservative regulariser (Kumar et al. 2020, the continuous form) for each critic head.

For one critic head Q and a batch of encoded states h_b (b = 1..B):

    R = alpha * ( T * mean_b logsumexp_j (x_bj / T)  -  mean_b Q(h_b, u(a_b)) )

where a_b is the dataset action, T the temperature (1 in V-D4RL), and the x_bj (j = 1..3N) are Q at
N uniform actions on [-1, 1]^|A|, N policy samples drawn at h_b, and N policy samples drawn at h'_b (the
next state) but evaluated at h_b. With ``importance_sampling=True`` (the original CQL's "min_q_version 3")
each x has its sampling log-density subtracted: log(2^-|A|) for the uniform actions and the policy's
log-probability for the policy samples. Off in the config (``agent.cql.importance_sampling``), as in
V-D4RL's pixel CQL (conglu1997/v-d4rl, ``drqbc/cql.py``: ``cql_importance_sample=False``). Without importance
sampling V-D4RL (and the original CQL's "min_q_version 2") also put the data action's Q inside the logsumexp; that is
``include_data_in_logsumexp=True`` here (``agent.cql.include_data_in_logsumexp``, true as V-D4RL); False is
the three sample sets only. V-D4RL draws the policy samples with their noise clipped to ``stddev_clip`` (the
learner's ``agent.cql.clip_policy_samples``). alpha, T and both switches come from the config (``agent.cql``):
no defaults here.

Policy samples carry no gradient (CQL issue 5: otherwise the regulariser trains the policy). The caller
must pass them detached (drawn under ``torch.no_grad()``); ``critic_regularisers`` detaches them and their
log-probabilities again, so no gradient can reach the actor through them. The uniform actions stay in raw
action space; with TACO the caller's critic callable applies the action encoder u.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch

from repro.learners.losses._checks import same_shape


def uniform_log_density(action_dim: int) -> float:
    """Log density of the uniform distribution on [-1, 1]^action_dim: log(0.5^action_dim)."""
    return -action_dim * math.log(2.0)


def uniform_actions(batch: int, n: int, action_dim: int, like: torch.Tensor,
                    generator: torch.Generator | None = None) -> torch.Tensor:
    """(batch, n, action_dim) actions uniform on [-1, 1], on ``like``'s device and dtype."""
    u = torch.rand(batch, n, action_dim, generator=generator, device=like.device, dtype=like.dtype)
    return 2.0 * u - 1.0


def regulariser(q_data: torch.Tensor, q_uniform: torch.Tensor, q_policy: torch.Tensor,
                q_next_policy: torch.Tensor, alpha: float, temperature: float, *,
                importance_sampling: bool, include_data_in_logsumexp: bool, action_dim: int | None = None,
                log_prob_policy: torch.Tensor | None = None,
                log_prob_next_policy: torch.Tensor | None = None) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """The alpha-weighted regulariser of one critic head, and its parts (detached).

    ``q_data``: (B,) Q at the dataset actions. ``q_uniform``, ``q_policy``, ``q_next_policy``: (B, N) Q at
    the uniform actions, the policy samples at h and the policy samples at h' (all evaluated at h).
    ``log_prob_policy``, ``log_prob_next_policy``: (B, N) log pi of those samples (summed over action
    dimensions), needed only with importance sampling. Parts: ``lse`` (T * mean logsumexp) and ``q_data``.
    """
    same_shape(q_uniform=q_uniform, q_policy=q_policy, q_next_policy=q_next_policy)
    if q_data.shape != q_uniform.shape[:1] or q_uniform.dim() != 2:
        raise ValueError(f"q_data must be (B,) and the sample Qs (B, N); got {tuple(q_data.shape)} "
                         f"and {tuple(q_uniform.shape)}")
    if temperature <= 0:
        raise ValueError(f"temperature must be positive, got {temperature}")
    if importance_sampling:
        if action_dim is None or log_prob_policy is None or log_prob_next_policy is None:
            raise ValueError("importance sampling needs action_dim, log_prob_policy and log_prob_next_policy")
        if include_data_in_logsumexp:
            raise ValueError("include_data_in_logsumexp is the form without importance sampling")
        same_shape(q_policy=q_policy, log_prob_policy=log_prob_policy, log_prob_next_policy=log_prob_next_policy)
        parts = [q_uniform - uniform_log_density(action_dim), q_policy - log_prob_policy.detach(),
                 q_next_policy - log_prob_next_policy.detach()]
    else:
        parts = [q_uniform, q_policy, q_next_policy]
        if include_data_in_logsumexp:
            parts.append(q_data.unsqueeze(1))
    x = torch.cat(parts, dim=1)
    lse = temperature * torch.logsumexp(x / temperature, dim=1).mean()
    q_data_mean = q_data.mean()
    reg = alpha * (lse - q_data_mean)
    return reg, {"lse": lse.detach(), "q_data": q_data_mean.detach()}


def critic_regularisers(critic: Callable[[torch.Tensor, torch.Tensor], Sequence[torch.Tensor]],
                        h: torch.Tensor, q_data: Sequence[torch.Tensor], uniform: torch.Tensor,
                        policy: torch.Tensor, next_policy: torch.Tensor, alpha: float,
                        temperature: float, *, importance_sampling: bool, include_data_in_logsumexp: bool,
                        log_prob_policy: torch.Tensor | None = None,
                        log_prob_next_policy: torch.Tensor | None = None,
                        ) -> tuple[tuple[torch.Tensor, ...], dict[str, torch.Tensor]]:
    """The regulariser of every critic head, and metrics named per head (``cql_reg_q1`` ...).

    ``critic(h_rows, action_rows)`` returns one (rows, 1) or (rows,) tensor per head (the DrQ-v2 Critic, or a
    wrapper applying the action encoder). ``h``: (B, R) encoded states, with the encoder's gradient if the
    encoder is to be trained. ``q_data``: per head, Q at (h, u(a)) for the dataset actions, (B, 1) or (B,).
    ``uniform``, ``policy``, ``next_policy``: (B, N, A) actions; all three sets are evaluated at h in one
    critic call over B * 3N rows. Policy samples and log-probabilities are detached here.
    Metrics per head i: ``cql_reg_q{i}`` (alpha-weighted), ``cql_lse_q{i}``, ``cql_q_data_q{i}``,
    ``cql_q_uniform_q{i}``, ``cql_q_policy_q{i}``, ``cql_q_next_policy_q{i}``.
    """
    same_shape(uniform=uniform, policy=policy, next_policy=next_policy)
    batch, n, action_dim = uniform.shape
    if h.shape[0] != batch:
        raise ValueError(f"h has {h.shape[0]} rows but the actions {batch}")
    actions = torch.cat([uniform, policy.detach(), next_policy.detach()], dim=1)  # (B, 3N, A)
    h_rows = h.repeat_interleave(3 * n, dim=0)  # row b*3N + j is state b
    q_heads = critic(h_rows, actions.reshape(batch * 3 * n, action_dim))
    if len(q_heads) != len(q_data):
        raise ValueError(f"the critic returned {len(q_heads)} heads but q_data has {len(q_data)}")
    regs: list[torch.Tensor] = []
    metrics: dict[str, torch.Tensor] = {}
    for i, (q_all, q_d) in enumerate(zip(q_heads, q_data), start=1):
        q_all = q_all.reshape(batch, 3 * n)
        q_u, q_p, q_np = q_all[:, :n], q_all[:, n:2 * n], q_all[:, 2 * n:]
        reg, parts = regulariser(q_d.reshape(batch), q_u, q_p, q_np, alpha, temperature,
                                 importance_sampling=importance_sampling, action_dim=action_dim,
                                 log_prob_policy=log_prob_policy, log_prob_next_policy=log_prob_next_policy,
                                 include_data_in_logsumexp=include_data_in_logsumexp)
        regs.append(reg)
        metrics[f"cql_reg_q{i}"] = reg.detach()
        metrics[f"cql_lse_q{i}"] = parts["lse"]
        metrics[f"cql_q_data_q{i}"] = parts["q_data"]
        metrics[f"cql_q_uniform_q{i}"] = q_u.detach().mean()
        metrics[f"cql_q_policy_q{i}"] = q_p.detach().mean()
        metrics[f"cql_q_next_policy_q{i}"] = q_np.detach().mean()
    return tuple(regs), metrics
