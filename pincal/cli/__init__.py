"""The ``pincal`` command line: it parses the arguments, runs one workflow of
:mod:`pincal.workflows` and prints what it returns. The top layer: nothing in pincal imports it.
"""

from pincal.cli.commands import console, main

__all__ = ["console", "main"]
