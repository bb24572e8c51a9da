"""What the rows' temperature and time let ``diagnose`` test: the ``thermal`` and ``pause_step``
candidates (:mod:`pincal.model.thermal`), and a line for each that cannot be tested, with what to add.

``thermal`` is offered only with a temperature column whose value changes over the fitted rows
(without a change its basis, T_k − T_ref, is zero); a ``pause_step`` for every gap longer than
``pause_s`` between consecutive rows of a session, which needs a time column.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from pincal.errors import PincalError
from pincal.measurements.data import MeasurementSet
from pincal.model.drift import TIME_COLUMNS, TimeSpan, time_spans
from pincal.model.effects import Effect, EffectInputs
from pincal.model.thermal import (
    PAUSE_S,
    TEMPERATURE_COLUMNS,
    Pause,
    TemperatureRange,
    find_pauses,
    pause_rows,
    temperature_column,
)

__all__ = ["Readings", "read_readings", "ConditionSearch", "search_conditions"]


@dataclass(frozen=True)
class Readings:
    """The rows' temperatures and the pause rule, as ``diagnose`` is given them.

    Attributes:
        temperature / heldout_temperature: each calibration / held-out row's temperature [°C], or None.
        column: the temperature column's name (for messages and the report).
        pause_s: the gap between consecutive rows of a session that starts a new segment [s].
        partial: without a temperature: a default column (:data:`~pincal.model.thermal.TEMPERATURE_COLUMNS`)
            that some of several session files have, with the files without it (the join dropped it), or None.
        time_partial: the same for a default time column (:data:`~pincal.model.drift.TIME_COLUMNS`) when no
            time column is left, or None.
    """

    temperature: np.ndarray | None = None
    heldout_temperature: np.ndarray | None = None
    column: str | None = None
    pause_s: float = PAUSE_S
    partial: tuple[str, tuple[str, ...]] | None = None
    time_partial: tuple[str, tuple[str, ...]] | None = None


def read_readings(data: MeasurementSet, heldout: MeasurementSet | None, column: str | None,
                  pause_s: float = PAUSE_S) -> Readings:
    """The :class:`Readings` of calibration rows ``data`` and held-out rows ``heldout``: the temperature column
    ``column`` (None: the first of :data:`~pincal.model.thermal.TEMPERATURE_COLUMNS` in ``data``).

    Raises:
        PincalError: a column that is missing (did you mean; named, in some of several files only), not finite, or
            in the calibration rows only.
    """
    found = temperature_column(data, column)
    # a default column of some session files only, the join dropped it: said by search_conditions
    time_partial = None if any(n in data.extra for n in TIME_COLUMNS) else _partial(data, TIME_COLUMNS)
    if found is None:
        return Readings(pause_s=pause_s, partial=_partial(data, TEMPERATURE_COLUMNS), time_partial=time_partial)
    held = None
    if heldout is not None:
        if found[0] not in heldout.extra:
            raise PincalError(f"{heldout.source}: the held-out rows need the temperature column '{found[0]}' of "
                              "the calibration rows (thermal expansion is judged on both); add it")
        held = temperature_column(heldout, found[0])
    return Readings(found[1], None if held is None else held[1], found[0], pause_s, time_partial=time_partial)


def _lacking(effects: str, kind: str, name: str, lacking: Sequence[str]) -> str:
    """The note for a ``kind`` column ``name`` that the session files ``lacking`` lack (the join dropped it)."""
    return (f"{effects} cannot be tested: {', '.join(lacking)} lack(s) the {kind} column '{name}' of the other "
            "session file(s), and sessions are joined on the columns every file has: add it to "
            f"{'that file' if len(lacking) == 1 else 'those files'}")


def _partial(data: MeasurementSet, names: Sequence[str]) -> tuple[str, tuple[str, ...]] | None:
    """The first of ``names`` that some of ``data``'s session files lack, with those files; None if none."""
    return next(((n, tuple(data.dropped_extra[n])) for n in names if n in data.dropped_extra), None)


