"""Exceptions raised by pincal.

Every error a user can cause derives from :class:`PincalError`; the command line
prints its message on one line and exits non-zero, never with a traceback.
"""

from __future__ import annotations


class PincalError(Exception):
    """Root of all errors pincal raises on bad input or impossible requests."""


class MeasurementError(PincalError):
    """A measurement file cannot be used as given (file, row, column named in the message)."""


class ModelError(PincalError):
    """The URDF or the requested chain cannot be used (names the link or joint)."""


class CalibrationError(PincalError):
    """The data cannot determine what was asked for, or the fit failed."""
