"""The ``pincal`` command line and the file-level workflows behind it (read, fit,
write, check). The top layer: nothing in pincal imports it.
"""

from pincal.cli.commands import console, main

__all__ = ["console", "main"]
