"""How far this project's TACO update and upstream's stay equal on the same batches, update after update.

Builds this project's TACO agent (plain path, ``agent.fast=false``) as a run builds it, copies its initial weights
into the re-expression of upstream's ``TACOAgent`` (tests/upstream_taco.py, which lists the upstream facts), and
feeds both the same batch stream (a replay of synthetic episodes, repro.bench.batches) with the same random draws:
``torch.manual_seed(seed + i)`` before update i on each side (the two policy-noise draws, taken in the same order by
both) and the same random shifts fed to both by role (the two codes draw their shifts in different orders and along
swapped axes from one RNG state; ``--draws native`` lets each draw its own from the seed instead). With ``--fast``
this project's fast path (agent.fast=true: on a CPU with native bf16 the encoder's convolutions in bf16, the uint8
shift, fused Adam) gets the same batches, seeds and shifts and is compared with the plain path.

Per update it reports the max |difference| of every parameter group (encoder, actor, critic, target critic, action
encoder, TACO heads: state projection, W, proj_sa, reward head), of the Adam moments, of the losses and of the
actor's pre-tanh output on a fixed probe batch (frames not shifted).

``--variant`` picks the upstream agent: ``faithful`` (upstream as it is) or one with diagnostic switches that
replace its rounding-level differences by this project's arithmetic (``matched``: all three; ``grid_only``,
``polyak_only``, ``order_only``: all but one), to tell which differences there are.

    OMP_NUM_THREADS=1 .venv/bin/python scripts/upstream_drift.py --updates 200 --task cartpole_balance --fast
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from upstream_taco import GROUPS, VARIANTS, run_drift  # noqa: E402

COLUMNS = (*GROUPS, "adam", "metrics", "pre_tanh")
SHORT = {"encoder": "enc", "actor": "actor", "critic": "critic", "critic_target": "target", "action_encoder": "act_enc",
         "taco_heads": "heads", "adam": "adam", "metrics": "losses", "pre_tanh": "pretanh"}


def shown(n: int, updates: int) -> bool:
    return n <= 3 or n == updates or n in (5, 10, 20, 50, 100, 150, 200, 300, 500, 1000)


def table(rows: list[dict], key: str) -> str:
    cols = [c for c in COLUMNS if c in rows[0][key]]
    lines = ["update " + " ".join(f"{SHORT[c]:>8}" for c in cols)]
    for row in rows:
        if shown(row["update"], len(rows)):
            lines.append(f"{row['update']:>6} " + " ".join(f"{row[key][c]:8.1e}" for c in cols))
    return "\n".join(lines)


def first_difference(rows: list[dict], key: str) -> int | None:
    """The first update after which some group, moment, loss or probe output differs (None: none did)."""
    return next((row["update"] for row in rows if any(v != 0.0 for v in row[key].values())), None)


def from_run(run: Path, checkpoint: Path | None) -> tuple[list, dict, str, int, int, int]:
    """(replay episodes stored at the checkpoint, its modules, task, image size, batch size, agent step) of a run."""
    from repro.config.compose import typed
    from repro.data.episodes import EpisodeStore
    from repro.runs import rundir
    from repro.runs.checkpoint import load_checkpoint

    rc = typed(rundir.saved_config(run))
    state = load_checkpoint(checkpoint or run / "checkpoint.pt")
    store = EpisodeStore(run / "replay")
    kept = sorted(int(rec[0]) for rec in state["buffer"]["episodes"] if int(rec[0]) >= 0)
    episodes = [store.load(i) for i in kept]
    image = int(episodes[0]["frames"].shape[-1])
    return episodes, state["agent"], rc.task.name, image, int(rc.agent.batch_size), int(state["counters"]["step"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--updates", type=int, default=200)
    ap.add_argument("--task", default="cartpole_balance", help="cartpole_balance: |A|=1, cheetah_run: |A|=6")
    ap.add_argument("--image", type=int, default=32, help="frames (9, image, image)")
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--hidden", type=int, default=None, help="agent.hidden_dim (default: the config's, 1024)")
    ap.add_argument("--variant", choices=sorted(VARIANTS), default="faithful")
    ap.add_argument("--draws", choices=("fed", "native"), default="fed")
    ap.add_argument("--fast", action="store_true", help="also run agent.fast=true and compare it with plain")
    ap.add_argument("--step", type=int, default=2000, help="agent step of the first update (std schedule)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--out", type=Path, default=None, help="write every row as JSON here")
    ap.add_argument("--override", action="append", default=[], help="another config override (repeatable)")
    ap.add_argument("--run", type=Path, default=None, help="start from this TACO run's checkpoint (--checkpoint, "
                    "default its checkpoint.pt) on its replay episodes (real frames, its task, batch and image)")
    ap.add_argument("--checkpoint", type=Path, default=None)
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)
    overrides = list(args.override) + ([f"agent.hidden_dim={args.hidden}"] if args.hidden else [])
    t0 = time.time()

    def progress(row: dict) -> None:
        if row["update"] % 25 == 0:
            print(f"  ... update {row['update']} ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)

    episodes, init = None, None
    if args.run is not None:
        episodes, init, args.task, args.image, args.batch, args.step = from_run(args.run, args.checkpoint)
    rows = run_drift(args.task, args.updates, args.image, args.batch, overrides, args.variant, args.fast,
                     args.draws, args.step, seed=args.seed, on_row=progress, episodes=episodes, init=init)
    print(f"task {args.task}, frames (9, {args.image}, {args.image}), batch {args.batch}, variant {args.variant}, "
          f"draws {args.draws}, {args.updates} updates in {time.time() - t0:.0f} s")
    print(f"\nthis project (plain) vs upstream ({args.variant}): max |difference| after each update")
    print(table(rows, "upstream"))
    first = first_difference(rows, "upstream")
    print(f"bit-identical for {'all ' + str(len(rows)) if first is None else first - 1} updates")
    if args.fast:
        print("\nthis project: fast path vs plain path: max |difference| after each update")
        print(table(rows, "fast"))
        first = first_difference(rows, "fast")
        print(f"bit-identical for {'all ' + str(len(rows)) if first is None else first - 1} updates")
    print("\nmean pre-tanh on the probe after each update: " + ", ".join(sorted(rows[0]["pre_tanh_mean"])))
    for row in rows:
        if shown(row["update"], len(rows)) or row["update"] % 25 == 0:
            print(f"{row['update']:>6} " + " ".join(f"{row['pre_tanh_mean'][k]:8.3f}"
                                                 for k in sorted(row["pre_tanh_mean"])))
    lo = min(r["pre_tanh_range"][0] for r in rows)
    hi = max(r["pre_tanh_range"][1] for r in rows)
    print(f"\nplain path's pre-tanh on the probe over the run: [{lo:.3g}, {hi:.3g}]")
    if args.out:
        args.out.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
