"""agent.fast's CUDA-graph path (repro/agent/graphs.py): where the plan turns it on, and on the CPU that the update
a graph records reads everything that changes between updates (the batch, the schedule's stddev) from its static
inputs, so replaying it is the plain update: bit for bit here, eagerly. Recording and replaying need CUDA (the last
test, and benchmarks/gpu_check.sh's fast_check)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch

from repro.agent import fast
from repro.agent.agent import Agent
from repro.agent.graphs import GraphedUpdate
from repro.bench.batches import batch_stream, synthetic_episodes
from repro.config.compose import compose, typed
from repro.learners import build_learner

OBS = (9, 36, 36)
# a schedule that moves at every step of the test, so a stddev frozen at its recording would show
FAST_DECAY = ["agent.stddev_schedule.start=1.0", "agent.stddev_schedule.end=0.1",
              "agent.stddev_schedule.duration=8"]


def agent_of(flags: list[str], device: str = "cpu") -> Agent:
    rc = typed(compose(["agent=taco", "agent.hidden_dim=32", "agent.batch_size=4", *FAST_DECAY, *flags]))
    torch.manual_seed(0)
    learner = build_learner(rc.agent, OBS, 4, device)
    assert isinstance(learner, Agent)
    return learner


def stream_of(agent: Agent, device: str = "cpu") -> Iterator[dict[str, torch.Tensor]]:
    """Batches drawn as training draws them (repro/bench/batches.py): a replay of short synthetic episodes, sampled
    with the agent's sample_options; a new batch at each step, so a graph that kept its first one would show."""
    episodes = synthetic_episodes(n_episodes=2, length=20, action_dim=4, frame_shape=(3, *OBS[1:]))
    return batch_stream(agent, agent.cfg, OBS[0] // 3, episodes, device)


def test_the_plan_records_the_update_on_cuda_only_and_only_for_the_online_agent(monkeypatch):
    flags = {"avx512_bf16"}
    assert fast.resolve_fast(True, torch.device("cuda"), flags).graphs
    assert not fast.resolve_fast(True, torch.device("cpu"), flags).graphs
    assert not fast.resolve_fast(False, torch.device("cuda"), flags).graphs
    # a plan that asks for graphs (as on CUDA): the online agent keeps it and builds capturable Adam; an offline
    # learner on the same backbone drops it (its update branches on the step)
    monkeypatch.setattr(fast, "resolve_fast", lambda enabled, device, flags=None: fast.FastPlan(graphs=True))
    monkeypatch.setattr("repro.agent.agent.GraphedUpdate",
                        lambda body, device: GraphedUpdate(body, device, capture=False))
    online = agent_of(["agent.fast=true"])
    assert online.backbone.fast.graphs and isinstance(online.graph, GraphedUpdate)
    assert all(o.defaults["capturable"] for o in online.optimizers().values())
    rc = typed(compose(["agent=td3bc_taco", "offline.dataset=medium", "agent.hidden_dim=32", "agent.fast=true"]))
    offline = build_learner(rc.agent, OBS, 4, "cpu")
    assert not offline.backbone.fast.graphs  # type: ignore[attr-defined]
    assert not any(o.defaults["capturable"] for o in offline.optimizers().values())


@pytest.mark.parametrize("flags", [[], ["agent.fast=true"]], ids=["plain", "fast"])
def test_the_static_update_is_the_update_bit_for_bit(flags):
    """Each update on a new batch at a new step: a body that kept its first batch, or the stddev of its recording,
    or read the schedule instead of the static stddev, gives other numbers."""
    plain, static = agent_of(flags), agent_of(flags)
    graph = GraphedUpdate(static.static_update, "cpu", capture=False)
    got, want = [], []
    stream = stream_of(plain)
    for i in range(4):
        batch, step = next(stream), 2 * i + 1
        torch.manual_seed(100 + i)
        want.append({k: v.clone() for k, v in plain.update(batch, step).items()})
        torch.manual_seed(100 + i)
        got.append(graph(batch, static.cfg.stddev_schedule(step)))
    assert {plain.cfg.stddev_schedule(2 * i + 1) for i in range(4)} != {plain.cfg.stddev_schedule(1)}
    for w, g in zip(want, got):
        assert sorted(w) == sorted(g) and all(torch.equal(w[k], g[k]) for k in w), (w, g)
    for (name, p), q in zip(plain.backbone.critic.named_parameters(), static.backbone.critic.parameters()):
        assert torch.equal(p, q), name
    assert static.backbone._std is None  # the schedule is back for acting


def test_a_graphed_update_refuses_a_batch_of_another_layout():
    graph = GraphedUpdate(lambda batch, std: {"n": batch["x"].sum() * std}, "cpu", capture=False)
    assert float(graph({"x": torch.ones(3)}, 2.0)["n"]) == 6.0
    assert float(graph({"x": torch.full((3,), 2.0)}, 0.5)["n"]) == 3.0  # new values in the same buffers
    with pytest.raises(ValueError, match=r"one layout; \['x'\] changed"):
        graph({"x": torch.ones(4)}, 1.0)
    with pytest.raises(ValueError, match="CUDA device"):
        GraphedUpdate(lambda batch, std: {}, "cpu", capture=True)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a CUDA device")
def test_replayed_updates_track_the_eager_fast_updates_on_cuda():
    """On CUDA: 8 fast updates recorded after 3 warm-up ones against the same updates with the graph removed, from
    one seed and the same RNG draws: each loss within 1e-3 + 1e-3 |eager| (the same kernels; the bf16 rounding of
    autocast without its weight cache is the same)."""
    graphed, eager = agent_of(["agent.fast=true"], "cuda"), agent_of(["agent.fast=true"], "cuda")
    assert graphed.graph is not None and eager.graph is not None
    eager.graph.capture = False  # the same static body, never recorded
    rows: list[tuple[dict[str, float], dict[str, float]]] = []
    stream = stream_of(graphed, "cuda")
    for i in range(8):
        batch = next(stream)
        torch.manual_seed(100 + i)
        g = {k: float(v) for k, v in graphed.update(batch, 2 * i + 1).items()}
        torch.manual_seed(100 + i)
        e = {k: float(v) for k, v in eager.update(batch, 2 * i + 1).items()}
        rows.append((g, e))
    assert graphed.graph.replaying and graphed.graph.failed is None
    for g, e in rows:
        assert all(abs(g[k] - e[k]) <= 1e-3 + 1e-3 * abs(e[k]) for k in e), (g, e)
