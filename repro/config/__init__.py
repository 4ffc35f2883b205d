"""Layer 1: the run config. ``schema`` (typed sections, the allowed values as Enums, the learner and objective
names), ``compose`` (Hydra compose and validation), ``paper_defaults`` (the paper's tables that training reads,
packaged once under ``data/``). Imports nothing else of ``repro``."""
