"""Pure loss functions (and the Decision Transformer model) of the offline learners, one file per algorithm.

Optimizer steps, target updates and the order of updates belong to the learners (``repro/learners``).
"""
