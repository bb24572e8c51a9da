"""Former home of the file-level workflows, kept for scripts that import them from here: calibrate in
:mod:`pincal.workflows.calibration`, diagnose in :mod:`pincal.workflows.diagnosis`, simulate in
:mod:`pincal.workflows.simulation` (each also ``pincal.calibrate_files`` …). Importing this module warns."""

from __future__ import annotations

import warnings

from pincal.workflows.calibration import CalibrationRun, calibrate_chain_dh, calibrate_files, unfitted_sessions
from pincal.workflows.diagnosis import DiagnoseRun, diagnose_files
from pincal.workflows.simulation import simulate_to_directory
from pincal.workflows.verdict import RELOAD_TOLERANCE, write_checked_urdf

__all__ = [
    "RELOAD_TOLERANCE", "simulate_to_directory", "CalibrationRun", "calibrate_chain_dh", "calibrate_files",
    "unfitted_sessions", "write_checked_urdf", "DiagnoseRun", "diagnose_files",
]

warnings.warn("pincal.cli.workflows moved to pincal.workflows (or import from pincal)", DeprecationWarning,
              stacklevel=2)
