"""REPORT.json ``sessions``: each session's registration and errors.

A calibration of several sessions (files, or values of a ``session`` column)
estimates one registration sensor_T_base per session with one model and one
target (:mod:`pincal.fit.sessions`). Each entry::

    {"name": "day2", "file": "day2.csv", "rows": 40,
     "registration": {"position": {...}, "orientation": {...}},
     "calibration_errors": {...eq 24 on the session's rows...}}

``registration`` has the keys of the report's top-level ``registration``
(``rotation_xyzw``, ``translation_m``: g ≈ Omega t + tau); one estimate serves
positions and orientations. A one-session report has one entry, equal to the
top-level ``registration``; with several, the top-level one is the first
session's.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import numpy as np

from pincal.fit.metrics import PoseErrors
from pincal.fit.sessions import session_rows
from pincal.measurements.data import MeasurementSet
from pincal.model.drift import time_spans
from pincal.model.sensor import Registration
from pincal.report.model import SessionEntry, TimeSpanJson, errors_json, registration_pair
from pincal.report.model_diagnosis import TimeSpansPart

__all__ = ["session_errors", "session_entries", "drift_spans"]


def session_errors(errors: PoseErrors, rows: np.ndarray) -> PoseErrors:
    """The errors of the rows ``rows`` (mask or indices) of ``errors``."""
    return PoseErrors(position_m=errors.position_m[rows],
                      rotation_rad=None if errors.rotation_rad is None else errors.rotation_rad[rows])


def session_entries(
    names: Sequence[str],
    registrations: Sequence[Registration],
    data: MeasurementSet,
    sessions: np.ndarray,
    errors: PoseErrors,
) -> list[SessionEntry]:
    """The ``sessions`` list of a report.

    Args:
        names / registrations: the sessions and their registrations, in fit order.
        data: the rows in the fit; ``sessions`` (K,) each one's index into ``names``.
        errors: eq 24 errors of those rows (in the same order).
    """
    entries: list[SessionEntry] = []
    for s, (name, registration) in enumerate(zip(names, registrations)):
        rows = np.flatnonzero(np.asarray(sessions) == s)
        files = list(dict.fromkeys(data.files[rows].tolist()))
        entries.append({
            "name": name,
            "file": files[0] if len(files) == 1 else files,
            "rows": int(rows.size),
            "registration": registration_pair(registration, registration),
            "calibration_errors": errors_json(session_errors(errors, rows)) if rows.size else None,
        })
    return entries


def drift_spans(diagnosis, time: np.ndarray | None, calibration, used: MeasurementSet) -> TimeSpansPart:
    """REPORT.json ``time_spans_s`` when ``diagnosis`` adopted a drift: the time span
    (first, last, mean [s]) of the rows it was fitted on, per calibrated session —
    where ``evaluate`` applies it (:func:`pincal.model.drift.drift_offsets`); {} without a drift.

    Args:
        diagnosis: :class:`pincal.diagnosis.diagnose.Diagnosis`.
        time: the time of every row of the data (K,) [s], or None.
        calibration: the geometric calibration (``used_index``, ``session_names``).
        used: the rows of the fit, ``data.select(calibration.used_index)``.
    """
    if time is None or not any(effect.type == "drift" for effect, _, _ in diagnosis.effects):
        return {}
    names = np.asarray(calibration.session_names, dtype=object)[session_rows(used, calibration.session_names)]
    spans = time_spans(np.asarray(time, dtype=float)[calibration.used_index], names)
    return {"time_spans_s": [cast(TimeSpanJson, span.as_dict()) for span in spans]}
