"""What every ``repro`` command prints: the one-line error and the rich console of its tables.

One source for all commands (repro/data, repro/train, repro/bench, repro/launch and repro_app import it;
the lowest of them is layer 3, so it lives here, below them).
"""

from __future__ import annotations

import shutil
import sys
from typing import TYPE_CHECKING, Any, NoReturn, Optional

import typer
from typer.core import TyperGroup

from repro.config.errors import UserError

if TYPE_CHECKING:
    from rich.console import Console

PIPED_WIDTH = 240  # columns of a console whose output is not a terminal (a log file): lines are not wrapped


def fail(message: str, code: int = 2) -> NoReturn:
    """Bad input or a failed step: print ``error: MESSAGE`` as one line on stderr and exit with ``code``
    (2 for bad input; ``error:`` is red on a terminal, plain text otherwise)."""
    typer.echo(f"{typer.style('error:', fg='red')} {message}", err=True)
    raise typer.Exit(code)


class Commands(TyperGroup):
    """The group of the `repro` app (``typer.Typer(cls=Commands)``; `repro dataset`'s too, which also runs alone):
    the one place a :class:`UserError` raised by any of its commands, sub-commands included, is caught and printed by
    :func:`fail` (one line, exit 2). A command catches an error itself only to add to its message or to choose
    another exit code."""

    def invoke(self, ctx: Any) -> Any:  # the context typer gives (its base class is private to typer)
        try:
            return super().invoke(ctx)
        except UserError as exc:
            fail(str(exc))


def console(stderr: bool = False, min_width: Optional[int] = None) -> Console:
    """A rich console on stdout (or stderr). With ``min_width``: at least that many columns (more when the
    terminal is wider), so a table is not truncated in narrow or piped output. Without: the terminal's width,
    or :data:`PIPED_WIDTH` columns without soft wrapping when the output is not a terminal."""
    from rich.console import Console

    if min_width is not None:
        return Console(stderr=stderr, width=max(min_width, shutil.get_terminal_size((min_width, 24)).columns))
    if (sys.stderr if stderr else sys.stdout).isatty():
        return Console(stderr=stderr)
    return Console(stderr=stderr, width=PIPED_WIDTH, soft_wrap=True)
