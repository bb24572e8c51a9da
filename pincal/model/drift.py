"""A drift's time: which rows a sensor drift was fitted on, and the offset it gives other rows.

A drift describes the session it was fitted on: its offset is (t_k − t̄) u,
t̄ the mean time of the fitted rows (``time_reference_s``), and it holds only
inside the time span [first_S, last_S] of the session's fitted rows
(``time_spans_s``). It is never extrapolated: a row outside the span of the
session S whose registration it uses (another day) is held at that session's
mean time t̄_S, offset (t̄_S − t̄) u — zero for a one-session fit, where t̄_S = t̄:
no drift term (:func:`drift_offsets`).

The rows' time comes from a numeric extra column of the measurement file
(:data:`TIME_COLUMNS`, or the one ``--time-column`` names) [s].
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pincal.errors import PincalError
from pincal.measurements.data import MeasurementSet, reported_session

__all__ = [
    "TIME_COLUMNS", "time_column", "TimeSpan", "time_spans", "read_time_spans", "DriftOffsets", "own_spans",
    "held_times", "drift_offsets",
]

#: Extra columns taken as the row time [s], first found wins.
TIME_COLUMNS = ("time", "t", "timestamp", "t_start_robot")


def time_column(data: MeasurementSet, name: str | None = None) -> np.ndarray | None:
    """The rows' time [s] from ``name`` or the first of :data:`TIME_COLUMNS` present; None without one.

    Raises:
        PincalError: no column ``name`` (with the closest names; in some of several files: naming the files
            without it), or an empty / non-finite cell.
    """
    found = data.reading_column(name, TIME_COLUMNS, "time", "a drift or a pause step needs every row's time",
                                "--time-column")
    return None if found is None else found[1]


@dataclass(frozen=True)
class TimeSpan:
    """The times of one session's rows a drift was fitted on (REPORT.json ``time_spans_s``).

    Attributes:
        session: the calibrated session's name.
        first / last / mean: earliest, latest and mean row time [s], in the time column's units.
    """

    session: str
    first: float
    last: float
    mean: float

    def as_dict(self) -> dict[str, str | float]:
        return {"session": self.session, "first": self.first, "last": self.last, "mean": self.mean}


def time_spans(time: npt.ArrayLike, sessions: npt.ArrayLike) -> tuple[TimeSpan, ...]:
    """The span of the row times ``time`` (K,) [s] of each session (``sessions`` (K,)
    each row's name), in the order of their first row."""
    time, sessions = np.asarray(time, dtype=float), np.asarray(sessions, dtype=object)
    spans = []
    for name in dict.fromkeys(sessions.tolist()):
        own = time[sessions == name]
        first, last = float(np.min(own)), float(np.max(own))
        # the rounded mean of equal times can land an ulp outside them
        spans.append(TimeSpan(str(name), first, last, min(max(float(np.mean(own)), first), last)))
    return tuple(spans)


def read_time_spans(entries: Any, where: str, key: str = "time_spans_s") -> tuple[TimeSpan, ...] | None:
    """REPORT.json ``time_spans_s`` (a list of :meth:`TimeSpan.as_dict`) back; None if absent.

    Raises:
        PincalError: a malformed entry (``where`` names the report).
    """
    if entries is None:
        return None
    try:
        spans = tuple(TimeSpan(reported_session(e["session"], where, key), float(e["first"]), float(e["last"]),
                               float(e["mean"])) for e in entries)
    except (KeyError, TypeError, ValueError):
        spans = ()
    if not spans or not all(np.isfinite([s.first, s.last, s.mean]).all() and s.first <= s.mean <= s.last
                            for s in spans):
        raise PincalError(f"{where}: {key} must be a list of {{session, first, last, mean}} with "
                          "first <= mean <= last (finite seconds); rewrite it with pincal diagnose")
    return spans


@dataclass(frozen=True)
class DriftOffsets:
    """The drift offsets of evaluated rows and where the drift was not extrapolated.

    Attributes:
        offsets: the offset t u added to each row's registration translation [m], (K, 3).
        inside: whether each row lies in its session's fitted span (its offset (t_k − t̄) u), (K,).
        gap: how far each row lies from that span [s], 0 inside, (K,).
    """

    offsets: np.ndarray
    inside: np.ndarray
    gap: np.ndarray


def own_spans(
    time: np.ndarray, spans: Sequence[TimeSpan], held_session: Sequence[str | None] | np.ndarray,
    group: np.ndarray | None = None,
) -> np.ndarray:
    """Each row's span, an index in ``spans`` (K,): its session's (``held_session``); else one for all rows of its
    ``group`` (default each row alone), the nearest their median time: a session is never split between two."""
    first, last = (np.array([getattr(s, end) for s in spans]) for end in ("first", "last"))
    index = {s.session: i for i, s in enumerate(spans)}
    own = np.array([index.get(name, -1) if name is not None else -1 for name in held_session], dtype=np.intp)
    group = np.arange(len(own)) if group is None else np.asarray(group)
    for g in np.unique(group[own < 0]):
        members = np.flatnonzero((group == g) & (own < 0))
        centre = float(np.median(np.asarray(time, dtype=float)[members]))
        own[members] = int(np.argmin(np.maximum(np.maximum(first - centre, centre - last), 0.0)))
    return own


def held_times(
    time: np.ndarray, spans: Sequence[TimeSpan], held_session: Sequence[str | None] | np.ndarray,
    group: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The time [s] a drift is taken at for rows of times ``time`` (K,), and each
    row's distance from its span [s] (0 inside), (K,) each (:func:`drift_offsets`)."""
    time = np.asarray(time, dtype=float)
    first, last, mean = (np.array([getattr(s, key) for s in spans]) for key in ("first", "last", "mean"))
    own = own_spans(time, spans, held_session, group)
    gap = np.maximum(np.maximum(first[own] - time, time - last[own]), 0.0)
    reestimated = np.array([name is None for name in held_session], dtype=bool)
    return np.where(reestimated, np.clip(time, first[own], last[own]), np.where(gap == 0.0, time, mean[own])), gap


def drift_offsets(
    time: np.ndarray, velocity: np.ndarray, reference: float, spans: Sequence[TimeSpan] | None,
    held_session: Sequence[str | None] | np.ndarray, group: np.ndarray | None = None,
) -> DriftOffsets:
    """The drift's offsets at rows of times ``time`` (K,) [s], never extrapolated.

    S is the row's span (:func:`own_spans`: that of the session ``held_session[k]``
    names, whose registration the row uses, else one per ``group``). Inside S (first_S <= t <= last_S) the offset
    is (t − t̄) u as fitted, t̄ = ``reference``, u = ``velocity`` [m/s] (3,);
    outside it the drift is held at S's mean time, (t̄_S − t̄) u: the session's
    average state, where its registration is best determined (t is centred
    there, so registration and drift are uncorrelated); 0 for a one-session fit.
    A row named None (a registration re-estimated on the evaluated rows, which
    absorbs any constant offset) is held instead at the nearer end of S,
    (clip(t, first_S, last_S) − t̄) u, so that its session's rows stay
    continuous across the span's end. Without ``spans`` (a report older than
    ``time_spans_s``) no row is known to lie inside: every row gets offset 0.
    """
    time = np.asarray(time, dtype=float)
    velocity = np.asarray(velocity, dtype=float).reshape(3)
    if not spans:
        return DriftOffsets(offsets=np.zeros((time.size, 3)), inside=np.zeros(time.size, dtype=bool),
                            gap=np.full(time.size, np.inf))
    effective, gap = held_times(time, spans, held_session, group)
    return DriftOffsets(offsets=(effective - reference)[:, None] * velocity, inside=gap == 0.0, gap=gap)
