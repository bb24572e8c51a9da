"""Several sessions in one calibration: one registration sensor_T_base per session.

A session is a run of measurements during which the sensor (or fixture) did not
move relative to the robot base: its rows share one registration (Omega_s, tau_s),
while the kinematic model and the target are shared by every session
(:class:`pincal.residuals.sensor.SensorResidual` with ``sessions``). The
sessions of a :class:`~pincal.measurements.data.MeasurementSet` are its
``sessions`` labels (the ``session`` column, or one per file).

This module holds what the sessions add to a fit:

* :func:`check_registrable` — whether the rows of each session can determine
  their registration, with one line naming the file, the session, why not and
  what to add;
* :func:`initial_target` — starting registrations (one per session: Arun et al.
  1987 from 3 or more points, else from the orientations, Registration 2) and
  target points, alternated from the nominal model;
* :func:`session_rows` — which registration the rows of another set use;
* :func:`register_session` — a session the calibration has not seen: its 6
  registration parameters fitted with the model and the target fixed;
* :func:`session_pose_errors` — eq 24 with each row in its session's registration.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Literal, cast

import numpy as np
import numpy.typing as npt

from pincal.errors import CalibrationError
from pincal.fit.metrics import PoseErrors, RowCorrections, pose_errors
from pincal.fit.outliers import RowOutlier
from pincal.fit.registration import (
    mean_rotation,
    register_line,
    register_orientations,
    register_points,
)
from pincal.fit.solver import solve
from pincal.measurements.data import (
    SESSION_COLUMN,
    MeasurementSet,
    default_session_name,
)
from pincal.model.chain import KinematicChain, points_in_base
from pincal.model.parameter_sets import NoParameters
from pincal.model.sensor import Registration
from pincal.model.thermal import RowConditions
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import FittedBlocks, ModelledEffects, RowWeights
from pincal.residuals.so3 import log3

__all__ = [
    "MIN_SPREAD_M", "MIN_SPREAD_RATIO", "LINE_RATIO", "MIN_TURN_RAD", "where", "rows_at", "by_orientation",
    "check_registrable", "session_rows", "by_points", "start_registration", "initial_target", "register_session",
    "session_pose_errors", "RegistrationStart", "registration_problem",
]

#: How a session's registration is started: from its points (Arun), from its orientations
#: (Registration 2), or from points on one line (:func:`pincal.fit.registration.register_line`).
RegistrationStart = Literal["points", "orientations", "line"]

#: Measured points whose spread about a point (or off a line) is below this [m]
#: coincide (lie on one line) for a registration: 1 µm is below the noise of any
#: sensor pincal is used with (a laser tracker's ~10 µm; ``simulate``'s default 55 µm),
#: so such a spread carries no information on the rotation it would fix.
MIN_SPREAD_M = 1e-6
#: ... or below this fraction of the largest spread (rounding, the test of
#: :func:`pincal.fit.registration.register_points`).
MIN_SPREAD_RATIO = 1e-9
#: Modelled tool positions off their line by less than this fraction of their spread along it lie on
#: it: 0.1 mm per metre, the path error of a straight-line move replayed through encoders (jitter of
#: 1e-5 rad at a 1 m reach is 10 µm), far below any path meant to leave the line.
LINE_RATIO = 1e-4
#: A tool that turns by less than this over a session's rows [rad] keeps one orientation
#: (the test of :data:`pincal.fit.target_hold.NO_TURN_RAD`: a controller's rounding).
MIN_TURN_RAD = 1e-6


def where(data: MeasurementSet, name: str) -> str:
    """The file (and session) of session ``name``'s rows, for messages: ``A.csv, session 'day2'``."""
    rows = np.flatnonzero(data.sessions == name)
    files = list(dict.fromkeys(data.files[rows].tolist())) or [data.source]
    text = " + ".join(files)
    if len(data.session_names) > 1 or name != default_session_name(files[0]):
        text += f", session '{name}'"
    return text


def rows_at(data: MeasurementSet, index: Sequence[int]) -> str:
    """Where rows are, for notes: ``lines [3, 9]`` in one file, else ``A.csv line 3, B.csv line 9``."""
    if len(set(data.files.tolist())) == 1:
        return f"lines {[int(data.lines[k]) for k in index]}"
    return ", ".join(f"{data.files[k]} line {int(data.lines[k])}" for k in index)


