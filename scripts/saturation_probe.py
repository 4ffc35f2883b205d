"""Where a run's actor stands on the states of its own replay, checkpoint by checkpoint (issue 49's dead seed).

For each checkpoint of an online run (the run's ``checkpoint.pt``, or copies kept after each episode), it builds the
run's learner from its ``config.yaml``, loads the checkpoint's modules and, on the frame-stacked observations of every
``--every``-th replay slot (the run's ``replay/`` episodes, as its replay buffer stacks them), reports:

- the share of states whose policy mean is exactly +-1 in float32 (the policy gradient through the tanh is exactly
  zero there) and the range of the pre-tanh output,
- the critic's slope dQ/da at the policy mean (min of the two heads, through the action encoder, as the actor's loss
  sees it): the share of states where it points back towards 0 from the mean's side ("inward"), over all states and
  over the saturated ones (where the critic says "move away from the bound" but the actor cannot),
- from the second checkpoint on, how many of the actor's and the encoder's weights changed since the previous one
  given, and by how much at most (an actor at the bound on every batch state gets an exactly zero gradient, so only
  Adam's decaying momentum and the encoder, trained by the critic's and auxiliary losses, can still move its output).

    OMP_NUM_THREADS=1 .venv/bin/python scripts/saturation_probe.py RUN_DIR [CHECKPOINT ...] [--every 10] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from repro.config.compose import typed
from repro.data.episodes import EpisodeStore
from repro.data.replay import ReplayBuffer
from repro.runs import rundir
from repro.runs.checkpoint import load_checkpoint
from repro.train.build import build_run_learner


def stacked_replay(run: Path, state: dict, rc, action_dim: int, every: int) -> tuple[torch.Tensor, int]:
    """(N, 3F, H, W) uint8 observations of every ``every``-th stored slot, stacked as the run's buffer stacks them,
    and the number of slots stored."""
    store = EpisodeStore(run / "replay")
    frames = store.load(store.ids()[0])["frames"]
    buffer = ReplayBuffer(rc.replay.capacity, tuple(frames.shape[1:]), action_dim, rc.env.frame_stack,
                          rc.agent.nstep, rc.agent.K, rc.agent.discount, seed=0)
    buffer.restore(state["buffer"], EpisodeStore(run / "replay").load)
    slots = np.arange(0, len(buffer), every)
    slots = slots[buffer.ep_id[slots] >= 0]
    return buffer._stack(slots), len(buffer)


def weights_moved(before: dict, after: dict) -> dict:
    """How many of a module's weights differ between two state dicts, of how many, and the largest |difference|."""
    changed = sum(int((before[k] != after[k]).sum()) for k in after)
    largest = max(float((before[k].double() - after[k].double()).abs().max()) for k in after)
    return {"changed": changed, "of": sum(int(after[k].numel()) for k in after), "max_diff": largest}


def probe(run: Path, checkpoint: Path, every: int, previous: dict | None = None) -> tuple[dict, dict]:
    """The row for ``checkpoint`` and its actor's and encoder's state dicts; ``previous``: those of the checkpoint
    probed before it."""
    rc = typed(rundir.saved_config(run))
    state = load_checkpoint(checkpoint)
    frame = int(state["counters"]["step"]) * int(rc.env.action_repeat)
    action_dim = int(state["agent"]["actor"]["policy.4.weight"].shape[0])
    obs, stored = stacked_replay(run, state, rc, action_dim, every)
    with torch.random.fork_rng(devices=[]):
        agent = build_run_learner(rc, (obs.shape[1], obs.shape[2], obs.shape[3]), action_dim, "cpu")
    agent.load_state_dict({"modules": state["agent"], "optimizers": state["optimizers"]})
    bb = agent.backbone  # type: ignore[attr-defined]
    with torch.no_grad():
        h = torch.cat([bb.encoder(chunk.float()) for chunk in obs.split(256)])
        dist = bb.actor(h, 0.1)
        pre, mean = dist.pre_tanh, dist.loc
    action = mean.detach().clone().requires_grad_(True)
    q1, q2 = bb.critic(h, bb.encode_action(action))
    torch.min(q1, q2).sum().backward()
    slope = action.grad
    at_bound = mean.abs() >= 1.0
    back = torch.sign(slope) == -torch.sign(mean)  # the critic's slope points back towards 0 from the mean's side
    inward = at_bound & back
    modules = {name: state["agent"][name] for name in ("actor", "encoder")}
    moved = {} if previous is None else {f"{name}_moved": weights_moved(previous[name], modules[name])
                                         for name in modules}
    return {"checkpoint": str(checkpoint), "frame": frame, "states": int(len(obs)), "stored": stored,
            "saturated": float(at_bound.float().mean()), "pretanh_min": float(pre.min()),
            "pretanh_max": float(pre.max()), "pretanh_mean": float(pre.mean()),
            "mean_action": float(mean.mean()), "inward_share": float(back.float().mean()),
            "inward_share_of_saturated":
                float(inward.float().sum() / at_bound.float().sum()) if bool(at_bound.any()) else float("nan"),
            **moved}, modules


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path)
    parser.add_argument("checkpoints", type=Path, nargs="*", help="default: the run's checkpoint.pt")
    parser.add_argument("--every", type=int, default=10, help="probe every N-th replay slot")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    checkpoints = args.checkpoints or [args.run / "checkpoint.pt"]
    rows = []
    print("frame   states  saturated  pre-tanh [min, max] (mean)  mean action  critic 'inward': all states, "
          "saturated ones; weights changed since the previous checkpoint: actor, encoder (max |diff|)")
    previous = None
    for ckpt in checkpoints:
        row, previous = probe(args.run, ckpt, args.every, previous)
        rows.append(row)
        moved = "".join(f"  {m['changed']}/{m['of']} ({m['max_diff']:.2g})"
                        for m in (row.get("actor_moved"), row.get("encoder_moved")) if m is not None)
        print(f"{row['frame']:>6} {row['states']:>7} {row['saturated']:10.3f}  [{row['pretanh_min']:6.2f}, "
              f"{row['pretanh_max']:6.2f}] ({row['pretanh_mean']:6.2f})  {row['mean_action']:11.3f}  "
              f"{row['inward_share']:.3f}, {row['inward_share_of_saturated']:.3f}{moved}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
