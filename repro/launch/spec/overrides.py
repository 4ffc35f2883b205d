"""Hydra override strings: their key and value, quoting, and merging lists where a later key wins."""

from __future__ import annotations

import re
from collections.abc import Iterable


def override_key(override: str) -> str:
    """The config key an override sets (``+a.b=1`` -> ``a.b``)."""
    return override.partition("=")[0].lstrip("+~")


def override_value(override: str) -> str:
    return override.partition("=")[2]


def hydra_quote(value: str) -> str:
    """A value as Hydra override syntax: bare when simple, else single-quoted."""
    if re.match(r"^[A-Za-z0-9_./\-]+$", value):
        return value
    return "'" + value.replace("\\", "\\\\").replace("'", "\\'") + "'"


def merge_overrides(*groups: Iterable[str]) -> tuple[str, ...]:
    """Concatenate override lists; a later override of the same key replaces an earlier one."""
    merged: dict[str, str] = {}
    for group in groups:
        for ov in group:
            key = override_key(ov)
            merged.pop(key, None)
            merged[key] = ov
    return tuple(merged.values())
