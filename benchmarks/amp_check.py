"""Plain against a speed-up path (`agent.amp` or `agent.fast`) on one device: the losses of the same updates from
the same weights and batches (repro/bench/agreement.py).

Two agents are built from one seed; each gets the same ``--updates`` synthetic batches (one seed per update) and
the same RNG draws, in the same order. The JSON (``--out``) holds every update's losses on both paths and, per
loss, the difference of their means over the updates against rel 0.05 / abs 0.02 of the plain mean (tests/
test_speedups.py's tolerance for one update), with each update's largest difference beside it. Used by
benchmarks/gpu_check.sh on CUDA; on CPU tests/test_speedups.py and tests/test_fast.py check the paths.

    python benchmarks/amp_check.py --device cuda --batch 256 --updates 5 --path fast --out fast_check.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REL, ABS = 0.05, 0.02  # tests/test_speedups.py:test_amp_matches_plain_path_approximately


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--path", default="amp", choices=("amp", "fast"))
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--updates", type=int, default=5)
    ap.add_argument("--hidden-dim", type=int, default=None, help="A smaller MLP (quick runs on CPU).")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    if args.batch < 1 or args.updates < 1:
        print("error: --batch and --updates must be >= 1", file=sys.stderr)
        return 2
    from repro.bench.agreement import compare

    report = compare(args.path, args.device, args.batch, args.updates, REL, ABS, args.hidden_dim)
    args.out.write_text(json.dumps(report, indent=2) + "\n")
    print(f"{args.path} vs plain over {args.updates} updates at B{args.batch} on {args.device}: each loss's mean "
          f"{'within' if report['all_within_tolerance'] else 'OUTSIDE'} rel {REL} / abs {ABS}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
