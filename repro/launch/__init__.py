"""Sweeps of the paper's experiments: declaration (sweeps/*.yaml), local and SLURM launchers, status."""
