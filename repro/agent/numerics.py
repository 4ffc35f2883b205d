"""The numerics contract of ``agent.amp`` / ``agent.fast``: the one list of what may compute in bfloat16.

Under ``agent.amp`` (or ``agent.fast`` where bf16 is native: ``fast.py``) an online learner runs its encoder's
convolutions under bfloat16 autocast (``DrQV2Backbone.encode``); everything else stays float32: the trunks, the
actor's tanh, the Q heads, the objectives' heads, A-LIX's mixing layer and strength rule, and every loss. Twice an op
that must be exact ran in bf16 all the same: the actor's tanh and the Q heads under an autocast that covered the
whole update (issue 33: tanh rounds to exactly +-1 from |mu| ~ 3.5, a zero gradient), then A-LIX's mixing layer,
whose random draw, shift and sampling grid took the dtype of its bf16 input (at strength 0, meant to be the
identity, it moved features by up to 0.2).

:data:`BF16_ALLOWED` declares every place allowed to produce a bf16 tensor, by the module or the function that
produces it and the aten ops it may run there:

* ``torch.nn.Conv2d`` inside an :class:`~repro.agent.networks.Encoder` (the online encoder, A-LIX's, a momentum
  copy): autocast's casts of its input, weight and bias (``aten::_to_copy``) and the convolution;
* ``torch.nn.ReLU`` inside an Encoder: ``aten::relu`` of a bf16 convolution output (exact: max(x, 0));
* ``Encoder.forward`` itself: ``x / 255 - 0.5`` on frames that ``agent.fast``'s ``bf16_input`` handed over in bf16
  (autocast would round it to bf16 before the first convolution anyway) and the flatten of the last ReLU's output
  (a copy of NHWC memory with ``channels_last``);
* ``ShiftU8.__call__`` (``fast.py``): the cropped uint8 frames converted to bf16 (exact: integers 0..255).

An op of the backward pass may produce bf16 only as the gradient of an op made at one of these places (the gradient
of a bf16 op is bf16), or as the gradient of a cast out of bf16 (:data:`BF16_GRADIENT_CAST`: the encoder's output
cast to float32 in ``DrQV2Backbone.encode``, A-LIX's mixing layer casting its input, autocast's own casts to
float32), which hands the gradient back in the dtype of a bf16 tensor whose own op was checked. Views of a bf16
tensor (``view``, ``permute``, ``detach``, ...) are not listed: they compute nothing, and the op that made the tensor
they view is checked. ``tests/test_numerics_contract.py`` runs one update of every registered online learner under
``agent.amp`` and ``agent.fast`` and fails naming each module or op that produced a bf16 tensor elsewhere; a learner
of a plugin that needs another place in bf16 adds it here, with its why.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import CodeType
from typing import Any

from torch import nn

from repro.agent.fast import ShiftU8
from repro.agent.networks import Encoder


@dataclass(frozen=True)
class Bf16Site:
    """One place allowed to produce bfloat16 tensors: an op runs there when the innermost module running is a
    ``module`` (within an ``inside`` module, when given) and the innermost function of the project running is
    ``function`` (when given). ``ops``: the aten ops (``aten::`` names without it) that may return bf16 there in the
    forward pass; the backward pass may be bf16 for every op made there."""

    what: str
    ops: frozenset[str]
    why: str
    module: type[nn.Module] | None = None
    inside: type[nn.Module] | None = None
    function: Callable[..., Any] | None = None

    def covers(self, modules: Sequence[nn.Module], code: CodeType | None) -> bool:
        """Whether an op run with ``modules`` entered (outermost first) from the project function ``code`` runs
        here."""
        if self.module is not None and not (modules and isinstance(modules[-1], self.module)):
            return False
        if self.inside is not None and not any(isinstance(m, self.inside) for m in modules[:-1]):
            return False
        return self.function is None or code is getattr(self.function, "__code__", None)


BF16_ALLOWED: tuple[Bf16Site, ...] = (
    Bf16Site("the encoder's convolutions", frozenset({"convolution", "_to_copy"}),
             "agent.amp's point: autocast casts the input, weight and bias to bf16 and convolves in bf16",
             module=nn.Conv2d, inside=Encoder),
    Bf16Site("the ReLUs between the encoder's convolutions", frozenset({"relu"}),
             "max(x, 0) of a bf16 convolution output: exact",
             module=nn.ReLU, inside=Encoder),
    Bf16Site("the encoder's input scaling and flatten", frozenset({"div", "sub", "clone", "_unsafe_view"}),
             "bf16_input: x / 255 - 0.5 on bf16 frames (autocast rounds it to bf16 before the first convolution "
             "anyway); the flatten of the last ReLU's bf16 output (a copy of NHWC memory with channels_last)",
             module=Encoder, function=Encoder.forward),
    Bf16Site("the uint8 random shift's frames", frozenset({"_to_copy", "clone"}),
             "bf16_input: the cropped uint8 frames converted to bf16, exact (integers 0..255)",
             function=ShiftU8.__call__),
)
# the backward pass's (autograd node, aten op) that returns the gradient of a cast (``.float()``, ``.to``, autocast's)
# in the dtype of its input: bf16 exactly when the cast was out of bf16
BF16_GRADIENT_CAST = ("ToCopyBackward0", "_to_copy")


def allowed_forward(op: str, modules: Sequence[nn.Module], code: CodeType | None) -> bool:
    """Whether aten op ``op`` (e.g. ``convolution``) may return bf16 when run with ``modules`` entered from the
    project function ``code`` (:meth:`Bf16Site.covers`)."""
    return any(op in site.ops and site.covers(modules, code) for site in BF16_ALLOWED)


def allowed_backward(node: str, op: str, modules: Sequence[nn.Module] | None, code: CodeType | None) -> bool:
    """Whether aten op ``op`` of autograd node ``node`` (e.g. ``ConvolutionBackward0``) may return bf16, its forward
    op made with ``modules`` entered from ``code`` (None: not known): the gradient of a cast out of bf16, or of an op
    made at a declared place."""
    if (node, op) == BF16_GRADIENT_CAST:
        return True
    return modules is not None and any(site.covers(modules, code) for site in BF16_ALLOWED)
