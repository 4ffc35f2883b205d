"""A-LIX's registration (issue 38): its typed section ``agent.alix`` and its :class:`LearnerSpec`.

A-LIX (Cetin et al., ICML 2022, "Stabilizing Off-Policy Deep RL from Pixels"; code Aladoro/Stabilizing-Off-Policy-RL
@ 34665c8, MIT) is DrQ-v2 with local signal mixing after each convolution of the encoder and a mixing strength
learned by its own gradient rule. It is registered as a plugin registers a learner (``docs/extending.md``): data
only, no torch; the code is named by ``factory`` and built by ``repro/learners/registry.py``. The values, each with
its source in ``cfgs/algo/ALIX.yaml``, are in ``repro/conf/agent/alix.yaml``; the differences from the authors' code
and their switches in ``docs/deviations.md`` ("A-LIX").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from repro.config.plugins import Bound, LearnerSpec


@dataclass
class ALIXConfig:
    """``agent.alix``: the learner's own section (values: conf/agent/alix.yaml)."""

    max_shift: Annotated[float, Bound(gt=0.0)]  # LocalSignalMixing's `pad`: the largest shift, in cells (strength 1)
    fixed_batch: bool  # one random shift per batch and layer (the authors' `fixed_batch: true`); false: per sample
    strength_init: Annotated[float, Bound(ge=0.0, le=1.0)]  # ParameterizedReg's `parameter_init`: S at the start
    # the rule's N: side of the neighbourhood over which the gradients' discontinuity is measured (odd)
    kernel: Annotated[int, Bound(ge=3)]
    # the rule's `target_capped_ratio`: the mean log(1 + ND) the strength is tuned towards
    target: Annotated[float, Bound(gt=0.0)]
    eps: Annotated[float, Bound(ge=0.0)]  # the rule's stabilising constant in ND = noise / (signal + eps)
    strength_lr: Annotated[float, Bound(ge=0.0)]  # Adam learning rate of S (its parameter group of the encoder's Adam)
    strength_beta1: Annotated[float, Bound(ge=0.0, lt=1.0)]  # Adam beta1 of S
    strength_beta2: Annotated[float, Bound(ge=0.0, lt=1.0)]  # Adam beta2 of S
    # DrQ-v2's random shift of the input frames, in pixels (0: none, the authors' NoShiftAug)
    input_shift: Annotated[int, Bound(ge=0)]
    critic_relu_gain: bool  # the twin Q heads' orthogonal init with the ReLU gain (the authors' DenseParallel init)


SPEC = LearnerSpec(name="alix", offline=False, label="A-LIX", section=ALIXConfig, factory="repro.agent.alix:ALIX")
