"""Layer 2: the run-directory contract, defined once and used by the writer, ``repro status`` and the analysis:
file names and columns (``runformat``), the directory itself (``rundir``), the CSV and TensorBoard logs,
evaluation videos, checkpoints and atomic file writes."""
