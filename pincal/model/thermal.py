"""Temperature and pauses: changes of the measured points that no joint reading carries.

**Thermal expansion** (``thermal``, one coefficient α [1/K] for the arm). With T_k the row's
temperature [°C] and T_ref the mean temperature of the fitted rows, every length of the chain —
the joint placements' translations and the tool (target points) — grows by
f_k = 1 + α (T_k − T_ref). For a serial chain the base-frame position of a measured point is

    y = t_1 + R_1 (t_2 + R_2 (… (t_n + R_n m)))  =  t_1 + R_1 t_2 + R_1 R_2 t_3 + … + R_1 … R_n m,

a sum of terms each one product of rotations times one translation (t_i of placement i, m of the
tool); scaling every translation by f_k scales every term, so

    y_k(T_k) = f_k y_k,      orientations unchanged                                   (T1)

— the measured point scales about the base origin: the origin of the URDF's root link, in whose
frame y is written. Every fixed placement from the root to the first calibrated joint (a pedestal, a
torso, a mobile base's height) is one of the t_i and grows too: the root is taken as the point the
robot stands on, the one that does not move with temperature. α is bounded physically
(:data:`ALPHA_RANGE`): steel 11–13, aluminium ~23 µm/m/K, so 5–30 µm/m/K.
The calibrated geometry holds at T_ref; a row outside the fitted temperature range
[T_min, T_max] is held at its nearer end (never extrapolated, :meth:`TemperatureRange.held`).

**A step per pause** (``pause_step``, one per pause, 3 values). The rows of a session in time
order; a gap between consecutive rows longer than ``pause_s`` (default :data:`PAUSE_S`) starts a
new segment. The registration's translation of the rows after pause p changes by d_p [m] in the
sensor frame; the steps of several pauses add:

    g_k = Ω f_k y_k + τ + d_k + drift_k,    d_k = Σ_p a_kp d_p,
    a_kp = 1 if row k lies after pause p of its session, else 0                  (T2)

Translation only: the registration changes across a pause because the cell's temperature
moved the sensor against the base — the floor and the stand between them expand by α L ΔT
(12e-6/K × 3 m × 1 K = 36 µm), a translation along them; a tilt takes a differential
expansion, second order. Were the whole 76 µm step of a real 8.4 h pause a tilt ρ of the tracker 3 m away,
ρ = 25 µrad, a translation would leave ρ × 0.5 m = 13 µm across the workspace — one noise σ of a
tracker — while a rotation's 3 more values cost 3 ln(m) ≈ 22 in ΔBIC (m ≈ 1 500 residuals), enough
to hand the pause to a 3-value drift (below); a step large enough for its tilt to matter is a
sensor that was moved: a new session (its own registration). A row belongs to the segment whose
time span, extended to the next pause, holds it: a row in a pause's gap takes the segment before
it, a row before the first fitted row the first segment, one after the last the last segment (the
nearest; never a made-up value).

**Drift and steps.** Both are candidates. Across a long pause a drift u and a step fit alike (the
rows sit in two clusters of time); they differ only by the drift's slope within the segments.
Where the data cannot tell them apart (the ambiguity check of :mod:`pincal.diagnosis.verdicts`),
the step is named: a drift across a pause assumes the sensor moved linearly through hours without
rows, a step assumes nothing of the gap; with the step in the model, a drift is then tested on the
motion within the segments.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pincal.errors import PincalError
from pincal.measurements.data import MeasurementSet, reported_session
from pincal.model.effects import Effect, EffectInputs

__all__ = [
    "TEMPERATURE_COLUMNS", "PAUSE_S", "ALPHA_RANGE", "temperature_column", "TemperatureRange", "Pause",
    "find_pauses", "pause_rows", "RowConditions", "row_conditions", "implausible", "shown",
]

#: Extra columns taken as the row temperature [°C], first found wins.
TEMPERATURE_COLUMNS = ("temperature_c", "temperature")
#: Default gap between consecutive rows of a session that starts a new segment [s]: half an hour.
#: The rows of one measuring program are seconds to minutes apart (the TIAGo sessions' at most 17 s,
#: a raster lap a few minutes); a stop of half an hour is long enough for the cell's temperature to
#: move and the sensor to be touched (on a real laser-tracker raster an 8.4 h pause stepped the registration by 76 µm).
PAUSE_S = 1800.0
#: Physical range of an arm's expansion coefficient α [1/K]: steel 11–13, aluminium ~23 µm/m/K.
ALPHA_RANGE = (5e-6, 30e-6)


def temperature_column(data: MeasurementSet, name: str | None = None) -> tuple[str, np.ndarray] | None:
    """The rows' temperature [°C] from ``name`` or the first of :data:`TEMPERATURE_COLUMNS` present,
    with the column's name; None without one.

    Raises:
        PincalError: no column ``name`` (with the closest names; in some of several files: naming the files
            without it), or an empty / non-finite cell.
    """
    return data.reading_column(name, TEMPERATURE_COLUMNS, "temperature",
                               "thermal expansion needs every row's temperature", "--temperature-column", " (°C)")


@dataclass(frozen=True)
class TemperatureRange:
    """The temperatures [°C] of the rows a thermal expansion was fitted on (REPORT.json ``temperature_range_c``).

    Attributes:
        low / high: the lowest and highest temperature; mean: T_ref of eq T1.
    """

    low: float
    high: float
    mean: float

    @classmethod
    def of(cls, temperature: npt.ArrayLike) -> TemperatureRange:
        values = np.asarray(temperature, dtype=float)
        low, high = float(values.min()), float(values.max())
        return cls(low, high, min(max(float(values.mean()), low), high))  # the rounded mean stays inside

    def held(self, temperature: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """T_k − T_ref [K] of rows at ``temperature`` (K,) [°C], a row outside [low, high] held at the
        nearer end, and which rows were held (K,)."""
        values = np.asarray(temperature, dtype=float)
        return np.clip(values, self.low, self.high) - self.mean, (values < self.low) | (values > self.high)

    def as_dict(self) -> dict[str, float]:
        return {"min": self.low, "max": self.high, "mean": self.mean}

    @classmethod
    def read(cls, entry: Any, where: str) -> TemperatureRange:
        """REPORT.json ``temperature_range_c`` back.

        Raises:
            PincalError: a missing or malformed entry (``where`` names the report).
        """
        try:
            out = cls(float(entry["min"]), float(entry["max"]), float(entry["mean"]))
        except (KeyError, TypeError, ValueError):
            out = None
        if out is None or not (np.isfinite([out.low, out.high, out.mean]).all() and out.low <= out.mean <= out.high):
            raise PincalError(f"{where}: a thermal effect needs temperature_range_c {{min, mean, max}} (°C, "
                              "min <= mean <= max); rewrite the report with pincal diagnose")
        return out


@dataclass(frozen=True)
class Pause:
    """A gap in one session's rows (REPORT.json ``pauses``), numbered from 1 in time order.

    Attributes:
        number: the ``pause`` of its ``pause_step`` effect.
        session: the session's name.
        before / after: time of the last row before and the first row after the gap [s].
    """

    number: int
    session: str
    before: float
    after: float

    def as_dict(self) -> dict[str, int | str | float]:
        return {"pause": self.number, "session": self.session, "before_s": self.before, "after_s": self.after}

    @classmethod
    def read(cls, entries: Any, where: str) -> tuple[Pause, ...]:
        """REPORT.json ``pauses`` back.

        Raises:
            PincalError: a malformed entry (``where`` names the report).
        """
        try:
            pauses = tuple(cls(int(e["pause"]), reported_session(e["session"], where, "pauses"), float(e["before_s"]),
                               float(e["after_s"])) for e in entries)
        except (KeyError, TypeError, ValueError):
            pauses = ()
        if not pauses or not all(np.isfinite([p.before, p.after]).all() and p.before < p.after for p in pauses):
            raise PincalError(f"{where}: pauses must be a list of {{pause, session, before_s, after_s}} with "
                              "before_s < after_s (finite seconds); rewrite it with pincal diagnose")
        return pauses


def find_pauses(time: npt.ArrayLike, sessions: Sequence[str], pause_s: float = PAUSE_S) -> tuple[Pause, ...]:
    """The gaps longer than ``pause_s`` [s] between consecutive rows (in time order) of each session;
    ``time`` (K,) [s], ``sessions`` (K,) each row's session name. Numbered in the order of their time."""
    time = np.asarray(time, dtype=float)
    names = np.asarray(sessions, dtype=object)
    found = []
    for name in dict.fromkeys(names.tolist()):
        own = np.sort(time[names == name])
        gaps = np.flatnonzero(np.diff(own) > pause_s)
        found += [(float(own[g + 1]), str(name), float(own[g])) for g in gaps]
    return tuple(Pause(n, name, before, after) for n, (after, name, before) in enumerate(sorted(found), start=1))


