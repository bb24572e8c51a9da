"""Python sources read as syntax trees, parsed once and walked once per test process.

The structural checks (tests/test_architecture.py, test_outputs.py, test_flag_messages.py …) each read
every module of pincal: about 230 files and 316 000 nodes. Parsing them for each check and walking each
whole tree again for each question was most of those files' time (~1300 parses and ~4.8 million
``ast.walk`` steps in one run of the suite). Here a source text is parsed once, its tree walked once into
an index of its nodes by class, and a question reads only the nodes of the classes it asks about.

The trees are shared between the checks: callers only read them. Keys are the source text itself, so a
file rewritten during a test (a planted example in ``tmp_path``) is parsed afresh.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Iterable


@functools.cache
def parsed(text: str) -> ast.Module:
    """The syntax tree of the source ``text``."""
    return ast.parse(text)


@functools.cache
def _walked(text: str) -> tuple[tuple[ast.AST, ...], dict[type, tuple[int, ...]]]:
    """Every node of ``text``'s tree in :func:`ast.walk`'s order, and the positions in it of each node class."""
    order = tuple(ast.walk(parsed(text)))
    positions: dict[type, list[int]] = {}
    for position, node in enumerate(order):
        positions.setdefault(type(node), []).append(position)
    return order, {cls: tuple(found) for cls, found in positions.items()}


@functools.cache
def nodes(text: str, *classes: type) -> tuple[ast.AST, ...]:
    """The nodes of ``text``'s tree that are instances of ``classes`` (an abstract class such as ``ast.expr``
    counts its subclasses), in :func:`ast.walk`'s order: ``[n for n in ast.walk(tree) if isinstance(n, classes)]``."""
    order, positions = _walked(text)
    wanted: Iterable[int] = (p for cls, found in positions.items() if issubclass(cls, classes) for p in found)
    return tuple(order[p] for p in sorted(wanted))