@dataclass(frozen=True)
class ConditionSearch:
    """The candidates the rows allow and what cannot be tested.

    Attributes:
        candidates: ``thermal`` and one ``pause_step`` per pause.
        notes: one line per candidate that cannot be tested, with what to add.
        temperature_range: of the fitted rows (T_ref its mean), or None without a temperature column.
        pauses: the pauses found (numbered from 1).
        pause_s / column: as :class:`Readings`; temperature: the fitted rows' [°C], or None.
        spans: the fitted rows' time span of each session with a pause.
    """

    candidates: tuple[Effect, ...]
    notes: tuple[str, ...]
    temperature_range: TemperatureRange | None
    pauses: tuple[Pause, ...]
    pause_s: float
    column: str | None
    temperature: np.ndarray | None = None
    spans: tuple[TimeSpan, ...] = ()

    def inputs(self, inputs: EffectInputs, temperature: np.ndarray | None, time: np.ndarray | None,
               sessions: Sequence[str]) -> EffectInputs:
        """``inputs`` with each row's T_k − T_ref [K] (held inside the fitted range) and a_kp of eq T2, for
        rows at ``temperature`` [°C] and ``time`` [s] of the sessions named ``sessions`` (K,)."""
        change = None
        if self.temperature_range is not None and temperature is not None:
            change = self.temperature_range.held(temperature)[0]
        steps = None if not self.pauses or time is None else pause_rows(time, sessions, self.pauses)
        return replace(inputs, temperature=change, pauses=steps)


def search_conditions(time: np.ndarray | None, sessions: Sequence[str], readings: Readings,
                      used: np.ndarray) -> ConditionSearch:
    """The :class:`ConditionSearch` of the fitted rows at ``time`` (K,) [s] (None: no time column) of the
    sessions named ``sessions`` (K,), their temperatures ``readings.temperature[used]``."""
    notes, candidates = [], []
    temperature_range: TemperatureRange | None = None
    pauses: tuple[Pause, ...] = ()
    temperature = None if readings.temperature is None else np.asarray(readings.temperature, dtype=float)[used]
    if temperature is None and readings.partial is not None:
        notes.append(_lacking("thermal", "temperature", *readings.partial))
    elif temperature is None:
        notes.append(f"thermal cannot be tested: the arm's lengths growing with temperature need each row's "
                     f"temperature [°C]: add a column {' or '.join(TEMPERATURE_COLUMNS)}, or name yours with "
                     "--temperature-column NAME")
    else:
        temperature_range = TemperatureRange.of(temperature)
        if temperature_range.high > temperature_range.low:
            candidates.append(Effect("thermal"))
        else:
            notes.append(f"thermal cannot be tested: the temperature does not change over the rows "
                         f"({temperature_range.low:g} °C in every row of column '{readings.column}')")
    if time is None and readings.time_partial is not None:
        notes.append(_lacking("drift and pause_step", "time", *readings.time_partial))
    elif time is None:
        notes.append(f"pause_step cannot be tested: a registration step across a pause needs each row's time [s]: "
                     f"add a column {', '.join(TIME_COLUMNS)}, or name yours with --time-column NAME")
    else:
        pauses = find_pauses(time, sessions, readings.pause_s)
        candidates += [Effect("pause_step", pause=p.number) for p in pauses]
        if not pauses:
            names = np.asarray(sessions, dtype=object)
            longest = max((float(np.max(np.diff(np.sort(time[names == n])), initial=0.0))
                           for n in dict.fromkeys(names.tolist())), default=0.0)
            notes.append(f"pause_step not tested: no gap longer than --pause-s {readings.pause_s:g} s between "
                         f"consecutive rows of a session (the longest: {longest:.3g} s)")
    spans = () if not pauses or time is None else tuple(
        s for s in time_spans(time, sessions) if s.session in {p.session for p in pauses})
    return ConditionSearch(tuple(candidates), tuple(notes), temperature_range, pauses, readings.pause_s,
                           readings.column, temperature, spans)