def pause_rows(time: npt.ArrayLike, sessions: Sequence[str | None], pauses: Sequence[Pause]) -> np.ndarray:
    """a_kp of eq T2 (K, P): 1 where row k (time (K,) [s], its session's name, None: no pause applies)
    lies after pause p of its session — at or after the first row that followed the gap."""
    time = np.asarray(time, dtype=float)
    names = np.asarray(sessions, dtype=object)
    out = np.zeros((time.size, len(pauses)))
    for p, pause in enumerate(pauses):
        out[:, p] = (names == pause.session) & (time >= pause.after)
    return out


@dataclass(frozen=True)
class RowConditions:
    """The per-row changes of eq T1–T2 at given values.

    Attributes:
        expansion: f_k − 1 = α (T_k − T_ref) of each row (K,), or None.
        steps: d_k of each row (K, 3) [m], or None.
    """

    expansion: np.ndarray | None = None
    steps: np.ndarray | None = None

    @property
    def factor(self) -> np.ndarray | None:
        """f_k (K,), or None."""
        return None if self.expansion is None else 1.0 + self.expansion

    def select(self, rows: np.ndarray | slice) -> RowConditions:  # indices, a mask (K,) or a slice
        return RowConditions(None if self.expansion is None else self.expansion[rows],
                             None if self.steps is None else self.steps[rows])

    def world(self, world: np.ndarray) -> np.ndarray:
        """f_k y_k of base-frame points (K, P, 3) [m] (eq T1)."""
        return world if self.expansion is None else world * (1.0 + self.expansion)[:, None, None]

    def offsets(self, drift: npt.ArrayLike | None) -> np.ndarray | None:
        """d_k + drift_k (K, 3) [m] (eq T2), or None when neither."""
        if self.steps is None:
            return None if drift is None else np.asarray(drift, dtype=float)
        return self.steps if drift is None else self.steps + np.asarray(drift, dtype=float)


