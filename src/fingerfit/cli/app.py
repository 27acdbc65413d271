"""The typer application and its error handling.

Every command module registers on :data:`app`. A :class:`FingerfitError`
(bad input) is printed as one red line and exits with status 2 -- never a
traceback. Where a command turns an unexpected exception (not fingerfit's) into one
line too (``study``: a session's, a source's or a worker's), the global ``--debug``
(:func:`debugging`) raises it instead, with its traceback.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, TypeVar

import typer
from rich.console import Console
from rich.markup import escape

from ..errors import FingerfitError

if TYPE_CHECKING:
    from rich.progress import Progress

app = typer.Typer(
    name="fingerfit",
    help="Individual skeletal finger models (joint centres and tilted axes) from 6-DOF motion capture.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
# No emoji codes and no highlighting: user text (paths, names) is shown verbatim; markup
# in our own templates only, with every user value passed through ``escape``.
console = Console(stderr=True, emoji=False, highlight=False)
out = Console(emoji=False, highlight=False)

F = TypeVar("F", bound=Callable)

_debug = False  # the global --debug of this invocation (set by the app's callback)


def debugging() -> bool:
    """Whether this invocation has the global ``--debug``: an unexpected exception (not
    a :class:`FingerfitError`) is raised with its traceback rather than shown as one
    line, and an interrupt shows where it happened."""
    return _debug


#: The ``--quiet`` option of every command that shows a progress bar.
Quiet = Annotated[
    bool,
    typer.Option(
        "--quiet",
        "-q",
        help="No progress bar (there is none either when stderr is not a terminal).",
    ),
]


#: The ``--quiet`` of a command whose result is a table (``fit``, ``joint``).
QuietTable = Annotated[
    bool,
    typer.Option(
        "--quiet",
        "-q",
        help="No progress bar and no table: only the line naming the file written, notes "
        "and warnings.",
    ),
]


def progress(quiet: bool = False) -> Progress:
    """The progress bar of every command: on stderr, transient, off when quiet or piped.

    Use as ``with progress(quiet) as bar: task = bar.add_task("reading", total=n)`` and
    ``bar.update(task, advance=1, description=...)``. Notes and warnings printed through
    :data:`console` meanwhile appear above the bar.
    """
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
    )

    return Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
        disable=quiet or not console.is_terminal,
    )


def fail(message: str) -> typer.Exit:
    """Print one error line and return the exit to raise."""
    console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    return typer.Exit(code=2)


def notice(kind: str, message: str) -> None:
    """Print a yellow ``note:`` or ``warning:`` line (message shown literally) to stderr."""
    console.print(f"[yellow]{kind}:[/] {escape(message)}", highlight=False, soft_wrap=True)


def user_errors(func: F) -> F:
    """Turn :class:`FingerfitError` into a one-line message and exit status 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except FingerfitError as exc:
            raise fail(str(exc)) from None
        except KeyboardInterrupt:
            if _debug:
                raise
            raise fail("interrupted") from None

    return wrapper  # type: ignore[return-value]


def parse_list(value: str | None, allowed: tuple[str, ...], what: str) -> list[str] | None:
    """Comma-separated names checked against ``allowed``."""
    if value is None:
        return None
    items = [v.strip() for v in value.split(",") if v.strip()]
    bad = [v for v in items if v not in allowed]
    if bad or not items:
        raise FingerfitError(
            f"{what} must be comma-separated names from {', '.join(allowed)}", field=what
        )
    return items


def say(template: str, *values: object) -> None:
    """Print a line to stdout: ``template`` may hold markup; ``values`` are shown verbatim.

    ``say("model written to [bold]{}[/]", path)``.
    """
    out.print(template.format(*(escape(str(v)) for v in values)), soft_wrap=True)


def _version(value: bool) -> None:
    if value:
        from .. import __version__

        out.print(f"fingerfit {__version__}")
        raise typer.Exit()


def one_line_summaries() -> None:
    """Give each registered command its line in ``fingerfit --help``: the first paragraph
    of its docstring as one line of text, which the help wraps to the terminal (the
    docstring's own line breaks, which Rich's help keeps, would break it mid-sentence)."""
    for info in app.registered_commands:
        doc = info.callback.__doc__ if info.callback is not None else None
        if info.short_help is None and doc:
            info.short_help = " ".join(doc.strip().split("\n\n")[0].split())


def run() -> None:
    """Entry point of the console script."""
    try:
        app()
    except FingerfitError as exc:  # raised outside a wrapped command
        console.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
        sys.exit(2)


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
    debug: bool = typer.Option(
        False,
        "--debug",
        help="Show the traceback of an unexpected error (a bug, not bad input) instead of "
        "one line; give it before the command: fingerfit --debug study ...",
    ),
) -> None:
    """Individual skeletal finger models (joint centres and tilted axes) from 6-DOF motion capture."""
    global _debug
    _debug = debug