def by_orientation(data: MeasurementSet, outliers: Sequence[RowOutlier]) -> str:
    """``; by their orientation: lines [9]`` naming the outliers (rows of ``data``) that their orientation
    error flags, to follow :func:`rows_at` in a note; empty when none is."""
    turned = [o.row for o in outliers if o.by == "orientation"]
    return f"; by their orientation: {rows_at(data, turned)}" if turned else ""


def registration_problem(points: np.ndarray, n_rows: int, has_orientation: bool) -> str | None:
    """Why measured points (n, 3) [m] of ``n_rows`` rows cannot determine a registration
    (rotation and translation, 6 parameters), and what to add; None if they can.

    One row with an orientation fixes the rotation, any point the translation;
    without orientations the rotation needs 3 or more points not on one line.
    """
    if has_orientation and n_rows >= 1:
        return None
    n = len(points)
    orientation = "or orientation columns qx,qy,qz,qw"
    if n < 3:
        return (f"{n_rows} row(s) with {n} measured point(s) in all: a registration (the sensor's pose, "
                f"6 parameters) needs 3 or more points not on one line, or one row with an orientation; "
                f"add rows to this session ({orientation}), or — if the sensor did not move — give the rows "
                f"the session of others ('{SESSION_COLUMN}' column)")
    spread = _spreads(points)
    if spread[0] <= MIN_SPREAD_M:
        return (f"all {n} measured points coincide (within {spread[0] * 1000:.3g} mm; rows that all measure "
                "one fixed point, e.g. one socket of a fixture, say nothing of where the sensor is): the "
                "registration (the sensor's pose, 6 parameters) is undetermined; measure the target at 3 or more "
                f"positions not on one line, {orientation}")
    if spread[1] <= max(MIN_SPREAD_M, MIN_SPREAD_RATIO * spread[0]):
        return (f"all {n} measured points lie on one line (within {spread[1] * 1000:.3g} mm of it; e.g. the "
                "two sockets of a fixture used without their grouping): the registration's rotation about that "
                f"line is undetermined; add rows measuring a point off the line, {orientation}")
    return None


def check_registrable(data: MeasurementSet, orientations: bool = True) -> None:
    """Raise one clear line for the first session whose rows cannot determine its registration.

    ``orientations=False``: from positions alone, although orientations were
    measured (the paper's Registration 1).

    Raises:
        CalibrationError: naming the file and session, why, and what to add.
    """
    index = data.session_index
    for s, name in enumerate(data.session_names):
        rows = np.flatnonzero(index == s)
        problem = registration_problem(data.points[rows].reshape(-1, 3), len(rows),
                                       data.has_orientation and orientations)
        if problem:
            raise CalibrationError(f"{where(data, name)}: {problem}")


def session_rows(data: MeasurementSet, names: Sequence[str]) -> np.ndarray:
    """Each row's registration: the index in ``names`` of its session (K,).

    Rows of a session not in ``names`` use the only registration when there is
    one (held-out rows of the same setup, as ever); with several they are refused.

    Raises:
        CalibrationError: rows of an unknown session and several registrations.
    """
    order = {name: i for i, name in enumerate(names)}
    unknown = [n for n in data.session_names if n not in order]
    if unknown and len(names) == 1:
        return np.zeros(data.n_rows, dtype=np.intp)
    if unknown:
        raise CalibrationError(
            f"{where(data, unknown[0])}: not one of the calibrated sessions ({', '.join(names)}), so no "
            f"registration is known for it; give the rows a '{SESSION_COLUMN}' column naming the session "
            "they were measured in")
    return np.array([order[n] for n in data.sessions], dtype=np.intp)


def by_points(data: MeasurementSet) -> bool:
    """Whether the measured points of ``data`` alone fix a registration (Registration 1,
    Arun: 3 or more points not on one line); else the orientations must (Registration 2)."""
    return registration_problem(data.points.reshape(-1, 3), data.n_rows, False) is None


