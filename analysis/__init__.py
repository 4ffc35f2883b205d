"""Analysis of TACO reproduction runs: loading, scores, statistics, tables, claims, audit and report.

The only inputs are run directories (``docs/run-format.md``) under a results root and the paper's own
numbers (``repro_data/paper``, a copy of ``shared/paper``; Tables 1 and 6 from ``repro/config/data``).
"""
