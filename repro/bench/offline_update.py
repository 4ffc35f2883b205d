"""Time one update of each offline learner against the online DrQ-v2 update, side by side in one run.

Every learner is built through the learner registry (``repro.learners.registry``) from its packaged agent
file, on the same device, and fed a batch drawn the way its training loop draws one: single transitions
from a ReplayBuffer (``learner.sample_options``), or windows from the learner's own sampler for a sequence
learner (Decision Transformer, ``make_sampler``), at that learner's own batch size. The same synthetic
episodes feed every learner; each gets the same untimed warm-up updates and the same number of timed
updates (median reported). Only ratios to the DrQ-v2 update measured in this run are printed.
"""

from __future__ import annotations

import statistics
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import torch

from repro.agent.protocol import SequenceLearner
from repro.bench.batches import FRAME_SHAPE, synthetic_episodes, training_batch
from repro.bench.clock import timed
from repro.bench.progress import Steps
from repro.bench.results import machine_load
from repro.config.compose import ConfigError, compose, config_groups, offline_agents, typed
from repro.envs import get_task
from repro.learners.registry import LEARNERS, build_learner

REFERENCE = "drqv2"  # the online update every ratio is taken against
DATASET_KIND = "medium"  # offline.dataset of the timed offline learners (not read: the batches are synthetic)
STEP = 10**6  # update step passed to learners (past every schedule's warm-up, as repro.bench.cli does online)


def available(agent: str) -> str | None:
    """None when ``agent`` can be built here, else why not (one line)."""
    if agent not in config_groups()["agent"]:
        return f"no agent file repro/conf/agent/{agent}.yaml"
    try:
        learner = str(compose([f"agent={agent}"]).agent.learner)
    except ConfigError as exc:  # the config refuses an agent file whose learner is not registered
        return str(exc).strip().splitlines()[0]
    if learner not in LEARNERS:
        return f"learner '{learner}' is not registered in repro/learners/registry.py"
    return None


def time_learner(agent: str, batch_size: int, task: str, episodes: Sequence[Mapping[str, np.ndarray]],
                 repeats: int, warmup: int, device: str, own_batch: int | None = None) -> dict[str, Any]:
    """Median seconds of one update of ``agent`` (built from its agent file through the registry) at
    ``batch_size``, or, for a learner with its own batch size (DT), at that one (``own_batch`` replaces it)."""
    overrides = [f"agent={agent}", f"task={task}", f"agent.batch_size={batch_size}"]
    if agent in offline_agents():  # a dataset kind resolves what depends on it (CQL's Table 6 alpha)
        overrides.append(f"offline.dataset={DATASET_KIND}")
    rc = typed(compose(overrides))
    action_dim = get_task(task).action_dim
    frame_stack = rc.env.frame_stack
    obs_shape = (FRAME_SHAPE[0] * frame_stack, *FRAME_SHAPE[1:])
    torch.manual_seed(0)
    learner = build_learner(rc.agent, obs_shape, action_dim, device=device)
    # a sequence learner samples its own windows at its own batch size (DT: agent.dt.batch_size whatever
    # agent.batch_size says); ``own_batch`` replaces that one
    own = isinstance(learner, SequenceLearner)
    batch, size = training_batch(learner, rc.agent, frame_stack, episodes, device,
                                 own_batch if own and own_batch is not None else None)
    learner.train(True)
    for _ in range(warmup):
        learner.update(batch, STEP)
    times = [timed(lambda: learner.update(batch, STEP), device)[1] for _ in range(repeats)]
    return {"agent": agent, "learner": rc.agent.learner, "batch_size": size, "own_batch": own,
            "update_seconds": statistics.median(times), "repeats": repeats, "warmup": warmup}


def run_offline_bench(batch_size: int, repeats: int, warmup: int, device: str, agents: Sequence[str] | None = None,
                      task: str = "cheetah_run", echo: Callable[[str], None] = print,
                      own_batch: int | None = None, steps: Steps | None = None) -> dict[str, Any]:
    """Time DrQ-v2 and each available offline learner, each entry with the machine's load then; print each one's
    ratio to DrQ-v2 measured here. ``own_batch`` replaces the batch size of learners that have their own (DT's 64);
    ``steps``: the progress bar to advance."""
    episodes = synthetic_episodes(action_dim=get_task(task).action_dim)
    steps = steps or Steps(0, enabled=False)
    with steps.item(f"{REFERENCE} B{batch_size} (online reference)"):
        ref = {**time_learner(REFERENCE, batch_size, task, episodes, repeats, warmup, device), **machine_load()}
    echo(f"{REFERENCE} (online) batch {ref['batch_size']}: {ref['update_seconds']:.4f} s/update "
         f"({warmup} warm-up + {repeats} timed updates, median, {device})")
    rows, ratios, skipped = [ref], {}, {}
    for agent in offline_agents() if agents is None else agents:
        why = available(agent)
        if why:
            skipped[agent] = why
            echo(f"{agent}: skipped ({why})")
            with steps.item(f"{agent} (skipped)"):
                pass
            continue
        with steps.item(f"{agent} B{batch_size}"):
            row = {**time_learner(agent, batch_size, task, episodes, repeats, warmup, device, own_batch),
                   **machine_load()}
        row["over_drqv2"] = row["update_seconds"] / ref["update_seconds"]
        rows.append(row)
        ratios[f"{agent}_b{row['batch_size']}_over_{REFERENCE}_b{ref['batch_size']}"] = round(row["over_drqv2"], 3)
        own = " (its own batch size)" if row["own_batch"] else ""
        echo(f"{agent} B{row['batch_size']}{own} / {REFERENCE} B{ref['batch_size']} update time: "
             f"{row['over_drqv2']:.2f}x (measured in this run)")
    return {"task": task, "device": device, "results": rows, "ratios": ratios, "skipped": skipped}
