"""The public API: every name ``pincal`` lists in ``__all__`` imports from the package root.

Most are lazy (``pincal.__getattr__`` imports the defining module on first use), so a module
moved without its line in ``pincal._DEFINED_IN`` would fail only when a user first reached for
the name; this reaches for every one.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest
from sources import parsed

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


def _statically_bound() -> tuple[dict[str, str], dict[str, str]]:
    """The names ``pincal/__init__.py`` imports, by module: at module level, and under ``if TYPE_CHECKING:``."""
    tree = parsed(Path(pincal.__file__).read_text())
    eager: dict[str, str] = {}
    checking: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom):
            eager.update({alias.asname or alias.name: node.module for alias in node.names})
        elif isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for inner in ast.walk(node):
                if isinstance(inner, ast.ImportFrom):
                    checking.update({alias.asname or alias.name: inner.module for alias in inner.names})
    return eager, checking


def test_every_public_name_is_typed_for_type_checkers():
    """A lazy name a type checker cannot see reaches users as ``Any``: each one is imported under
    ``TYPE_CHECKING``, from the module ``__getattr__`` imports it from at run time."""
    eager, checking = _statically_bound()
    lazy = {name: module for module, names in pincal._DEFINED_IN.items() for name in names}
    assert set(pincal.__all__) - set(eager) - set(checking) == set()
    assert {name: checking.get(name) for name in lazy} == lazy
