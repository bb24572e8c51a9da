"""Former home of evaluate's workflow, kept for scripts that import it from here: it lives in
:mod:`pincal.workflows.evaluation` (and ``pincal.evaluate_files`` …). Importing this module warns."""

from __future__ import annotations

import warnings

from pincal.workflows.evaluation import (
    HELD_DRIFT,
    MIN_THRESHOLD_DOF,
    REESTIMATED,
    REGISTRATION_PARAMETERS,
    THE_REGISTRATION,
    Evaluation,
    SessionEvaluation,
    evaluate_files,
)

__all__ = [
    "REESTIMATED", "REGISTRATION_PARAMETERS", "MIN_THRESHOLD_DOF", "THE_REGISTRATION", "HELD_DRIFT",
    "SessionEvaluation", "Evaluation", "evaluate_files",
]

warnings.warn("pincal.cli.evaluation moved to pincal.workflows.evaluation (or import from pincal)",
              DeprecationWarning, stacklevel=2)
