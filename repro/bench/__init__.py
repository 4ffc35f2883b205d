"""Layer 4: ``repro bench``: update, sampler and offline-data throughput, reported as ratios measured in one run.

Its modules import torch (and the learners) when a benchmark runs, not when `repro` starts."""

OFFLINE_AGENTS = ("bc", "td3bc", "td3bc_taco", "cql", "cql_taco", "iql", "dt")  # agent files (repro/conf/agent)
