"""Command-line interface (``fingerfit --help``). One module per command group."""

from . import (  # noqa: F401  (registers the commands)
    capture,
    convert,
    export,
    fit,
    joint,
    retarget,
    session,
    simulate,
    stream,
    study,
    stylus,
    view,
)
from .app import app, one_line_summaries, run

one_line_summaries()

main = run

__all__ = ["app", "main"]
