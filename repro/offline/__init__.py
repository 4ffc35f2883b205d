"""Offline visual RL: datasets, loading them into the replay, and what offline runs log."""