def start_registration(
    world: np.ndarray, sensed: np.ndarray, model_rotations: np.ndarray, measured: MeasurementSet
) -> Registration:
    """A session's starting registration: Registration 1 (Arun) from the points when
    they fix it, else Registration 2 — Ω the mean rotation of G_k (R_k R_T)ᵀ
    (Moakher), τ by eq 19 — so one 6D row registers a session.

    Args:
        world: (K, P, 3) the target points in the robot base [m]; ``sensed`` the same measured [m].
        model_rotations: (K, 3, 3) the target frame in the robot base, R_k R_T.
        measured: the session's rows (their orientations G_k and points).
    """
    if measured.rotations is None or (by_points(measured) and not _on_one_line(world.reshape(-1, 3))):
        return register_points(world.reshape(-1, 3), sensed.reshape(-1, 3))
    return register_orientations(model_rotations, measured.rotations, world.reshape(-1, 3), sensed.reshape(-1, 3))


def initial_target(
    chain: KinematicChain, data: MeasurementSet, fit_points: bool, iterations: int = 10
) -> TargetEstimate:
    """Registrations (one per session of ``data``) and target points from the nominal
    model, alternating the registrations with the linear solution for the points;
    the target rotation is the mean of R_kᵀ Omega_sᵀ G_k (Moakher).

    A session is registered by Registration 1 (Arun) from its points; one whose
    points cannot fix a rotation (fewer than 3, or on one line) but whose rows
    have orientations by Registration 2 (:func:`start_registration`), with the
    target rotation R_T of the sessions registered by points (the identity when
    there are none, or the target is known: ``fit_points=False``). A session whose
    modelled tool positions lie on one line at one orientation (a straight-line path),
    which its rows cannot register but about the line, is registered by
    :func:`pincal.fit.registration.register_line`: nearest Registration 2 taken with
    that R_T (rows with orientations), else levelled — the rotation about the line the
    calibration then holds (:mod:`pincal.fit.registration_hold`).
    """
    poses = chain.poses(data.q)
    t, rot = poses.tool_positions, poses.tool_rotations
    index = data.session_index
    groups = [np.flatnonzero(index == s) for s in range(len(data.session_names))]
    how = [_start_kind(data, name, rows, t, rot, fit_points) for name, rows in zip(data.session_names, groups)]
    from_points = [kind != "orientations" for kind in how]  # τ by eq 19 from the points (Arun's, or a line's)
    points = np.zeros((data.n_points, 3))
    for _ in range(iterations if fit_points else 1):
        world = points_in_base(t, rot, points)
        registrations = [register_points(world[rows].reshape(-1, 3), data.points[rows].reshape(-1, 3))
                         if kind == "points" else None for rows, kind in zip(groups, how)]
        if not all(kind == "points" for kind in how):
            target = np.eye(3)
            if fit_points and "points" in how and data.rotations is not None:
                target = _target_rotation(rot, data, registrations)
            registrations = [registration or _start_session(world[rows], data.select(rows), rot[rows] @ target, kind)
                             for rows, registration, kind in zip(groups, registrations, how)]
        if not fit_points:
            break
        local = np.empty_like(data.points)
        # every session is registered by now (by its points or its orientations)
        for rows, registration in zip(groups, cast("list[Registration]", registrations)):  # Ωᵀ(g − τ)
            local[rows] = (data.points[rows] - registration.translation) @ registration.rotation
        target = np.einsum("kji,kpj->kpi", rot, local - t[:, None, :])
        if all(from_points) or not any(from_points):
            points = target.mean(axis=0)
        else:  # a session registered by its orientations fits its τ to the points: it would only damp them
            points = target[np.concatenate([rows for rows, ok in zip(groups, from_points) if ok])].mean(axis=0)
    rotation = np.eye(3)
    if data.rotations is not None:
        rotation = _target_rotation(rot, data, registrations)
    registered = cast("list[Registration]", registrations)  # every session's, as above
    return TargetEstimate(registered[0], points, rotation, tuple(registered))