def row_conditions(effects: Sequence[Effect], values: Sequence[np.ndarray], inputs: EffectInputs | None,
                   fixed: RowConditions | None = None) -> RowConditions | None:
    """The :class:`RowConditions` of ``effects`` at ``values`` over the rows of ``inputs`` (their
    ``temperature`` and ``pauses``), added to ``fixed``; None when no effect and nothing fixed changes a row."""
    expansion = None if fixed is None else fixed.expansion
    steps = None if fixed is None else fixed.steps
    for effect, value in zip(effects, values):
        if effect.type == "thermal":
            if inputs is None or inputs.temperature is None:
                raise PincalError("a thermal effect needs a temperature column (--temperature-column)")
            change = inputs.temperature * float(np.asarray(value).ravel()[0])
            expansion = change if expansion is None else expansion + change
        elif effect.type == "pause_step":
            number = int(effect.pause or 0)
            if inputs is None or inputs.pauses is None or not 1 <= number <= inputs.pauses.shape[1]:
                raise PincalError(f"effect '{effect.label}': no such pause in these rows")
            step = inputs.pauses[:, [number - 1]] * np.asarray(value, dtype=float).reshape(1, 3)
            steps = step if steps is None else steps + step
    if expansion is None and steps is None:
        return None
    return RowConditions(expansion, steps)


def implausible(effect: Effect, value: np.ndarray, std: np.ndarray) -> str | None:
    """Why a thermal expansion α is outside its physical range beyond its standard deviation
    (:data:`ALPHA_RANGE`), else None."""
    if effect.type != "thermal":
        return None
    alpha, spread = float(np.ravel(value)[0]), float(np.ravel(std)[0])
    low, high = ALPHA_RANGE
    if alpha + spread >= low and alpha - spread <= high:
        return None
    return (f"its value {alpha * 1e6:.3g} ± {spread * 1e6:.2g} µm/m/K is outside the physical range of an arm's "
            f"expansion ({low * 1e6:g}–{high * 1e6:g} µm/m/K: steel 11–13, aluminium ~23), a stand-in for something "
            "else (a drift with time, the sensor's own expansion)")


def shown(effect: Effect, values: np.ndarray, std: np.ndarray, unit: str) -> tuple[np.ndarray, np.ndarray, str]:
    """Values, standard deviations and unit as printed: α in µm/m/K, a step in µm; others as given."""
    if effect.type == "thermal":
        return np.asarray(values) * 1e6, np.asarray(std) * 1e6, "µm/m/K"
    if effect.type == "pause_step":
        return np.asarray(values) * 1e6, np.asarray(std) * 1e6, "µm"
    return np.asarray(values), np.asarray(std), unit
