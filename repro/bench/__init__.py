"""Layer 4: ``repro bench``: update, sampler and offline-data throughput, reported as ratios measured in one run.

Its modules import torch (and the learners) when a benchmark runs, not when `repro` starts. The offline agent files
it times are those whose learner trains offline, plugins' included (``repro.config.compose.offline_agents``)."""

from repro.bench.results import PATH_FLAGS

# The speed-up paths `repro bench` times (update and e2e) and the config overrides that turn each on: one vocabulary,
# owned by repro/bench/results.py (which also says which path a run trains with)
SPEEDUP_FLAGS = PATH_FLAGS
