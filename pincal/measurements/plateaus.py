"""Static postures out of recorded streams: still stretches, the clock offset, averaged rows.

A robot visiting postures for a measurement stops at each for a few seconds. From a joint stream
and the measuring system's streams (:mod:`pincal.measurements.bags`) this module makes the rows of
CSV v1, one per stop:

1. **Still stretches** (:func:`still_stretches`): a stretch is still where windows of
   ``min_still`` seconds in which every joint stays within ``still_tol`` (max − min) cover it; a
   stretch covered only by windows of a quarter of that (:data:`SHORT_FRACTION`) is a stop too
   short to use, shorter still is motion.
2. **Clock offset** (:func:`estimate_clock_offset`): the measuring system stamps on its own clock.
   The offset — measurement stamp minus joint stamp of one instant — is first where the joints'
   speed (norm of dq/dt) and the measured points' speed correlate best, searched ``max_offset``
   either side of what the recorder's receive times say; then, about each start and end of a stop,
   where the measured positions are best explained by a polynomial of the joint motion.
3. **Averaging** (:func:`extract_postures`): each stretch is trimmed by ``trim`` seconds at both
   ends (the arm settles after the joints stop); the joint readings and, shifted by the offset,
   the measured samples in what is left are averaged — positions by the mean, orientations by the
   rotation mean (:meth:`scipy.spatial.transform.Rotation.mean`, the chordal L2 mean), not by
   averaging quaternion components. A row is refused, with its reason, when the stop is too short,
   a measured topic has fewer than ``min_samples`` samples in the window (dropouts), or the
   measured positions spread more than ``max_spread_mm`` (the target moved while the joints did
   not).

Times are seconds; joint values rad (m for prismatic joints); positions m; spreads mm and deg.
Nothing here prints: refusals are returned (:class:`Refusal`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.errors import MeasurementError, PincalError
from pincal.measurements.bags import JointStream, MeasurementStream
from pincal.measurements.data import MeasurementSet, is_reserved
from pincal.measurements.plateau_defaults import (
    MAX_OFFSET_S,
    MAX_SPREAD_MM,
    MIN_SAMPLES,
    MIN_STILL_S,
    STILL_TOL,
    TRIM_S,
)

__all__ = [
    "STILL_TOL", "MIN_STILL_S", "TRIM_S", "MIN_SAMPLES", "MAX_SPREAD_MM", "MAX_OFFSET_S", "SHORT_FRACTION",
    "MIN_CORRELATION", "SPEED_SMOOTHING_S", "REFINE_STAGES", "EDGE_WINDOW_S", "DEGREE", "GRID_STEP_RANGE", "REASONS",
    "PlateauSettings", "ClockOffset", "Refusal", "EXTRA_COLUMNS", "Extraction", "still_stretches", "stops_of",
    "estimate_clock_offset", "extract_postures",
]

# STILL_TOL, MIN_STILL_S, TRIM_S, MIN_SAMPLES, MAX_SPREAD_MM, MAX_OFFSET_S: the defaults of `pincal extract`'s
# flags, pincal.measurements.plateau_defaults (the parser reads them)

#: Stops covered by windows of this fraction of ``min_still`` (but not by full ones) are reported
#: as too short; shorter stops count as motion.
SHORT_FRACTION = 0.25
#: Fewest correlation (Pearson, of the two speeds) at the best offset for the estimate to be used.
MIN_CORRELATION = 0.5
#: Smoothing of positions before differentiating them for speeds [s] (a moving average).
SPEED_SMOOTHING_S = 0.05
#: The refinement's trial offsets: half-width and step [s] about the speeds' estimate, then about
#: the best of those (the speeds' estimate was off by up to 60 ms in simulated sessions).
REFINE_STAGES = ((0.2, 0.01), (0.015, 0.001))
#: Half-width of the window about each start and end of a stop that the refinement regresses [s],
#: and the degree of the polynomial of the joint motion regressed on: 0.15 s and 3 came within
#: 0.7 ms in simulated sessions from 0.6 s to 4 s moves, where 0.3 s was off by 5 ms on 0.6 s moves
#: and a straight line by up to 4 ms.
EDGE_WINDOW_S = 0.15
DEGREE = 3
#: Step of the grid the speeds are correlated on: the finer stream's period, within these [s].
GRID_STEP_RANGE = (1e-3, 2e-2)

REASONS = ("too short", "too few samples", "moving")


@dataclass(frozen=True)
class PlateauSettings:
    """How still stretches are found and averaged (defaults: the module constants).

    Attributes:
        still_tol: joint tolerance, max − min over a window [rad; m for prismatic joints].
        min_still: shortest still stretch [s].
        trim: cut from both ends of a stretch before averaging [s]; less than ``min_still / 2``.
        min_samples: fewest samples of each measured topic in a window.
        max_spread_mm: largest RMS spread of the measured positions in a window [mm].
        max_offset: half-width of the clock-offset search [s].
        clock_offset: the offset (measurement stamp − joint stamp) [s] if known; None: estimated.
    """

    still_tol: float = STILL_TOL
    min_still: float = MIN_STILL_S
    trim: float = TRIM_S
    min_samples: int = MIN_SAMPLES
    max_spread_mm: float = MAX_SPREAD_MM
    max_offset: float = MAX_OFFSET_S
    clock_offset: float | None = None

    def __post_init__(self) -> None:
        if not 2 * self.trim < self.min_still:
            raise PincalError(f"--trim {self.trim:g} s leaves nothing of a {self.min_still:g} s stretch "
                              "(--min-still): give a trim below half of it")


@dataclass(frozen=True)
class ClockOffset:
    """The offset between the clocks: measurement stamp − joint stamp of one instant [s].

    Attributes:
        seconds: the offset used.
        estimated: whether it was estimated (else given).
        correlation: Pearson correlation of the two speeds at the offset (None when given).
        prior: the receive-time estimate the search was centred on [s].
        step: the step of the correlation grid [s].
        coarse: the speeds' estimate, before the refinement at the stops [s].
        edges: starts and ends of stops the refinement used (0: the speeds' estimate is the answer).
    """

    seconds: float
    estimated: bool
    correlation: float | None = None
    prior: float = 0.0
    step: float = 0.0
    coarse: float | None = None
    edges: int = 0


@dataclass(frozen=True)
class Refusal:
    """A stop that gives no row: its stretch on the joint clock [s], the reason and the numbers."""

    start: float
    end: float
    reason: str
    detail: str


#: The extra columns of the rows written (:class:`Extraction`).
EXTRA_COLUMNS = ("spread_mm", "spread_deg", "samples", "t_start_robot", "t_end_robot")


@dataclass(frozen=True)
class Extraction:
    """The rows of the static postures and what was refused.

    Attributes:
        data: the rows (CSV v1; None when every stop was refused), extras ``spread_mm`` (and
            ``spread_deg`` for a pose), ``samples`` (the fewest samples of a measured topic in the
            window), ``t_start_robot`` and ``t_end_robot`` (the averaging window on the joint clock [s]).
        refused: the stops that gave no row, in time order.
        offset: the clock offset used.
        stretches: still stretches found (rows + refusals but the too-short stops).
    """

    data: MeasurementSet | None
    refused: tuple[Refusal, ...]
    offset: ClockOffset
    stretches: int

    def count(self, reason: str) -> int:
        """Refusals for ``reason`` (one of :data:`REASONS`)."""
        return sum(1 for r in self.refused if r.reason == reason)


def still_stretches(stamps: np.ndarray, positions: np.ndarray, tol: float, duration: float) -> list[tuple[int, int]]:
    """Index ranges ``(first, last)`` (inclusive) covered by windows of ``duration`` seconds in which
    every column of ``positions`` (N, J) stays within ``tol`` (max − min).

    A window is a number of samples, ``duration`` over the median sampling period (odd, at least
    3): the stream is assumed evenly sampled to a few percent; windows that would run past either
    end of the stream count as not still.
    """
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    n = len(stamps)
    if n < 3:
        return []
    period = float(np.median(np.diff(stamps)))
    size = max(int(round(duration / period)) if period > 0 else n, 2) | 1
    if size > n:
        return []
    spread = maximum_filter1d(positions, size, axis=0) - minimum_filter1d(positions, size, axis=0)
    ok = np.all(spread <= tol, axis=1)
    half = size // 2
    ok[:half] = ok[n - half:] = False  # truncated windows at the ends
    covered = maximum_filter1d(ok.astype(np.uint8), size) > 0
    edges = np.diff(np.concatenate([[0], covered.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), (np.flatnonzero(edges == -1) - 1).tolist()))


def stops_of(joints: JointStream, settings: PlateauSettings) -> tuple[list[tuple[int, int]], list[Refusal]]:
    """The still stretches of ``joints`` (index ranges, :func:`still_stretches` of ``min_still``) and the
    stops too short to use (still for :data:`SHORT_FRACTION` of it but not all), refused."""
    t, q = joints.stamps, joints.positions
    stops = still_stretches(t, q, settings.still_tol, settings.min_still)
    short = still_stretches(t, q, settings.still_tol, settings.min_still * SHORT_FRACTION)
    refused = [Refusal(float(t[a]), float(t[b]), "too short",
                       f"still for {t[b] - t[a]:.2f} s < --min-still {settings.min_still:g} s")
               for a, b in short if not any(a <= c and d <= b for c, d in stops)]
    return stops, refused


def _speed(grid: np.ndarray, stamps: np.ndarray, values: np.ndarray, step: float) -> np.ndarray:
    """Norm of the time derivative of ``values`` (N, D) resampled on ``grid`` (held constant beyond
    the stream's ends, so there the speed is zero)."""
    from scipy.ndimage import uniform_filter1d

    resampled = np.column_stack([np.interp(grid, stamps, values[:, d]) for d in range(values.shape[1])])
    width = max(int(round(SPEED_SMOOTHING_S / step)), 1)
    smooth = uniform_filter1d(resampled, width, axis=0, mode="nearest")
    return np.linalg.norm(np.gradient(smooth, step, axis=0), axis=1)


def estimate_clock_offset(joints: JointStream, measurements: Sequence[MeasurementStream],
                          max_offset: float = MAX_OFFSET_S, still_tol: float = STILL_TOL,
                          min_still: float = MIN_STILL_S) -> ClockOffset:
    """The offset measurement stamp − joint stamp [s] of one instant, from the motion.

    First the speeds: where the norm of the joints' dq/dt and the measured points' speed correlate
    best, searched ``max_offset`` either side of what the receive times say (median of stamp −
    receive time of the measurements minus that of the joints: the clocks' offset up to the
    difference of the transport delays), on a grid of the finer stream's period (1–20 ms). The two
    speeds are not proportional (the arm's lever changes along a move), so that peak can be off by
    tens of milliseconds. Then the stops: about each start and end of a still stretch (stops of
    ``min_still`` / 4 or longer, ``still_tol``), within :data:`EDGE_WINDOW_S`, the measured
    positions are regressed on a cubic polynomial of the joint motion read at sample time − a trial
    offset (the kinematics expanded there, whatever the arm's lever); the trial offset with the
    least misfit (:func:`_alignment_costs`), searched in :data:`REFINE_STAGES` and refined between
    trials by a parabola, is the answer (simulated sessions: within 0.7 ms, from 30 Hz to 300 Hz
    trackers and 0.6–4 s moves).

    Raises:
        MeasurementError: the speeds' best match lies at the edge of the search range, or correlates
            less than :data:`MIN_CORRELATION` (too little motion, or no relation): give the offset.
    """
    coarse, correlation, prior, step = _correlated_offset(joints, measurements, max_offset)
    stops = still_stretches(joints.stamps, joints.positions, still_tol, min_still * SHORT_FRACTION)
    edges = [joints.stamps[i] for a, b in stops for i in (a, b) if 0 < i < len(joints.stamps) - 1]
    centre, used = coarse, 0
    for half_width, trial_step in REFINE_STAGES:  # coarse to fine, each about the last one's best
        trials = centre + np.arange(-half_width, half_width + trial_step / 2, trial_step)
        costs, used = _alignment_costs(joints, measurements, edges, trials, still_tol)
        if not used:
            break
        best = int(np.argmin(costs))
        shift = 0.0
        if 0 < best < len(costs) - 1:
            below, low, above = costs[best - 1: best + 2]
            curvature = below - 2 * low + above
            shift = 0.5 * (below - above) / curvature if curvature > 0 else 0.0
        centre = float(trials[best] + shift * trial_step)
    return ClockOffset(centre, True, correlation, prior, step, coarse, used)


def _correlated_offset(joints: JointStream, measurements: Sequence[MeasurementStream],
                       max_offset: float) -> tuple[float, float, float, float]:
    """The offset where the speeds correlate best [s], that correlation, the receive-time estimate
    [s] and the grid step [s] (:func:`estimate_clock_offset`, first step)."""
    from scipy.signal import correlate, correlation_lags

    prior = float(np.median(measurements[0].stamps - measurements[0].received)
                  - np.median(joints.stamps - joints.received))
    stamps = [joints.stamps, *(s.stamps for s in measurements)]
    span = max(t[-1] for t in stamps) - min(t[0] for t in stamps)
    if max_offset > span:
        raise MeasurementError(f"--max-offset {max_offset:g} s: longer than the recording ({span:.3g} s); "
                               "give at most the recording's length, or --clock-offset if it is known")
    periods = [np.median(np.diff(t)) for t in stamps if len(t) > 1]
    step = float(np.clip(min(periods, default=GRID_STEP_RANGE[1]), *GRID_STEP_RANGE))
    origin = joints.stamps[0]
    first = min(joints.stamps[0], min(s.stamps[0] for s in measurements) - prior) - max_offset
    last = max(joints.stamps[-1], max(s.stamps[-1] for s in measurements) - prior) + max_offset
    grid = np.arange(first - origin, last - origin + step, step)
    x = _speed(grid, joints.stamps - origin, joints.positions, step)
    y = np.mean([_speed(grid, s.stamps - origin - prior, s.positions, step) for s in measurements], axis=0)
    x, y = x - x.mean(), y - y.mean()
    norm = float(np.sqrt(np.sum(x * x) * np.sum(y * y)))
    if norm == 0:
        raise MeasurementError("clock offset: the joints or the measured points never move; give --clock-offset")
    reach = int(np.ceil(max_offset / step))
    lags = correlation_lags(len(y), len(x))
    inside = np.abs(lags) <= reach
    values = correlate(y, x, mode="full", method="fft")[inside] / norm  # values[k]: sum x[t] y[t + lag]
    lags = lags[inside]
    best = int(np.argmax(values))
    if best in (0, len(values) - 1):
        raise MeasurementError(f"clock offset: the best match lies at the edge of the search range "
                               f"({prior:+.3f} s ± {max_offset:g} s from the receive times): raise --max-offset "
                               "or give --clock-offset")
    correlation = float(values[best])
    if correlation < MIN_CORRELATION:
        raise MeasurementError(f"clock offset: joint and measured speeds correlate at most {correlation:.2f} "
                               f"(< {MIN_CORRELATION}) within ±{max_offset:g} s: too little motion to time it; "
                               "give --clock-offset")
    return prior + lags[best] * step, correlation, prior, step


def _alignment_costs(joints: JointStream, measurements: Sequence[MeasurementStream], edges: Sequence[float],
                     trials: np.ndarray, still_tol: float) -> tuple[np.ndarray, int]:
    """The misfit of each trial offset, and how many ``edges`` (joint clock [s]) it used.

    About an edge, the measured positions are regressed on a cubic polynomial of the joint motion
    read at sample time − the trial offset: the joint motion's principal directions that move more
    than ``still_tol`` RMS (one for a move interpolated in joint space), read between samples by a
    cubic spline. Each edge has its own noise (a target shaken during a stop has much), so the
    misfit is the negative log-likelihood with each edge's variance profiled out: the sum over
    edges of n·log(residual sum of squares), n the edge's residuals.
    """
    from scipy.interpolate import CubicSpline

    costs = np.zeros(len(trials))
    used = 0
    middle = trials[len(trials) // 2]
    reach = EDGE_WINDOW_S + float(np.max(np.abs(trials - middle))) + 0.05
    for edge in edges:
        near = np.abs(joints.stamps - edge) <= reach
        readings = joints.positions[near] - joints.positions[near].mean(axis=0)
        if len(readings) < 4:
            continue
        _, singular, directions = np.linalg.svd(readings, full_matrices=False)
        basis = directions[singular / np.sqrt(len(readings)) > still_tol].T
        if basis.shape[1] == 0:
            continue
        motion = CubicSpline(joints.stamps[near] - edge, readings @ basis, extrapolate=True)
        squares, count = np.zeros(len(trials)), 0
        for stream in measurements:
            inside = np.abs(stream.stamps - middle - edge) <= EDGE_WINDOW_S
            if np.sum(inside) <= DEGREE * basis.shape[1] + 2:
                continue
            target = stream.positions[inside] - stream.positions[inside].mean(axis=0)
            count += target.size
            for k, trial in enumerate(trials):
                scores = motion(stream.stamps[inside] - trial - edge)
                design = np.column_stack([scores**d for d in range(1, DEGREE + 1)] + [np.ones(len(scores))])
                residual = target - design @ np.linalg.lstsq(design, target, rcond=None)[0]
                squares[k] += float(np.sum(residual**2))
        if count and np.all(squares > 0):
            costs += count * np.log(squares)
            used += 1
    return costs, used


_Window = tuple[np.ndarray | None, float, np.ndarray | None, float | None, int]  # what _window_mean returns


def _window_mean(stream: MeasurementStream, start: float, end: float) -> _Window:
    """Mean position, spreads (sum of squared deviations [m²], RMS angle [rad]), rotation mean and
    count of the samples of ``stream`` stamped in [start, end]."""
    inside = (stream.stamps >= start) & (stream.stamps <= end)
    points = stream.positions[inside]
    count = len(points)
    if count == 0:
        return None, 0.0, None, None, 0
    mean = points.mean(axis=0)
    squares = float(np.sum((points - mean) ** 2))
    if stream.quaternions is None:
        return mean, squares, None, None, count
    rotations = Rotation.from_quat(stream.quaternions[inside])
    average = rotations.mean()
    angle = float(np.sqrt(np.mean((average.inv() * rotations).magnitude() ** 2)))
    return mean, squares, average.as_matrix(), angle, count


def extract_postures(joints: JointStream, measurements: Sequence[MeasurementStream],
                     settings: PlateauSettings = PlateauSettings(), source: str = "<bag>") -> Extraction:
    """The rows of the static postures of a recording, the refusals and the clock offset.

    Args:
        joints: the joint stream; stillness is judged on all its joints.
        measurements: one pose stream (quaternions given) or one or more point streams, in column order.
        settings: tolerances (:class:`PlateauSettings`).
        source: the bag's path, named in errors and as the rows' source.

    Raises:
        MeasurementError: a joint named as a column the rows are written with, or the clock offset
            cannot be estimated.
    """
    clash = [n for n in joints.names if is_reserved(n, ()) or n in EXTRA_COLUMNS]
    if clash:
        raise MeasurementError(f"{source}: joint '{clash[0]}' has the name of a column of the CSV written "
                               f"({', '.join(('x, y, z, qx … qw, x1 …, role, session',) + EXTRA_COLUMNS)}); "
                               "rename it in the URDF and the bag, or leave it out with --joint-names")
    if settings.clock_offset is not None:
        offset = ClockOffset(settings.clock_offset, False)
    else:
        offset = estimate_clock_offset(joints, measurements, settings.max_offset, settings.still_tol,
                                       settings.min_still)
    t, q = joints.stamps, joints.positions
    stops, refused = stops_of(joints, settings)
    pose = measurements[0].quaternions is not None
    # per posture: q, positions, rotation, spread [mm], spread [rad], samples, window [s]
    rows: list[tuple[np.ndarray, list[np.ndarray | None], np.ndarray | None, float, float | None, int,
                     tuple[float, float]]] = []
    for a, b in stops:
        start, end = float(t[a]), float(t[b])
        if end - start < settings.min_still:
            refused.append(Refusal(start, end, "too short", f"still for {end - start:.2f} s < --min-still "
                                   f"{settings.min_still:g} s (uneven sampling)"))
            continue
        window = (start + settings.trim, end - settings.trim)
        inside = (t >= window[0]) & (t <= window[1])
        results = [_window_mean(s, window[0] + offset.seconds, window[1] + offset.seconds) for s in measurements]
        counts = [r[4] for r in results]
        if min(counts) < settings.min_samples:
            worst = int(np.argmin(counts))
            refused.append(Refusal(start, end, "too few samples", f"{counts[worst]} samples of "
                                   f"{measurements[worst].topic} in the {window[1] - window[0]:.2f} s window "
                                   f"< --min-samples {settings.min_samples}"))
            continue
        spread_mm = 1000 * float(np.sqrt(sum(r[1] for r in results) / sum(counts)))
        if spread_mm > settings.max_spread_mm:
            refused.append(Refusal(start, end, "moving", f"measured positions spread {spread_mm:.3f} mm RMS > "
                                   f"--max-spread {settings.max_spread_mm:g} mm while the joints were still"))
            continue
        rows.append((q[inside].mean(axis=0), [r[0] for r in results], results[0][2], spread_mm,
                     results[0][3], min(counts), window))
    refused.sort(key=lambda r: r.start)
    if not rows:
        return Extraction(None, tuple(refused), offset, len(stops))
    extra = {"spread_mm": np.array([r[3] for r in rows])}
    if pose:
        extra["spread_deg"] = np.degrees(np.array([r[4] for r in rows], dtype=float))  # pose rows: every angle set
    extra.update(samples=np.array([r[5] for r in rows], dtype=float), t_start_robot=np.array([r[6][0] for r in rows]),
                 t_end_robot=np.array([r[6][1] for r in rows]))
    data = MeasurementSet(
        joint_names=joints.names,
        q=np.array([r[0] for r in rows]),
        points=np.array([r[1] for r in rows]),
        rotations=np.array([r[2] for r in rows]) if pose else None,
        roles=np.array(["calibration"] * len(rows), dtype=object),
        lines=np.arange(2, len(rows) + 2),
        extra=extra,
        source=source,
    )
    return Extraction(data, tuple(refused), offset, len(stops))