def _start_kind(data: MeasurementSet, name: str, rows: np.ndarray, t: np.ndarray, rot: np.ndarray,
                fit_points: bool) -> RegistrationStart:
    """How :func:`initial_target` starts a session's registration: ``points`` (Arun), ``orientations``
    (Registration 2) or ``line`` (:func:`pincal.fit.registration.register_line`).

    Raises:
        CalibrationError: modelled tool positions on one line that no rule registers: the tool turns and
            no orientation was measured (the data may fix the target; the start cannot), or they coincide.
    """
    if data.rotations is not None and not by_points(data.select(rows)):
        return "orientations"
    if not _on_one_line(t[rows]):
        return "points"
    turns = np.linalg.norm(log3(rot[rows[0]].T @ rot[rows]), axis=1)  # from the first row's [rad]
    if data.rotations is not None and (turns.max() > MIN_TURN_RAD or not fit_points):  # they fix the rotation
        return "orientations"
    if turns.max() > MIN_TURN_RAD and fit_points:  # the tool turns, so the data may fix it; the start cannot
        raise CalibrationError(
            f"{where(data, name)}: the tool positions of these rows lie on one line in the model (e.g. a "
            "straight-line path) and no orientation was measured: pincal cannot start the registration "
            "from them; add rows off the line, orientation columns (qx,qy,qz,qw), or give --tool")
    if _spreads(t[rows])[0] <= MIN_SPREAD_M:
        raise CalibrationError(
            f"{where(data, name)}: the tool sits at one point in the model in all of these rows: the sensor's "
            "rotation cannot be told from them and no geometry is seen; move the tool along a path (a line, an "
            "arc), or measure its orientation and give --tool")
    return "line"


def _start_session(world: np.ndarray, measured: MeasurementSet, model_rotations: np.ndarray, kind: str
                   ) -> Registration:
    """A session's start not by Arun's method: :func:`start_registration` (``orientations``), or the
    rotation about the line stated by :func:`pincal.fit.registration.register_line` (``line``), nearest
    Registration 2 with the target frame at ``model_rotations`` (K, 3, 3) when the rows have orientations."""
    if kind != "line":
        return start_registration(world, measured.points, model_rotations, measured)
    sensed = measured.points.reshape(-1, 3)
    reference = None
    if measured.rotations is not None:
        reference = register_orientations(model_rotations, measured.rotations, world.reshape(-1, 3), sensed).rotation
    return register_line(world.reshape(-1, 3), sensed, reference)


def _on_one_line(positions: np.ndarray) -> bool:
    """Whether modelled tool positions (n, 3) [m] lie on one line: off it by at most :data:`MIN_SPREAD_M`
    or :data:`LINE_RATIO` of their spread along it (RMS)."""
    if len(positions) < 3:
        return False
    spread = _spreads(positions)
    return bool(spread[1] <= max(MIN_SPREAD_M, LINE_RATIO * spread[0]))


def _spreads(points: np.ndarray) -> np.ndarray:
    """RMS spread of points (n, 3) [m] along their principal axes, largest first (3,)."""
    return np.linalg.svd(points - points.mean(axis=0), compute_uv=False) / np.sqrt(len(points))


def _target_rotation(rot: np.ndarray, data: MeasurementSet, registrations: Sequence[Registration | None]
                     ) -> np.ndarray:
    """R_T: the mean of R_kᵀ Omega_sᵀ G_k over the rows of the sessions registered so far (Moakher)."""
    assert data.rotations is not None  # called only for rows with orientations
    rows: slice | np.ndarray
    if len(registrations) == 1:
        omega, rows = cast(Registration, registrations[0]).rotation, slice(None)  # one session: registered
    else:
        index = data.session_index
        rows = np.flatnonzero(np.array([r is not None for r in registrations])[index])  # in row order
        omega = np.stack([np.eye(3) if r is None else r.rotation for r in registrations])[index[rows]]
    relative = rot[rows].transpose(0, 2, 1) @ np.swapaxes(omega, -1, -2) @ data.rotations[rows]  # R_kᵀ Ωᵀ G_k
    return mean_rotation(relative)


