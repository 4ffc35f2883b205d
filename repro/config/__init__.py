"""Layer 1: the run config. ``schema`` (typed sections), ``compose`` (Hydra compose and validation),
``paper_defaults`` (per-task and per-dataset values taken from the paper). Imports nothing else of ``repro``."""
