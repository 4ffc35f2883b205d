"""Composed configs kept in the command's cache (analysis/cache.py, section ``compose``): F8 reads each task's
default K from its config, ``repro plan --claims`` composes the claims' sweeps for their cost; composing takes
about 0.2 s, so an unchanged config is composed once, not at every report."""

from __future__ import annotations

import copy
from collections.abc import Sequence
from typing import Any

from omegaconf import DictConfig, OmegaConf

from analysis import cache
from repro.config.compose import compose, config_digest


def _kept(overrides: Sequence[str]) -> DictConfig:
    """The composition of ``overrides`` as the cache keeps it (not to be changed)."""
    if cache.active():
        scratch = cache.current().scratch
        digest = scratch.get("config_digest") or scratch.setdefault("config_digest", config_digest())
    else:
        digest = config_digest()
    return cache.lookup("compose", (digest, tuple(overrides)), lambda: compose(list(overrides)))


def composed_value(overrides: Sequence[str], key: str) -> Any:
    """The value at ``key`` of :func:`composed` ``(overrides)``, read without copying the whole config (F8 reads one
    number of nine compositions)."""
    return OmegaConf.select(_kept(overrides), key)


def composed(overrides: Sequence[str]) -> DictConfig:
    """:func:`repro.config.compose.compose` of ``overrides`` (ConfigError as it raises), kept under the overrides
    and :func:`repro.config.compose.config_digest` (what composing reads: computed once per command); a fresh copy
    each call, so a caller may set values in it."""
    return copy.deepcopy(_kept(overrides))
