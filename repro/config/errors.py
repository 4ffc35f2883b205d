"""The one base of the errors a user can act on (bad input, a refused start, a file of the wrong format): every
such exception class of the project derives from :class:`UserError` beside its own built-in base, and the `repro`
app catches it once (:class:`repro.runs.console.Commands`): its message as one line on stderr, exit 2. Any other
exception is a bug and shows its traceback. Imports nothing, so every layer can derive from it."""

from __future__ import annotations


class UserError(Exception):
    """An error the user can act on; its message is one line that says what is wrong and, where it can, what to
    do."""
