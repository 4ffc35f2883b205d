"""The one exception of sweep handling."""

from __future__ import annotations

from repro.config.errors import UserError


class SweepError(UserError, ValueError):
    """A user-facing problem with a sweep, explained in one line (the CLI exits 2)."""
