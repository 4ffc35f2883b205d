"""taco-repro: reproduce, extend and report TACO (Zheng et al., NeurIPS 2023)."""

__version__ = "0.1.0"
