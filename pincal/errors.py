"""Exceptions raised by pincal.

Every error a user can cause derives from :class:`PincalError`; the command line
prints its message on one line and exits non-zero, never with a traceback.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = [
    "PincalError", "MeasurementError", "ModelError", "CalibrationError", "LISTED", "did_you_mean", "expect_value",
]


class PincalError(Exception):
    """Root of all errors pincal raises on bad input or impossible requests."""


class MeasurementError(PincalError):
    """A measurement file cannot be used as given (file, row, column named in the message)."""


class ModelError(PincalError):
    """The URDF or the requested chain cannot be used (names the link or joint)."""


class CalibrationError(PincalError):
    """The data cannot determine what was asked for, or the fit failed."""


#: Names a message lists at most before "… and N more".
LISTED = 12


def did_you_mean(name: str, choices: Iterable[str], what: str) -> str:
    """The end of a "no such name" message: the closest of ``choices`` (difflib's ratio ≥ 0.6) as
    "did you mean 'x'?", then ``what`` with at most :data:`LISTED` of them.

    Example: ``f"no link named 'tol0'; {did_you_mean('tol0', links, 'links')}"`` →
    ``"no link named 'tol0'; did you mean 'tool0'? links: base_link, …, tool0"``.
    """
    choices = list(choices)
    close = difflib.get_close_matches(name, choices, n=1)
    shown = ", ".join(choices[:LISTED]) + (f", … and {len(choices) - LISTED} more" if len(choices) > LISTED else "")
    guess = ("did you mean " + " or ".join(f"'{c}'" for c in close) + "? ") if close else ""
    return f"{guess}{what}: {shown or 'none'}"


def expect_value(value: object, kind: type, function: str) -> None:
    """Refuse, with a TypeError naming the class, a call of ``function`` whose options or settings
    argument ``value`` is not a ``kind`` (a script written for a former signature, which took each
    option as its own argument: a bool or a str there would fail later and obscurely)."""
    if not isinstance(value, kind):
        raise TypeError(f"{function}() takes a {kind.__module__}.{kind.__qualname__} where it got "
                        f"{type(value).__name__} (changed in this version: build the {kind.__qualname__} value)")
