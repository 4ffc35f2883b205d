"""The numerics contract of agent.amp / agent.fast (issue 49): only what repro/agent/numerics.py declares
(``BF16_ALLOWED``: the encoder's convolutions and what legitimately goes with them) may produce a bfloat16 tensor.

For every registered online agent (the registry's agent files: a plugin's too), one update at a tiny size under
``agent.amp`` and under ``agent.fast`` (with native bf16 forced, so the whole plan is on wherever the test runs),
watched op by op: global forward hooks keep the stack of modules running, a TorchFunctionMode marks each autograd node
with the module and the function that made it, and a TorchDispatchMode sees every aten op, forward and backward, and
records each one that returned bf16 outside the declared list, by module, function and op. The test fails naming
them. Widening autocast over the critic, or A-LIX's mixing layer as it was (its grid in bf16), is caught and named.

A-LIX's mixing layer (repro/agent/alix.py) at strength 0 is the identity under autocast, to float32 rounding: the
same float32 computation as without autocast.
"""

from __future__ import annotations

import inspect
import sys
from collections import Counter
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from types import CodeType, FrameType
from typing import Any

import pytest
import torch
from torch import nn
from torch.nn.modules.module import register_module_forward_hook, register_module_forward_pre_hook
from torch.overrides import TorchFunctionMode
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_leaves

from repro.agent import alix, fast, numerics
from repro.agent.backbone import DrQV2Backbone
from repro.agent.networks import Critic
from repro.bench.online_update import compose_learner, replay_batch
from repro.config.compose import online_agents

TORCH = f"{Path(torch.__file__).parent}/"  # torch's own frames: not where an op was called from
ROOT = Path(__file__).resolve().parents[1]
SITE = "numerics_site"  # the key of an autograd node's metadata that says where its forward op ran
IMAGE, BATCH = 36, 4
TINY = ["profile=tiny", "agent.hidden_dim=32", "agent.feature_dim=16"]
MODES = {"amp": ["agent.amp=true"], "fast": ["agent.fast=true", "agent.amp=true"]}
# Known failures outside this test's files, each with its reason: strict, so a fix makes the mark fail until removed.
BROKEN: dict[tuple[str, str], str] = {}


@dataclass(frozen=True)
class Site:
    """Where an op ran: the modules entered (outermost first) and the innermost function outside torch."""

    modules: tuple[nn.Module, ...]
    code: CodeType | None
    line: int


class Watch:
    """The running modules (global forward hooks) and the names of a learner's modules, for attributing ops."""

    def __init__(self, learner: Any) -> None:
        self.stack: list[nn.Module] = []
        self.names: dict[int, str] = {}
        for key, module in learner.modules().items():
            for name, sub in module.named_modules(prefix=key):
                self.names.setdefault(id(sub), name)

    @contextmanager
    def hooks(self) -> Iterator[None]:
        pre = register_module_forward_pre_hook(self._enter)
        post = register_module_forward_hook(self._leave, always_call=True)
        try:
            yield
        finally:
            pre.remove()
            post.remove()

    def _enter(self, module: nn.Module, args: Any) -> None:
        self.stack.append(module)

    def _leave(self, module: nn.Module, args: Any, out: Any) -> None:  # None: the output is left as it is
        self.stack.pop()

    def site(self) -> Site:
        frame: FrameType | None = sys._getframe(1)
        while frame is not None and frame.f_code.co_filename.startswith((TORCH, __file__)):  # to the caller
            frame = frame.f_back
        return Site(tuple(self.stack), frame.f_code if frame else None, frame.f_lineno if frame else 0)

    def describe(self, site: Site) -> str:
        """``critic.q1.0 (Linear) in Critic.forward (repro/agent/networks.py:103)``."""
        where = "no module"
        if site.modules:
            module = site.modules[-1]
            where = f"{self.names.get(id(module), '?')} ({type(module).__qualname__})"
        if site.code is not None:
            path = Path(site.code.co_filename)
            shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
            where += f" in {site.code.co_qualname} ({shown}:{site.line})"
        return where


class MarkNodes(TorchFunctionMode):
    """Marks the autograd node of every tensor a torch function returns with the :class:`Site` it ran at."""

    def __init__(self, watch: Watch) -> None:
        super().__init__()
        self.watch = watch

    def __torch_function__(self, func: Any, types: Any, args: Any = (), kwargs: Any = None) -> Any:
        out = func(*args, **(kwargs or {}))
        site = None
        for t in tree_leaves(out):
            if isinstance(t, torch.Tensor) and t.grad_fn is not None and SITE not in t.grad_fn.metadata:
                site = site or self.watch.site()
                t.grad_fn.metadata[SITE] = site
        return out


def _computes(func: Any) -> bool:
    """False for a view (its result aliases an input without writing it: the op that made that input is checked)."""
    return not any(r.alias_info is not None and not r.alias_info.is_write for r in func._schema.returns)


