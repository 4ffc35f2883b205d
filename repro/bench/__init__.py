"""Layer 4: ``repro bench``: update, sampler and offline-data throughput, reported as ratios measured in one run."""
