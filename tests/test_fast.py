"""agent.fast (repro/agent/fast.py): what it turns on per machine, the exact uint8 random shift, the agent with the
plan applied (recorded, close to plain over 100 updates, restored bit for bit from a checkpoint)."""

from __future__ import annotations

import copy
import platform

import pytest
import torch

from helpers import OBS, make_batch
from repro.agent import fast
from repro.agent.agent import Agent
from repro.agent.aug import RandomShift
from repro.agent.fast import FastPlan, ShiftU8, cpu_flags, native_bf16, resolve_fast
from repro.bench.agreement import compare
from repro.config.compose import compose, typed
from repro.runs import rundir, runformat

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


@pytest.fixture
def bf16_cpu(monkeypatch):
    """A CPU whose flags say native bf16, so the whole plan is on wherever the test runs (emulated bf16 elsewhere
    is slower, not different)."""
    monkeypatch.setattr(fast, "cpu_flags", lambda cpuinfo=None: {"avx512_bf16"})


def tiny_agent(flags: list[str]) -> Agent:
    rc = typed(compose(["agent.hidden_dim=32", *flags]))
    torch.manual_seed(0)
    return Agent(rc.agent, OBS, 4)


def test_the_agent_applies_the_plan_and_records_it(bf16_cpu):
    agent = tiny_agent(["agent.fast=true"])
    plan = agent.backbone.fast
    assert plan == FastPlan(amp=True, u8_shift=True, bf16_input=True, channels_last=True, fused_adam=True)
    aug = agent.backbone.aug
    assert isinstance(aug, ShiftU8) and aug.dtype == torch.bfloat16 and aug.channels_last
    conv = agent.backbone.encoder.convnet[0].weight
    assert conv.is_contiguous(memory_format=torch.channels_last) and not conv.is_contiguous()
    assert all(o.defaults["fused"] for o in agent.optimizers().values())
    values = rundir.resolved_values(typed(compose(["agent.fast=true"])), agent)
    assert runformat.check_resolved(values)["fast"] == plan.as_dict()
    plain = tiny_agent([])  # the plain path: nothing of the plan, and resolved.json as before agent.fast
    assert plain.backbone.fast == FastPlan() and isinstance(plain.backbone.aug, RandomShift)
    assert "fast" not in plain.resolved
    assert not any(o.defaults["fused"] for o in plain.optimizers().values())
    assert plain.backbone.encoder.convnet[0].weight.is_contiguous()


@pytest.fixture
def one_thread():
    """Tiny tensors: one thread (two spin and stall for seconds on a loaded 2-core machine)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


# Fast (bf16 forward passes and bf16 input, uint8 shift, channels_last, fused Adam) against plain, 100 updates on
# one batch stream with the same RNG draws (repro/bench/agreement.py), at B8 on 36-pixel frames (hidden 32): each
# loss's mean over the updates within 0.05 + 0.05 x |plain mean|. Measured on an Intel Xeon (AMX-BF16): the worst
# mean uses 0.05 of its allowance (the worst single update 0.6 of the same allowance); doubling the learning rate on
# the fast side uses 1.8 (actor_loss). docs/performance.md, "agent.fast against plain", has the real size.
def test_fast_losses_track_the_plain_ones_over_100_updates(bf16_cpu, one_thread):
    report = compare("fast", "cpu", batch=8, updates=100, rel=0.05, abs_=0.05, hidden=32, image=36)
    assert set(report["per_loss"]) >= {"critic_loss", "actor_loss", "aux_loss", "taco_loss", "curl_loss"}
    assert report["all_within_tolerance"], report["per_loss"]
    # not trivially equal: bf16 does change the numbers (the paths are not the same code)
    assert any(w["max_abs_diff"] > 0 for w in report["per_loss"].values())


def test_a_fast_agent_restored_from_its_checkpoint_continues_bit_for_bit(bf16_cpu):
    a = tiny_agent(["agent.fast=true"])
    for i in range(2):
        torch.manual_seed(10 + i)
        a.update(make_batch(B=4, seed=i), step=100 + 2 * i)
    state, rng = copy.deepcopy(a.state_dict()), torch.get_rng_state()
    b = tiny_agent(["agent.fast=true"])  # a fresh process's agent: other weights until the checkpoint loads
    b.load_state_dict(state)
    runs = []
    for agent in (a, b):
        torch.set_rng_state(rng)
        runs.append([{k: float(v) for k, v in agent.update(make_batch(B=4, seed=5 + i), step=104 + 2 * i).items()}
                     for i in range(2)])
    assert runs[0] == runs[1]
    for (name, p), q in zip(a.backbone.encoder.named_parameters(), b.backbone.encoder.parameters()):
        assert torch.equal(p, q), name
    assert b.backbone.encoder.convnet[0].weight.is_contiguous(memory_format=torch.channels_last)  # fast layout


def test_under_fast_only_the_encoder_runs_in_bf16_the_heads_and_losses_are_float32(bf16_cpu):
    """Issue 33's bug: with the actor and critic under bf16 autocast the critic's Q values were rounded to 0.125 at
    Q ~ 27 and the policy's tanh to exactly +-1 from |mu| ~ 3.5, so a saturated policy got an exactly zero gradient
    and the verification run never left 136 on cartpole_balance. Given the same features, the fast agent's critic
    loss equals the plain computation bit for bit, and a saturated actor still moves."""
    agent = tiny_agent(["agent.fast=true"])
    bb = agent.backbone
    assert bb.fast.amp
    batch = make_batch(B=8, seed=1)
    h, next_h, action, reward, discount = bb.encode_batch(batch)
    assert h.dtype == next_h.dtype == torch.float32  # the encoder's bf16 output, handed on in float32
    plain = tiny_agent([]).backbone  # the plain path (no autocast anywhere) with the fast agent's heads
    for name in ("actor", "critic", "critic_target"):
        getattr(plain, name).load_state_dict(getattr(bb, name).state_dict())
    torch.manual_seed(4)
    loss, (q1, _), _ = bb.critic_loss(h, action, reward, discount, next_h, step=10)
    torch.manual_seed(4)
    want, (want_q1, _), _ = plain.critic_loss(h, action, reward, discount, next_h, step=10)
    assert torch.equal(loss, want) and torch.equal(q1, want_q1)
    # a saturated policy: mu ~ 6 (tanh = 0.99999 in float32, exactly 1.0 in bf16, whose gradient would be 0)
    last = bb.actor.policy[-1]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.fill_(6.0)
    before = last.bias.detach().clone()
    bb.actor_step(h.detach(), step=10)
    assert not torch.equal(last.bias, before)  # Adam moved it: the gradient through tanh was not exactly 0
