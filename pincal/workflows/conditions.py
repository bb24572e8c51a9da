"""``pincal evaluate``: a report's thermal expansion and pause steps on the evaluated rows, never extrapolated.

Thermal expansion (eq T1 of :mod:`pincal.model.thermal`): a row at temperature T inside the fitted
range [T_min, T_max] (REPORT.json ``temperature_range_c``) scales by 1 + α (T − T_ref); a row outside
it is held at the nearer end (:data:`HELD_THERMAL`). Pause steps (eq T2): a row takes the steps of the
pauses of its session before it (:data:`NEAREST_SEGMENT`). Each rule is noted once on stderr when it
held rows, and counted in ``--json`` (``thermal``, ``pause_steps``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np

from pincal.errors import PincalError
from pincal.measurements.data import MeasurementSet
from pincal.model.drift import own_spans, read_time_spans, time_column
from pincal.model.effects import Effect
from pincal.model.thermal import Pause, RowConditions, TemperatureRange, pause_rows, temperature_column
from pincal.report.model_diagnosis import PauseJson, TemperatureRangeJson
from pincal.report.model_evaluation import PauseStepUse, ThermalUse

__all__ = ["HELD_THERMAL", "NEAREST_SEGMENT", "AppliedConditions", "applied_conditions"]

#: How rows outside the fitted temperature range are evaluated (``thermal.held_rule`` in ``--json``).
HELD_THERMAL = ("thermal expansion not extrapolated: a row whose temperature lies outside the range of the rows it "
                "was fitted on is evaluated at the nearer end of that range")
#: Which pause steps a row takes (``pause_steps.rule`` in ``--json``).
NEAREST_SEGMENT = ("a row takes the steps of the pauses of its session before it (a row in a pause's gap: the segment "
                   "before the pause; a row outside the time span of its session's fitted rows: the nearest segment, "
                   "the first before it, the last after it); a row of a re-estimated registration or of a session "
                   "without pauses: the session whose span is nearest its evaluated session's median time")


@dataclass(frozen=True)
class AppliedConditions:
    """The report's thermal and pause-step changes of the evaluated rows, and how they were applied.

    Attributes:
        conditions: the rows' changes (eq T1–T2), or None.
        thermal / pause_steps: ``evaluate --json``'s entries, or None.
        notes: one line for each rule that held rows.
    """

    conditions: RowConditions | None = None
    thermal: ThermalUse | None = None
    pause_steps: PauseStepUse | None = None
    notes: tuple[str, ...] = ()


def applied_conditions(parsed: Sequence[tuple[Effect, np.ndarray]], effects: Mapping[str, Any], data: MeasurementSet,
                       held: tuple[np.ndarray, np.ndarray], temperature_name: str | None,
                       report_path: str | Path) -> AppliedConditions:
    """The :class:`AppliedConditions` of the report's effects ``parsed`` (its keys ``effects``) on ``data``;
    ``held`` = (each row's reported session name, or None for a re-estimated registration; each row's evaluated
    session) as for a drift; ``temperature_name``: ``--temperature-column`` (None: the report's).

    Raises:
        PincalError: a malformed report entry, data without the temperature or time column needed, or a
            ``temperature_name`` for a report without a thermal expansion (it would apply to nothing).
    """
    if temperature_name is not None and not any(effect.type == "thermal" for effect, _ in parsed):
        raise PincalError(f"--temperature-column applies to a report with a thermal expansion, and {report_path} has "
                          "none (pincal diagnose adopted no effect 'thermal'); drop it")
    notes: list[str] = []
    expansion = steps = thermal = pause_steps = None
    for effect, value in parsed:
        if effect.type == "thermal":
            expansion, thermal = _thermal(notes, float(value[0]), effects, data, temperature_name, report_path)
    stepping = [(effect, value) for effect, value in parsed if effect.type == "pause_step"]
    if stepping:
        steps, pause_steps = _steps(notes, stepping, effects, data, held, report_path)
    conditions = None if expansion is None and steps is None else RowConditions(expansion, steps)
    return AppliedConditions(conditions, thermal, pause_steps, tuple(notes))


def _thermal(notes: list[str], alpha: float, effects: Mapping[str, Any], data: MeasurementSet, name: str | None,
             report_path: str | Path) -> tuple[np.ndarray, ThermalUse]:
    """α (T_k − T_ref) of each row, held inside the fitted range, and its use; ``notes`` gains its note."""
    fitted = TemperatureRange.read(effects.get("temperature_range_c"), str(report_path))
    name = name or effects.get("temperature_column")
    if name is not None and not isinstance(name, str):
        raise PincalError(f"{report_path}: temperature_column must be a column name; rewrite it with pincal diagnose")
    found = temperature_column(data, name)
    if found is None:
        raise PincalError(f"{data.source}: the report has a thermal expansion; the rows need their temperature [°C] "
                          "(a column temperature_c, or name it with --temperature-column NAME)")
    change, outside = fitted.held(found[1])
    use: ThermalUse = {"alpha_per_k": alpha, "temperature_column": found[0],
                       "temperature_range_c": cast(TemperatureRangeJson, fitted.as_dict()),
                       "rows_applied": int(np.sum(~outside)), "rows_held": int(np.sum(outside)),
                       "held_rule": HELD_THERMAL}
    if outside.any():
        away = float(np.max(np.maximum(fitted.low - found[1], found[1] - fitted.high)))
        notes.append(f"{data.source}: the report's thermal expansion is not extrapolated: {int(outside.sum())} of "
                         f"{data.n_rows} row(s) lie outside the temperature range it was fitted on ({fitted.low:g}–"
                         f"{fitted.high:g} °C in column '{found[0]}'), up to {away:.3g} K away; they are evaluated "
                         "at the nearer end of that range")
    return alpha * change, use


def _steps(notes: list[str], stepping: Sequence[tuple[Effect, np.ndarray]], effects: Mapping[str, Any],
           data: MeasurementSet, held: tuple[np.ndarray, np.ndarray], report_path: str | Path
           ) -> tuple[np.ndarray, PauseStepUse]:
    """d_k of each row (K, 3) [m] (:data:`NEAREST_SEGMENT`) and its use; ``notes`` gains its note."""
    where = str(report_path)
    pauses = Pause.read(effects.get("pauses"), where)
    spans = read_time_spans(effects.get("pause_spans_s"), where, "pause_spans_s")
    if spans is None:
        raise PincalError(f"{where}: pause steps need pause_spans_s (the fitted rows' time span of each session with "
                          "a pause); rewrite the report with pincal diagnose")
    time = time_column(data, effects.get("time_column"))
    if time is None:
        raise PincalError(f"{data.source}: the report has pause steps; the rows need their time column "
                          f"'{effects.get('time_column') or 'time'}' [s]")
    first, last = np.array([s.first for s in spans]), np.array([s.last for s in spans])
    own = own_spans(time, spans, held[0], held[1])  # one span per evaluated session, as a drift's
    outside = (time < first[own]) | (time > last[own])
    applies = pause_rows(time, [spans[i].session for i in own], pauses)
    numbers = {p.number: p for p in pauses}
    steps, stepped = np.zeros((data.n_rows, 3)), np.zeros(data.n_rows, dtype=bool)
    for effect, value in stepping:
        if effect.pause not in numbers:
            raise PincalError(f"{where}: effect {effect.label} names no pause of 'pauses'; rewrite it with "
                              "pincal diagnose")
        after = applies[:, [p.number for p in pauses].index(effect.pause)]
        steps += after[:, None] * np.asarray(value).reshape(1, 3)
        stepped |= after > 0
    use: PauseStepUse = {"pauses": [cast(PauseJson, p.as_dict()) for p in pauses],
                         "rows_in_span": int(np.sum(~outside)), "rows_outside": int(np.sum(outside)),
                         "rule": NEAREST_SEGMENT, "rows_stepped": int(np.sum(stepped))}
    if outside.any():
        notes.append(f"{data.source}: {int(outside.sum())} of {data.n_rows} row(s) lie outside the time span of "
                         "the rows the report's pause steps were fitted on; they take the nearest segment's steps "
                     "(the first segment before the span, the last after it)")
    return steps, use
