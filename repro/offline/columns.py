"""Columns of an offline run's eval.csv and train.csv (docs/run-format.md, 'Offline runs').

Kept in one place so that the run-format module can take them over.
"""

from __future__ import annotations

OFFLINE_EVAL_COLUMNS = ["update", "episode_reward", "episode_reward_std", "episode_length", "success",
                        "eval_episodes", "normalized_score", "reference_return", "score_reference", "total_time"]
OFFLINE_TRAIN_COLUMNS = ["update", "updates_per_s", "total_time"]  # then the learner's metric names
OFFLINE_WALLCLOCK_COLUMNS = ("total_time", "updates_per_s")
