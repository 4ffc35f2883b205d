"""A taco-repro plugin: reward-weighted behaviour cloning (offline learner ``toy_rwbc``), DrQ-v2 with several critic
steps per update (online learner ``toy_utd``) and an inverse-dynamics auxiliary objective (``toy_inv``), registered
through pyproject.toml's entry points (docs/extending.md).

This module is what the entry points load: data only (no torch), since taco-repro loads it to validate config
names. The code is named by ``factory`` and imported when a run builds it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Optional

from repro.config.plugins import Bound, LearnerSpec, ObjectiveSpec

CONF = Path(__file__).resolve().parent / "conf"  # agent/toy_rwbc.yaml, agent/toy_utd.yaml, agent/toy_inv.yaml


@dataclass
class RWBCConfig:
    """``agent.toy_rwbc``: the learner's own section (its values: conf/agent/toy_rwbc.yaml). A ``Bound`` in a field's
    annotation is checked with taco-repro's own (one line, exit 2, before a run writes anything)."""

    temperature: Annotated[float, Bound(gt=0.0)]  # weight exp((r - max r) / temperature), r the n-step return
    max_weight: Annotated[float, Bound(ge=1.0)]  # cap of a weight after normalising the batch's weights to mean 1


@dataclass
class UTDConfig:
    """``agent.toy_utd``: the online learner's own section (its values: conf/agent/toy_utd.yaml)."""

    critic_steps: Annotated[int, Bound(ge=1)]  # critic steps per update, each on its own random shift (1: DrQ-v2)


@dataclass
class InvParams:
    """``agent.objective_params.toy_inv``: the objective's parameters, each with its default (an agent file may give
    none); taco-repro checks a run's values against it and the objective reads them as an instance of it."""

    hidden_dim: Annotated[Optional[int], Bound(ge=1)] = None  # width of the inverse-dynamics MLP; None: hidden_dim


LEARNER = LearnerSpec(name="toy_rwbc", offline=True, label="RWBC", section=RWBCConfig,
                      factory="taco_repro_toy.learner:RWBC", conf=CONF)
ONLINE_LEARNER = LearnerSpec(name="toy_utd", offline=False, label="DrQ-v2-UTD", section=UTDConfig,
                             factory="taco_repro_toy.online:UTD", conf=CONF)
OBJECTIVE = ObjectiveSpec(name="toy_inv", label="InvDyn", factory="taco_repro_toy.objective:InverseDynamics",
                          conf=CONF, params=InvParams)
