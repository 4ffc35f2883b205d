"""Benchmark (not a test): seconds per TACO / DrQ-v2 update at batch 256 and 1024, and replay memory.

Usage: `python benchmarks/update_speed.py [--device cuda]` (same as `repro bench`). Compare the
printed seconds with the upstream figures in ../shared/docs/upstream.md (TACO B1024 ~30 s, DrQ-v2 B1024
~11.5 s, TACO B256 ~6.7 s on the 2-core CPU).
"""

from repro.bench import register  # noqa: F401  (the implementation lives in the package)
from repro_app.cli import app

if __name__ == "__main__":
    import sys

    app(["bench", *sys.argv[1:]])
