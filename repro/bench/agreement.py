"""A speed-up path against the plain path: the losses of the same updates from the same weights and batches.

Two agents of one agent file are built from one seed; each gets the same stream of batches, drawn as training
draws them (repro/bench/batches.py:batch_stream: a replay of synthetic episodes sampled with the agent's
sample_options, from one seed), and the same RNG state before every update (the augmentation and target-noise
draws), so on the plain path twice the losses are equal bit for bit.
The differences of another path (bfloat16, another kernel order) grow update by update as its weights drift;
the report holds every update's losses on both paths and, per loss, the difference of their means over the
updates against a tolerance ``abs + rel x |plain mean|`` (and each update's largest difference, reported). Used by
benchmarks/amp_check.py (``--path fast``, gpu_check.sh) and tests/test_fast.py.
"""

from __future__ import annotations

import math
from typing import Any

from repro.bench.results import PATH_FLAGS

LOSSES = ("critic_loss", "actor_loss", "aux_loss", "taco_loss", "curl_loss", "reward_loss")


def losses(flags: list[str], device: str, batch: int, updates: int, hidden: int | None = None,
           agent: str = "taco", image: int = 84) -> list[dict[str, float]]:
    """The losses of ``updates`` updates of a fresh learner of agent file ``agent`` (``flags`` as overrides) on the
    batch stream (frames of ``image`` pixels square)."""
    import torch

    from repro.bench.batches import batch_stream, synthetic_episodes
    from repro.bench.online_update import compose_learner

    hidden_flag = [f"agent.hidden_dim={hidden}"] if hidden else []
    learner, rc = compose_learner(agent, batch, "cheetah_run", device, flags + hidden_flag, image)
    episodes = synthetic_episodes(action_dim=learner.action_dim, frame_shape=(3, image, image))
    stream = batch_stream(learner, rc.agent, rc.env.frame_stack, episodes, device, batch)
    out = []
    for i in range(updates):
        torch.manual_seed(1 + i)  # the same augmentation and noise draws on both paths
        metrics = learner.update(next(stream), step=10**6 + 2 * i)
        out.append({k: float(metrics[k]) for k in LOSSES if k in metrics})
    return out


def compare(path: str, device: str, batch: int, updates: int, rel: float, abs_: float, hidden: int | None = None,
            agent: str = "taco", image: int = 84) -> dict[str, Any]:
    """``path`` (a key of PATH_FLAGS) against plain over ``updates`` updates, per loss: the mean over the updates
    on both paths and its difference over the allowance ``abs_ + rel x |plain mean|`` (``mean_over_allowed``, <= 1:
    within), the largest single update's difference over its own allowance (``max_over_allowed``: reported, not
    judged, as one update of a small batch swings with a few flipped Adam signs) and finiteness."""
    plain = losses([], device, batch, updates, hidden, agent, image)
    other = losses(PATH_FLAGS[path], device, batch, updates, hidden, agent, image)
    worst: dict[str, dict[str, Any]] = {}
    for key in plain[0]:
        p = [row[key] for row in plain]
        o = [row[key] for row in other]
        mean_p, mean_o = sum(p) / len(p), sum(o) / len(o)
        over_mean = abs(mean_o - mean_p) / (abs_ + rel * abs(mean_p))
        worst[key] = {"mean_plain": mean_p, f"mean_{path}": mean_o, "mean_over_allowed": over_mean,
                      "max_abs_diff": max(abs(b - a) for a, b in zip(p, o)),
                      "max_over_allowed": max(abs(b - a) / (abs_ + rel * abs(a)) for a, b in zip(p, o)),
                      "finite": all(math.isfinite(v) for v in o), "within_tolerance": over_mean <= 1}
    return {"path": path, "agent": agent, "device": device, "batch_size": batch, "updates": updates,
            "hidden_dim": hidden, "image": image,
            "tolerance": {"rel": rel, "abs": abs_, "of": "the mean of each loss over the updates"},
            "plain": plain, path: other, "per_loss": worst,
            "all_within_tolerance": all(w["within_tolerance"] and w["finite"] for w in worst.values())}
