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

from repro.config.plugins import LearnerSpec


@dataclass
class ALIXConfig:
    """``agent.alix``: the learner's own section (values: conf/agent/alix.yaml)."""

    max_shift: float  # LocalSignalMixing's `pad`: the largest mixing shift, in feature-map cells (strength 1)
    fixed_batch: bool  # one random shift per batch and layer (the authors' `fixed_batch: true`); false: per sample
    strength_init: float  # ParameterizedReg's `parameter_init`: the strength S at the start, in [0, 1]
    kernel: int  # the rule's N: side of the neighbourhood over which the gradients' discontinuity is measured (odd)
    target: float  # the rule's `target_capped_ratio`: the mean log(1 + ND) the strength is tuned towards
    eps: float  # the rule's stabilising constant in ND = noise / (signal + eps)
    strength_lr: float  # Adam learning rate of S (its own parameter group of the encoder's optimizer)
    strength_beta1: float  # Adam beta1 of S
    strength_beta2: float  # Adam beta2 of S
    input_shift: int  # DrQ-v2's random shift of the input frames, in pixels (0: none, the authors' NoShiftAug)
    critic_relu_gain: bool  # the twin Q heads' orthogonal init with the ReLU gain (the authors' DenseParallel init)


SPEC = LearnerSpec(name="alix", offline=False, label="A-LIX", section=ALIXConfig, factory="repro.agent.alix:ALIX",
                   ranges={"max_shift": (0.0, False), "kernel": (3, True), "target": (0.0, False),
                           "eps": (0.0, True), "strength_init": (0.0, True, 1.0, True), "strength_lr": (0.0, True),
                           "strength_beta1": (0.0, True, 1.0, False), "strength_beta2": (0.0, True, 1.0, False),
                           "input_shift": (0, True)})
