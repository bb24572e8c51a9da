"""``python -m pincal``: same as the ``pincal`` command."""

import sys

from pincal.cli.commands import main

sys.exit(main())
