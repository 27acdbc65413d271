"""Command-line interface (``fingerfit --help``). One module per command group."""

from . import simulate  # noqa: F401  (registers the command)
from .app import app, run

main = run

__all__ = ["app", "main"]