def register_session(
    chain: KinematicChain,
    data: MeasurementSet,
    points: npt.ArrayLike,
    rotation: npt.ArrayLike,
    corrections: RowCorrections | None = None,
    sigma_pos_m: float = 1e-3,
    sigma_rot_rad: float = 1e-3,
) -> Registration:
    """sensor_T_base of rows measured in a session the calibration has not seen.

    Only the registration's 6 parameters are fitted — the chain (as it is), the
    target ``points`` (P, 3) [m] and ``rotation`` R_T in the tool frame are fixed:
    least squares of :class:`SensorResidual` with positions weighted by
    1/σ_p [1/m] and orientations by 1/σ_a [1/rad] (maximum likelihood for that
    noise), started from Registration 1 (Arun) — or, when the points cannot fix a
    rotation (fewer than 3, or on one line) and the rows have orientations, from
    Registration 2 with the target rotation fixed (:func:`start_registration`: one
    6D row suffices). Sensor effects of a report are undone first:
    g' = g / (1 + s) − drift_k − d_k; a thermal expansion scales the model's points (``corrections.conditions``,
    eq T1–T2 of :mod:`pincal.model.thermal`).

    Args:
        corrections: the rows' joint values corrected by effects (K, N), the sensor scale s, the drift
            offset t_k u of each row [m] (K, 3) and the thermal conditions (default: none).

    Raises:
        CalibrationError: rows that cannot determine a registration (:func:`check_registrable`).
    """
    check_registrable(data)
    corrections = RowCorrections() if corrections is None else corrections
    conditions = corrections.conditions
    q = data.q if corrections.q is None else np.asarray(corrections.q, dtype=float)
    sensed = data.points / (1.0 + corrections.sensor_scale)
    offsets = corrections.drift if conditions is None else conditions.offsets(corrections.drift)
    if offsets is not None:
        sensed = sensed - np.asarray(offsets, dtype=float)[:, None, :]
    expanded = None if conditions is None or conditions.expansion is None else RowConditions(conditions.expansion)
    points = np.atleast_2d(np.asarray(points, dtype=float))
    tool_rotations, tool_positions = corrections.tool_poses(chain, q)  # the joints bent by a lateral compliance
    world = points_in_base(tool_positions, tool_rotations, points)
    world = world if expanded is None else expanded.world(world)
    start = start_registration(world, sensed, tool_rotations @ np.asarray(rotation, dtype=float),
                               replace(data, points=sensed))
    cache = KinematicsCache(NoParameters(chain), np.array([], dtype=int), np.zeros(0), q, bends=corrections.bends)
    objective = SensorResidual(
        cache, sensed, data.rotations, TargetEstimate(start, points, np.asarray(rotation, dtype=float)),
        RowWeights(1.0 / sigma_pos_m, 1.0 / sigma_rot_rad), FittedBlocks(points=False, rotation=False),
        ModelledEffects(conditions=expanded),
    )
    solution = solve(objective, objective.start_vector(), what="session registration")
    return objective.estimate(solution.x).registration


def session_pose_errors(
    chain: KinematicChain,
    data: MeasurementSet,
    sessions: npt.ArrayLike,
    positions: Sequence[Registration],
    orientations: Sequence[Registration] | None = None,
    points: npt.ArrayLike | None = None,
    target_rotation: npt.ArrayLike | None = None,
    corrections: RowCorrections | None = None,
) -> PoseErrors:
    """Eq 24 on every row of ``data``, each through its session's registrations.

    Args:
        sessions: (K,) each row's index into ``positions`` / ``orientations``.
        positions / orientations: Registrations 1 and 2 of each session
            (``orientations`` default: ``positions``).
        points, target_rotation, corrections: as :func:`pincal.fit.metrics.pose_errors`.
    """
    orientations = positions if orientations is None else orientations
    corrections = RowCorrections() if corrections is None else corrections
    if len(positions) == 1:
        return pose_errors(chain, data, positions[0], orientations[0], points, target_rotation, corrections)
    sessions = np.asarray(sessions, dtype=np.intp)
    position = np.full((data.n_rows, 1 if points is None else np.atleast_2d(points).shape[0]), np.nan)
    rotation = None if data.rotations is None else np.full(data.n_rows, np.nan)
    for s, (reg_position, reg_orientation) in enumerate(zip(positions, orientations)):
        rows = np.flatnonzero(sessions == s)
        if rows.size:
            errors = pose_errors(chain, data.select(rows), reg_position, reg_orientation, points, target_rotation,
                                 corrections.select(rows))
            position[rows] = errors.position_m
            if rotation is not None:
                rotation[rows] = errors.rotation_rad
    return PoseErrors(position_m=position, rotation_rad=rotation)
