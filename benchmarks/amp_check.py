"""Plain against `agent.amp` on one device: the losses of the same updates from the same weights and batches.

Two agents are built from one seed; each gets the same ``--updates`` synthetic batches
(repro/bench/online_update.py:synthetic_batch, one seed per update) in the same order. The JSON (``--out``) holds
every update's losses on both paths and, per loss, the largest difference against the tolerance of
tests/test_speedups.py (rel 0.05, abs 0.02 for one update);
the differences grow update by update as the bfloat16 weights drift, so a later update may pass it less closely.
Used by benchmarks/gpu_check.sh on CUDA; on CPU tests/test_speedups.py checks one update.

    python benchmarks/amp_check.py --device cuda --batch 256 --updates 5 --out amp_check.json
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

REL, ABS = 0.05, 0.02  # tests/test_speedups.py:test_amp_matches_plain_path_approximately
LOSSES = ("critic_loss", "actor_loss", "aux_loss", "taco_loss", "curl_loss")


def losses(flags: list[str], device: str, batch: int, updates: int, hidden: int | None) -> list[dict[str, float]]:
    import torch

    from repro.agent.agent import Agent
    from repro.bench.online_update import synthetic_batch
    from repro.config.compose import compose, typed
    from repro.envs import get_task

    over = ["agent=taco", "task=cheetah_run", f"agent.batch_size={batch}", *flags]
    rc = typed(compose(over + ([f"agent.hidden_dim={hidden}"] if hidden else [])))
    A = get_task("cheetah_run").action_dim
    torch.manual_seed(0)
    agent = Agent(rc.agent, (9, 84, 84), A, device=device)
    out = []
    for i in range(updates):
        torch.manual_seed(1 + i)  # the same augmentation and noise draws on both paths
        metrics = agent.update(synthetic_batch(batch, rc.agent.K, A, device), step=10**6 + 2 * i)
        out.append({k: float(metrics[k]) for k in LOSSES if k in metrics})
    return out


def compare(device: str, batch: int, updates: int, hidden: int | None = None) -> dict:
    plain = losses([], device, batch, updates, hidden)
    amp = losses(["agent.amp=true"], device, batch, updates, hidden)
    worst: dict[str, dict[str, float | bool]] = {}
    for key in plain[0]:
        diffs = [abs(a[key] - p[key]) for p, a in zip(plain, amp)]
        allowed = [ABS + REL * abs(p[key]) for p in plain]
        worst[key] = {"max_abs_diff": max(diffs), "within_tolerance": all(d <= t for d, t in zip(diffs, allowed)),
                      "finite": all(math.isfinite(a[key]) for a in amp)}
    return {"device": device, "batch_size": batch, "updates": updates, "hidden_dim": hidden,
            "tolerance": {"rel": REL, "abs": ABS}, "plain": plain, "amp": amp, "per_loss": worst,
            "all_within_tolerance": all(bool(w["within_tolerance"]) for w in worst.values())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--updates", type=int, default=5)
    ap.add_argument("--hidden-dim", type=int, default=None, help="A smaller MLP (quick runs on CPU).")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    if args.batch < 1 or args.updates < 1:
        print("error: --batch and --updates must be >= 1", file=sys.stderr)
        return 2
    report = compare(args.device, args.batch, args.updates, args.hidden_dim)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"amp vs plain over {args.updates} updates at B{args.batch} on {args.device}: "
          f"{'within' if report['all_within_tolerance'] else 'OUTSIDE'} rel {REL} / abs {ABS}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
