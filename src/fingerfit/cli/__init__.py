"""Command-line interface (``fingerfit --help``). One module per command group."""

from . import convert, export, fit, joint, retarget, session, simulate, stream, study, view  # noqa: F401  (registers the commands)
from .app import app, run

main = run

__all__ = ["app", "main"]
