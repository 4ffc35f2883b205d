"""Benchmark (not a test): offline dataset load time, memory and sampling batches/s against the online buffer.

Usage: `python benchmarks/offline_data.py [--transitions N] [--batch B] [--sample-batches I]`, the same as
`repro bench data ...` (docs/performance.md). Prints only ratios measured in this one run.
"""

import sys

from repro_app.cli import app

if __name__ == "__main__":
    app(["bench", "data", *sys.argv[1:]])
