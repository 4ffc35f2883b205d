"""Offline visual RL: datasets on disk (:mod:`repro.offline.dataset`), their import/export formats,
loading them into the replay, and what offline runs log."""
