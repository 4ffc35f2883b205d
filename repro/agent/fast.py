"""``agent.fast``: one switch that composes the speed-ups that help on the machine a run uses (docs/performance.md).

What it turns on is decided here, from the device and the CPU's instruction sets, and recorded in the run's
``resolved.json`` (``fast``), so a run says what it ran:

* ``amp``: bfloat16 autocast of the encoder's convolutions (everything after them stays float32: the backbone's
  module docstring says why; ``numerics.py`` declares the one list of what may run in bf16, and
  tests/test_numerics_contract.py holds every online agent to it), where the hardware computes bf16 natively: a
  CUDA device with bf16 (Ampere and later), or a CPU with AVX512-BF16 or AMX-BF16 (elsewhere bf16 is emulated and
  slower);
* ``u8_shift``: the random shift cropped on the uint8 frames (4x fewer bytes than on float32), exact: the same
  offsets give the same pixels;
* ``bf16_input``: with ``amp``, the cropped frames go to bf16 before the encoder's ``x / 255 - 0.5`` (autocast
  would round that result to bf16 before the first convolution anyway);
* ``channels_last``: the encoder's convolutions in NHWC, where the oneDNN / cuDNN kernels prefer it (with bf16);
* ``fused_adam``: one fused Adam kernel per optimizer step instead of a loop over parameters;
* ``compile``: ``torch.compile`` of the encoder (``agent.compile``'s path), on CUDA only. On an Intel Xeon with
  AMX-BF16 it made the fast update 4-13% faster, but costs ~15 s of compiling in every process (each start and
  resume) and was slower than eager with amp on the other CPUs measured (docs/performance.md, "agent.fast"); a run
  can still add ``agent.compile=true``;
* ``graphs``: the whole online update recorded once in a CUDA graph and replayed (``repro/agent/graphs.py``), on
  CUDA only, with capturable Adam. Possible because the update makes no host sync (issue 25). Only the online
  agent uses it (``BackboneLearner.graphed``): the offline learners on the backbone are not wired to it.

The plain path (``agent.fast=false``, the default) is untouched and stays bit-identical to the upstream record.
"""

from __future__ import annotations

import functools
import platform
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypeVar

import torch
from torch import nn

from repro.agent.aug import RandomShift

M = TypeVar("M", bound=nn.Module)
BF16_CPU_FLAGS = ("avx512_bf16", "amx_bf16")  # x86 flags of native bf16 arithmetic (/proc/cpuinfo)
BF16_ARM_FLAGS = ("bf16",)  # aarch64's (/proc/cpuinfo "Features")


@dataclass(frozen=True)
class FastPlan:
    """Which speed-ups a run uses (all off: the plain path)."""

    amp: bool = False
    u8_shift: bool = False
    bf16_input: bool = False
    channels_last: bool = False
    fused_adam: bool = False
    compile: bool = False
    graphs: bool = False

    def as_dict(self) -> dict[str, bool]:
        return asdict(self)


def cpu_flags(cpuinfo: str | None = None) -> set[str]:
    """The CPU's instruction-set flags (``/proc/cpuinfo``'s first ``flags`` / ``Features`` line); empty where
    there is no such file."""
    if cpuinfo is None:
        try:
            cpuinfo = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
        except OSError:
            return set()
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("flags", "Features"):
            return set(value.split())
    return set()


def native_bf16(device: torch.device, flags: set[str] | None = None) -> bool:
    """Whether ``device`` computes bfloat16 natively (see the module docstring)."""
    if device.type == "cuda":
        return bool(torch.cuda.is_available() and torch.cuda.is_bf16_supported())
    if device.type != "cpu":
        return False
    flags = cpu_flags() if flags is None else flags
    wanted = BF16_ARM_FLAGS if platform.machine() in ("aarch64", "arm64") else BF16_CPU_FLAGS
    return any(f in flags for f in wanted)


def resolve_fast(enabled: bool, device: torch.device, flags: set[str] | None = None) -> FastPlan:
    """The speed-ups ``agent.fast`` turns on for ``device`` (``enabled`` false: none)."""
    if not enabled:
        return FastPlan()
    bf16 = native_bf16(device, flags)
    cuda = device.type == "cuda"
    return FastPlan(amp=bf16, u8_shift=True, bf16_input=bf16, channels_last=bf16, fused_adam=True, compile=cuda,
                    graphs=cuda)


class ShiftU8:
    """DrQ-v2's random shift on uint8 frames: each image moved by its own integer offset in [-pad, pad] per axis,
    the border replicated, then converted to ``dtype`` (``channels_last``: NHWC memory, else contiguous NCHW).

    It draws the offsets as :class:`repro.agent.aug.RandomShift` does (one ``torch.randint`` of shape (n, 2)), and
    replicate padding is index clamping, so ``ShiftU8()(x)`` equals ``RandomShift()(x.float())`` bit for bit from
    the same RNG state, without a padded float copy of the batch."""

    def __init__(self, pad: int = 4, dtype: torch.dtype = torch.float32, channels_last: bool = False):
        self.pad, self.dtype, self.channels_last = pad, dtype, channels_last

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        n, _, h, w = x.shape
        offsets = torch.randint(0, 2 * self.pad + 1, (n, 2), device=x.device)
        rows = (offsets[:, 0:1] - self.pad + torch.arange(h, device=x.device)[None]).clamp_(0, h - 1)  # (n, h)
        cols = (offsets[:, 1:2] - self.pad + torch.arange(w, device=x.device)[None]).clamp_(0, w - 1)  # (n, w)
        batch = torch.arange(n, device=x.device)[:, None, None]
        out = x.permute(0, 2, 3, 1)[batch, rows[:, :, None], cols[:, None, :]]  # (n, h, w, c), still uint8
        out = out.to(self.dtype).permute(0, 3, 1, 2)  # NHWC memory viewed as NCHW
        return out if self.channels_last else out.contiguous()


def shift(plan: FastPlan, pad: int = 4) -> RandomShift | ShiftU8:
    """The random shift of ``plan``: :class:`ShiftU8` on the uint8 frames, or the plain path's float shift."""
    if not plan.u8_shift:
        return RandomShift(pad=pad)
    return ShiftU8(pad=pad, dtype=torch.bfloat16 if plan.bf16_input else torch.float32,
                   channels_last=plan.channels_last)


def prepare_encoder(encoder: M, plan: FastPlan) -> M:
    """``encoder`` with its convolution weights in NHWC memory when ``plan.channels_last`` (same values)."""
    if plan.channels_last:
        encoder.to(memory_format=torch.channels_last)  # type: ignore[call-overload]  # in place; torch's stubs lack it
    return encoder


def adam(plan: FastPlan) -> Callable[..., torch.optim.Optimizer]:
    """The Adam constructor of ``plan``: fused (one kernel per step) or the plain path's default; capturable (its
    step count on the device) when the update is recorded in a CUDA graph."""
    if not (plan.fused_adam or plan.graphs):
        return torch.optim.Adam
    return functools.partial(torch.optim.Adam, fused=plan.fused_adam, capturable=plan.graphs)


def resolved(plan: FastPlan, enabled: bool) -> dict[str, Any]:
    """What resolved.json records of the plan: ``{"fast": {...}}`` when ``agent.fast`` is on (a plain run's
    resolved.json is left as it was)."""
    return {"fast": plan.as_dict()} if enabled else {}
