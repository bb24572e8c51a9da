"""``python -m pincal``: same as the ``pincal`` command."""

import sys

from .cli import main

sys.exit(main())
