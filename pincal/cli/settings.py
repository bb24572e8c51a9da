"""Former home of the settings values, kept for scripts that import them from here: they live in
:mod:`pincal.workflows.settings` (and ``pincal.CalibrateSettings`` …). Importing this module warns."""

from __future__ import annotations

import warnings

from pincal.workflows.settings import (
    CALIBRATE_LEVELS,
    DIAGNOSE_LEVELS,
    METHODS,
    CalibrateSettings,
    DiagnoseSettings,
    EvaluateSettings,
    default_selection,
    expect,
    no_prior,
)

__all__ = [
    "CALIBRATE_LEVELS", "DIAGNOSE_LEVELS", "METHODS", "expect", "no_prior", "default_selection", "CalibrateSettings",
    "DiagnoseSettings", "EvaluateSettings",
]

warnings.warn("pincal.cli.settings moved to pincal.workflows.settings (or import from pincal)", DeprecationWarning,
              stacklevel=2)
