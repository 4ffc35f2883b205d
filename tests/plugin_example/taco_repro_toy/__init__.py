"""A taco-repro plugin: reward-weighted behaviour cloning (offline learner ``toy_rwbc``), DrQ-v2 with several critic
steps per update (online learner ``toy_utd``) and an inverse-dynamics auxiliary objective (``toy_inv``), registered
through pyproject.toml's entry points (docs/extending.md).

This module is what the entry points load: data only (no torch), since taco-repro loads it to validate config
names. The code is named by ``factory`` and imported when a run builds it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from repro.config.plugins import LearnerSpec, ObjectiveSpec

CONF = Path(__file__).resolve().parent / "conf"  # agent/toy_rwbc.yaml, agent/toy_utd.yaml, agent/toy_inv.yaml


@dataclass
class RWBCConfig:
    """``agent.toy_rwbc``: the learner's own section (its values: conf/agent/toy_rwbc.yaml)."""

    temperature: float  # weight exp((r - max r) / temperature), r the transition's n-step return
    max_weight: float  # cap of a weight after normalising the batch's weights to mean 1


@dataclass
class UTDConfig:
    """``agent.toy_utd``: the online learner's own section (its values: conf/agent/toy_utd.yaml)."""

    critic_steps: int  # critic steps per update, each on its own random shift of the batch (1: DrQ-v2)


@dataclass
class InvParams:
    """``agent.objective_params.toy_inv``: the objective's parameters, each with its default (an agent file may give
    none); taco-repro checks a run's values against it and the objective reads them as an instance of it."""

    hidden_dim: Optional[int] = None  # width of the inverse-dynamics MLP; None: agent.hidden_dim


# ranges: checked with taco-repro's own (one line, exit 2, before a run writes anything): temperature > 0 (it
# divides), max_weight >= 1 (the weights' mean is 1), critic_steps >= 1; the objective's hidden_dim >= 1 when set
# (null is not checked)
LEARNER = LearnerSpec(name="toy_rwbc", offline=True, label="RWBC", section=RWBCConfig,
                      factory="taco_repro_toy.learner:RWBC", conf=CONF,
                      ranges={"temperature": (0.0, False), "max_weight": (1.0, True)})
ONLINE_LEARNER = LearnerSpec(name="toy_utd", offline=False, label="DrQ-v2-UTD", section=UTDConfig,
                             factory="taco_repro_toy.online:UTD", conf=CONF, ranges={"critic_steps": (1, True)})
OBJECTIVE = ObjectiveSpec(name="toy_inv", label="InvDyn", factory="taco_repro_toy.objective:InverseDynamics",
                          conf=CONF, params=InvParams, ranges={"hidden_dim": (1, True)})