class Bf16Ops(TorchDispatchMode):
    """Every aten op that returns a bf16 tensor: in ``outside`` (as 'forward|backward where: aten::op', counted)
    when numerics.BF16_ALLOWED does not cover it; ``convolutions`` counts the bf16 convolutions (autocast was on)."""

    def __init__(self, watch: Watch) -> None:
        super().__init__()
        self.watch = watch
        self.outside: Counter[str] = Counter()
        self.convolutions = 0

    def __torch_dispatch__(self, func: Any, types: Any, args: Any = (), kwargs: Any = None) -> Any:
        out = func(*args, **(kwargs or {}))
        if _computes(func) and any(isinstance(t, torch.Tensor) and t.dtype == torch.bfloat16
                                   for t in tree_leaves(out)):
            self.check(func._schema.name.removeprefix("aten::"), func._schema.name)
        return out

    def check(self, op: str, name: str) -> None:
        node = torch._C._current_autograd_node()
        if node is None:  # the forward pass
            site = self.watch.site()
            self.convolutions += op == "convolution"
            if not numerics.allowed_forward(op, site.modules, site.code):
                self.outside[f"forward  {self.watch.describe(site)}: {name}"] += 1
            return
        made: Site | None = node.metadata.get(SITE)
        if not numerics.allowed_backward(node.name(), op, made.modules if made else None, made.code if made else None):
            where = self.watch.describe(made) if made is not None else "an op of unknown place"
            self.outside[f"backward of {where} [{node.name()}]: {name}"] += 1


def one_watched_update(agent_name: str, flags: list[str]) -> Bf16Ops:
    """One update of online agent ``agent_name`` at the tiny size with ``flags``, on a batch drawn as training draws
    it, every op watched."""
    learner, rc = compose_learner(agent_name, BATCH, "cheetah_run", "cpu", [*TINY, *flags], image=IMAGE)
    batch = replay_batch(learner, rc, BATCH, "cpu", image=IMAGE)
    watch = Watch(learner)
    ops = Bf16Ops(watch)
    torch.manual_seed(0)
    with ExitStack() as stack:
        stack.enter_context(watch.hooks())
        stack.enter_context(MarkNodes(watch))
        stack.enter_context(ops)
        learner.update(batch, step=10**6)
    return ops


def report(ops: Bf16Ops) -> str:
    return "bf16 outside repro/agent/numerics.py's BF16_ALLOWED:\n" + "\n".join(
        f"  {what} x{n}" for what, n in sorted(ops.outside.items()))


@pytest.fixture(autouse=True)
def tiny_and_bf16(monkeypatch):
    """One thread (tiny tensors), and a CPU whose flags say native bf16, so agent.fast's whole plan (bf16 input,
    channels_last) is on wherever the test runs (emulated bf16 is slower, not different)."""
    monkeypatch.setattr(fast, "cpu_flags", lambda cpuinfo=None: {"avx512_bf16"})
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _cases() -> list[Any]:
    cases = []
    for agent_name in online_agents():  # the registry's online agent files, built-in and plugins'
        for mode in MODES:
            reason = BROKEN.get((agent_name, mode))
            marks = [pytest.mark.xfail(strict=True, raises=RuntimeError, reason=reason)] if reason else []
            cases.append(pytest.param(agent_name, mode, marks=marks, id=f"{agent_name}-{mode}"))
    return cases


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("agent_name, mode", _cases())
def test_only_the_declared_ops_run_in_bf16(agent_name: str, mode: str):
    ops = one_watched_update(agent_name, MODES[mode])
    assert ops.convolutions > 0, "no bf16 convolution: autocast was off, the check would be vacuous"
    assert not ops.outside, report(ops)


@pytest.mark.filterwarnings("ignore::UserWarning")
@pytest.mark.parametrize("agent_name, extra", [("spr", ["agent.objective_params.spr.momentum=0.9"]), ("atc", [])])
def test_a_momentum_target_encoder_runs_as_the_online_one(agent_name: str, extra: list[str]):
    """A momentum target encoder (ATC's; SPR's with momentum > 0) gets agent.fast's bf16 frames: it encodes them under
    the online encoder's autocast (AuxBatch.encode_by), as the online one does (before: a RuntimeError, a float32
    convolution refusing bf16 input)."""
    ops = one_watched_update(agent_name, MODES["fast"] + extra)
    assert ops.convolutions > 0 and not ops.outside, report(ops)


