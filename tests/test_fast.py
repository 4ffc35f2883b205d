"""agent.fast (repro/agent/fast.py): what it turns on per machine, and the exact uint8 random shift."""

from __future__ import annotations

import platform

import pytest
import torch

from repro.agent.aug import RandomShift
from repro.agent.fast import FastPlan, ShiftU8, cpu_flags, native_bf16, resolve_fast

EPYC = "processor\t: 0\nvendor_id\t: AuthenticAMD\nflags\t\t: fpu sse2 avx2 avx512f avx512_bf16\n"
OLD_XEON = "processor\t: 0\nflags\t\t: fpu sse2 avx2 avx512f\n"


@pytest.mark.parametrize("dtype, channels_last", [(torch.float32, False), (torch.bfloat16, True)])
def test_uint8_shift_equals_the_float_shift_bit_for_bit(dtype, channels_last):
    x = torch.randint(0, 256, (6, 9, 84, 84), dtype=torch.uint8)
    torch.manual_seed(3)
    want = RandomShift(pad=4)(x.float())
    after_plain = torch.get_rng_state()
    torch.manual_seed(3)
    got = ShiftU8(pad=4, dtype=dtype, channels_last=channels_last)(x)
    assert got.dtype == dtype and torch.equal(got, want.to(dtype))  # uint8 values are exact in bf16
    assert got.is_contiguous(memory_format=torch.channels_last if channels_last else torch.contiguous_format)
    assert torch.equal(torch.get_rng_state(), after_plain)  # the same draws: the training RNG stream is kept


def test_fast_turns_on_bf16_only_where_the_hardware_has_it():
    if platform.machine() not in ("x86_64", "AMD64"):
        pytest.skip("the flags below are x86's")
    cpu = torch.device("cpu")
    assert cpu_flags(EPYC) >= {"avx512_bf16", "avx2"} and cpu_flags("no flags here") == set()
    assert native_bf16(cpu, cpu_flags(EPYC)) and not native_bf16(cpu, cpu_flags(OLD_XEON))
    with_bf16, without = resolve_fast(True, cpu, cpu_flags(EPYC)), resolve_fast(True, cpu, cpu_flags(OLD_XEON))
    assert (with_bf16.amp, with_bf16.bf16_input, with_bf16.channels_last) == (True, True, True)
    assert (without.amp, without.bf16_input, without.channels_last) == (False, False, False)
    assert with_bf16.u8_shift and without.u8_shift and with_bf16.fused_adam and not with_bf16.compile
    assert resolve_fast(False, cpu, cpu_flags(EPYC)) == FastPlan()  # off: the plain path, nothing on
