"""Command-line interface (``fingerfit --help``). One module per command group."""

from . import convert  # noqa: F401, I001
from . import export, fit, simulate, study  # noqa: F401  (registers the commands)
from .app import app, run

main = run

__all__ = ["app", "main"]
