"""The command line: typer adapters that parse, call the library and print.

``app`` is the ``opticalstamp`` entry point; each module registers its commands on it.
"""

from . import design, fit, metrics, restore, scan, studies  # noqa: F401  (register their commands)
from .common import app, main

__all__ = ["app", "main"]
