"""Layer 4: ``repro bench``: update, sampler and offline-data throughput, reported as ratios measured in one run.

Its modules import torch (and the learners) when a benchmark runs, not when `repro` starts. The offline agent files
it times are those whose learner trains offline, plugins' included (``repro.config.compose.offline_agents``)."""
