"""The public API: every name ``pincal`` lists in ``__all__`` imports from the package root.

Most are lazy (``pincal.__getattr__`` imports the defining module on first use), so a module
moved without its line in ``pincal._DEFINED_IN`` would fail only when a user first reached for
the name; this reaches for every one.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

import pincal


@pytest.mark.parametrize("name", pincal.__all__)
def test_every_public_name_imports_from_the_root(name):
    namespace: dict[str, object] = {}
    exec(f"from pincal import {name}", namespace)  # the statement users write
    assert namespace[name] is getattr(pincal, name)


def test_every_lazy_name_is_public_and_defined_where_listed():
    lazy = {name for names in pincal._DEFINED_IN.values() for name in names}
    assert lazy <= set(pincal.__all__)
    assert set(pincal.__all__) - lazy <= {"__version__", "CalibrationError", "MeasurementError", "ModelError",
                                          "PincalError"}


def test_star_import_in_a_fresh_interpreter():
    """``from pincal import *`` resolves every lazy name (a fresh process: no module imported yet)."""
    code = "from pincal import *; import pincal; print(len([n for n in pincal.__all__ if n in globals()]))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert int(out) == len(pincal.__all__)
