"""Offline visual RL: datasets on disk (:mod:`repro.offline.dataset`) and their import/export formats."""
