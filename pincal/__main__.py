"""``python -m pincal``: same as the ``pincal`` command."""

from pincal.cli.commands import console

console()
