"""Benchmark (not a test): seconds per TACO / DrQ-v2 update at batch 256 and 1024, and replay memory.

Usage: `python benchmarks/update_speed.py [--device cuda] [--warmup N] [--repeats N]` (same as
`repro bench update`). It prints only ratios between measurements of this one run; to compare with the
upstream TACO code, time both side by side on your machine as docs/performance.md describes.
"""

from repro.bench.cli import register  # noqa: F401  (the implementation lives in the package)
from repro_app.cli import app

if __name__ == "__main__":
    import sys

    app(["bench", "update", *sys.argv[1:]])
