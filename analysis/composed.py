"""Composed configs kept in the command's cache (analysis/cache.py, section ``compose``): F8 reads each task's
default K from its config, ``repro plan --claims`` composes the claims' sweeps for their cost; composing takes
about 0.2 s, so an unchanged config is composed once, not at every report."""

from __future__ import annotations

import copy
from collections.abc import Sequence

from omegaconf import DictConfig

from analysis import cache
from repro.config.compose import compose, config_digest


def composed(overrides: Sequence[str]) -> DictConfig:
    """:func:`repro.config.compose.compose` of ``overrides`` (ConfigError as it raises), kept under the overrides
    and :func:`repro.config.compose.config_digest` (what composing reads: computed once per command); a fresh copy
    each call, so a caller may set values in it."""
    if cache.active():
        scratch = cache.current().scratch
        digest = scratch.get("config_digest") or scratch.setdefault("config_digest", config_digest())
    else:
        digest = config_digest()
    key = (digest, tuple(overrides))
    return copy.deepcopy(cache.lookup("compose", key, lambda: compose(list(overrides))))
