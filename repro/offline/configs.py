"""Config sections of the offline learners (TD3+BC, IQL, Decision Transformer).

Defined here so that the loss modules own their defaults; ``repro/schema.py`` wires them into the run
config (CQL's section, ``CQLConfig``, already lives there). Each default names its source.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional


@dataclass
class TD3BCConfig:
    """TD3+BC's actor loss (Fujimoto & Gu 2021, eq. 5; V-D4RL's DrQ+BC on the DrQ-v2 backbone)."""

    alpha: float = 2.5  # paper section 5.2: 2.5 (no difference in [2, 3])
    # "min": lambda and the Q term from min(Q1, Q2) (V-D4RL's DrQ+BC); "q1": from Q1 only (original paper)
    lambda_from: str = "min"


@dataclass
class IQLConfig:
    """Implicit Q-learning (Kostrikov et al. 2022)."""

    expectile: float = 0.7  # paper (TACO appendix): 0.7
    beta: float = 0.1  # inverse temperature; the TACO paper's 0.1; the IQL reference MuJoCo config uses 3
    max_weight: float = 100.0  # exp(beta * adv) is clipped here (IQL reference code)
    # which V the actor's advantage and the critic's target use: "after" the value step (the JAX code's
    # learner.py, the default) or "before" it (CORL's iql.py)
    value_for_targets: str = "after"
    # None: constant actor learning rate (DrQ-v2); N: cosine decay of the actor's rate to 0 over N updates
    # (the JAX code's opt_decay_schedule "cosine" with max_steps = N)
    actor_lr_cosine_updates: Optional[int] = None
    # False: the DrQ-v2 actor's scheduled std in log pi (DrQ-v2); True: a learned state-independent log-std
    # (the JAX actor: NormalTanhPolicy(state_dependent_std=False, log_std_min=-5), zeros at start)
    learned_log_std: bool = False
    # "none": the dataset's rewards as they are (DrQ-v2 / V-D4RL); "return_range": rewards x 1000 / (best - worst
    # episode return of the dataset), the JAX code's normalize() of locomotion datasets (train_offline.py)
    reward_scaling: str = "none"


@dataclass
class DTConfig:
    """Decision Transformer (Chen et al. 2021, the gym setting of github kzl/decision-transformer)."""

    context: int = 20
    embed_dim: int = 128
    n_layers: int = 3
    n_heads: int = 1
    dropout: float = 0.1
    lr: float = 1e-4
    weight_decay: float = 1e-4
    warmup_steps: int = 10_000
    grad_clip: float = 0.25
    batch_size: int = 64
    rtg_scale: float = 1e-3  # returns-to-go are multiplied by this (1/1000)
    max_timestep: int = 1000  # size of the learned timestep embedding; episodes must be shorter
    activation: str = "relu"  # feed-forward activation (Chen et al.'s --activation_function default); CORL: gelu
    init: str = "gpt2"  # "gpt2": N(0, 0.02) body weights (GPT2PreTrainedModel); "torch": torch's layer defaults
    ff_dropout: bool = False  # a dropout after the activation (torch's TransformerEncoderLayer); GPT-2: none
    action_pad: float = -10.0  # value of padded action slots in training windows (Chen et al.'s get_batch)
