"""Data from outside this project that the analysis reads at run time (provenance: README.md beside this file).

Files only, no code: the paper's own numbers and LaTeX source (:data:`PAPER_DIR`) and the DrQ-v2 authors'
published learning curves (:data:`PUBLISHED_DIR`). Package data (pyproject.toml), so that an installed
``repro`` finds them too.
"""

from __future__ import annotations

from pathlib import Path

DATA_DIR = Path(__file__).resolve().parent
PAPER_DIR = DATA_DIR / "paper"
PUBLISHED_DIR = DATA_DIR / "reference" / "drqv2_curves"