def test_the_registry_is_enumerated():
    assert {"taco", "drqv2", "alix", "spr", "atc", "driml", "curl"} <= set(online_agents())


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_autocast_widened_over_the_critic_is_caught_and_named(monkeypatch):
    """Issue 33's bug again: the critic's loss (trunk, Q heads) under the encoder's autocast."""
    critic_loss = DrQV2Backbone.critic_loss

    def under_autocast(self: DrQV2Backbone, *args: Any, **kwargs: Any) -> Any:
        with self.autocast():
            return critic_loss(self, *args, **kwargs)

    monkeypatch.setattr(DrQV2Backbone, "critic_loss", under_autocast)
    ops = one_watched_update("drqv2", MODES["amp"])
    message = report(ops)
    assert ops.outside, "widened autocast not caught"
    assert "forward  critic.q1.0 (Linear) in Critic.forward (repro/agent/networks.py:" in message, message
    lines, first = inspect.getsourcelines(Critic.forward)  # the line that calls the Q heads, wherever it moves
    q_line = first + next(i for i, ln in enumerate(lines) if "self.q1(" in ln)
    assert f"critic.q1.0 (Linear) in Critic.forward (repro/agent/networks.py:{q_line}): aten::addmm" in message, message
    assert "backward of critic.q1.0 (Linear) in Critic.forward" in message, message  # its gradient too
    assert "forward  critic_target.q1.0 (Linear)" in message, message
    assert "forward  actor.trunk.2 (Tanh) in Actor.forward" in message, message  # the target's policy sample


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_alix_mixing_as_it_was_is_caught_and_named(monkeypatch):
    """A-LIX's mixing layer before issue 49: its draw, shift and grid in the dtype of its bf16 input."""
    monkeypatch.setattr(alix, "local_signal_mixing",
                        lambda x, strength, max_shift, fixed_batch=True: alix._mix(x, strength, max_shift, fixed_batch))
    ops = one_watched_update("alix", MODES["amp"])
    message = report(ops)
    assert "forward  encoder (ALIXEncoder) in _mix" in message and "aten::rand" in message, message
    assert "aten::arange" in message, message


# ------------------------------------------------------------------ A-LIX's mixing layer at strength 0


def _alix_at_strength_0(mode: str) -> Any:
    learner, _ = compose_learner("alix", BATCH, "cheetah_run", "cpu", [*TINY, *MODES[mode]], image=IMAGE)
    with torch.no_grad():
        learner.backbone.encoder.strength.zero_()
    return learner


@pytest.mark.parametrize("mode", list(MODES))
def test_alix_mixing_at_strength_0_is_the_identity_under_autocast(mode: str, monkeypatch):
    """Each mixing layer of the agent's encoder, inside its forward pass under the agent's autocast, returns its bf16
    input to float32 rounding: bit for bit what the same layer computes in float32 without autocast (the plain
    path's computation). With the grid in bf16 it moved features by up to 0.2."""
    bb = _alix_at_strength_0(mode).backbone
    calls: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []
    mix = alix.local_signal_mixing

    def recorded(x: torch.Tensor, strength: torch.Tensor, max_shift: float, fixed_batch: bool = True) -> torch.Tensor:
        state = torch.get_rng_state()
        out = mix(x, strength, max_shift, fixed_batch)
        torch.set_rng_state(state)
        with torch.autocast("cpu", enabled=False):  # the plain path's computation of the same values
            want = mix(x.float(), strength, max_shift, fixed_batch)
        calls.append((x, out, want))
        return out

    monkeypatch.setattr(alix, "local_signal_mixing", recorded)
    bb.encode(bb.aug(torch.randint(0, 256, (BATCH, 9, IMAGE, IMAGE), dtype=torch.uint8)))
    assert len(calls) == 4 and all(x.dtype == torch.bfloat16 for x, _, _ in calls)  # after each bf16 ReLU
    for i, (x, out, want) in enumerate(calls):
        x = x.detach().float()
        assert out.dtype == torch.float32 and torch.equal(out, want), \
            f"layer {i}: {float((out - want).detach().abs().max())} from the float32 computation"
        # the grid's own float32 rounding: interpolation weights of ~1e-6 on the neighbours (2.9e-6 of the largest
        # feature measured at 84 pixels; 0.14 with the grid in bf16)
        torch.testing.assert_close(out.detach(), x, rtol=0, atol=2**-16 * float(x.abs().max()))


@pytest.mark.parametrize("mode", list(MODES))
def test_alix_encoder_at_strength_0_equals_the_encoder_without_mixing(mode: str):
    """The whole encoder: training mode (mixing at S = 0) against eval mode (no mixing), both under the agent's
    autocast. The layers' float32 rounding (1e-6) moves a few later convolution outputs across a bf16 rounding
    boundary, so they agree to a few bf16 roundings: measured 0.3% to 0.5% of the largest feature (36 and 84 pixels,
    5 seeds); with the grid in bf16, 13% to 28%."""
    bb = _alix_at_strength_0(mode).backbone
    obs = bb.aug(torch.randint(0, 256, (BATCH, 9, IMAGE, IMAGE), dtype=torch.uint8))
    with torch.no_grad():
        mixed = bb.encode(obs)
        bb.encoder.train(False)
        plain = bb.encode(obs)
    assert mixed.dtype == plain.dtype == torch.float32
    worst, largest = float((mixed - plain).abs().max()), float(plain.abs().max())
    assert worst <= 2**-5 * largest, f"{worst} apart, the largest feature {largest}"
