"""Default statistics settings, kept apart from :mod:`analysis.stats` so that command lines can show them
without importing rliable (and its scipy/arch stack) on every start, `repro train` included."""

DEFAULT_REPS = 50_000  # rliable's default for get_interval_estimates
DEFAULT_SEED = 0  # random state of every bootstrap (and t-SNE)
