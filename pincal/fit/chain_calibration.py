"""Calibration of any serial chain from absolute measurements (points, rigid targets, poses).

Levels:

* ``registration`` — only the registration sensor_T_base and the target;
* ``offsets`` — plus each joint's zero (:class:`pincal.model.parameter_sets.JointOffsets`);
* ``full`` — plus each joint placement's SE(3) error (:class:`PlacementErrors`).

The registration and the target (its points in the tip frame, and its
rotation when orientations are measured) are always estimated with the
kinematics, unless a known tool is given. Parameters the data cannot determine
are never returned: :mod:`pincal.fit.identifiability` drops them by name, and the
number of weakly determined combinations kept is chosen by an information
criterion (AIC by default; BIC or leave-one-row-out cross-validation on
request) computed on the calibration rows only — never on validation data.
Rows whose residual is far outside the others (robust scale) are reported and,
only when asked, removed before a refit. After the registration, the steps are the one
pipeline of :mod:`pincal.fit.pipeline`, shared with socket-fixture rows; what is particular
to sensor rows is the residual (:mod:`pincal.residuals.sensor`), its noise scales per kind
(positions, orientations) and the target directions the data cannot place.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np

from pincal.errors import CalibrationError, did_you_mean, expect_value
from pincal.fit.identifiability import Ordering, Selection, condition_number, correlated_pairs
from pincal.fit.outliers import OutlierError, find_row_outliers
from pincal.fit.pipeline import Analysis, Dropped, dropped_parameters, fit_kinematics
from pincal.fit.prior import Prior, PriorResidual, data_rows
from pincal.fit.registration_hold import HeldRotation, hold_registration, rotation_reason
from pincal.fit.selection import SELECTION_CRITERIA, SelectionCriterion
from pincal.fit.sensor_problem import START_SIGMA_POS_M, START_SIGMA_ROT_RAD, FitProblem
from pincal.fit.sessions import by_orientation, check_registrable, initial_target, rows_at
from pincal.fit.target_hold import HeldDirection, analysis_jacobian, held_reason, hold_target, weak_target
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import CHAIN_LEVELS, LEVELS, ChainLevel, ChainParameters, NoParameters
from pincal.progress import Counter, Progress
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import FittedBlocks

__all__ = [
    "START_SIGMA_POS_M", "START_SIGMA_ROT_RAD", "ChainCalibration", "ChainFitOptions", "row_weights", "FitProblem",
    "calibrate_chain",
]



@dataclass(frozen=True)
class ChainCalibration:
    """Outcome of :func:`calibrate_chain`.

    Attributes:
        level: ``registration``, ``offsets`` or ``full``.
        params: the kinematic parameter set (None at level ``registration``).
        vector: calibrated kinematic parameters (zero = nominal), (n,).
        std: their standard deviations, NaN where not estimated, (n,).
        status: per kinematic parameter, :data:`pincal.fit.pipeline.KEPT` or a reason it is not.
        target: registration(s) (one per session), target points and rotation.
        target_std: standard deviations of the registrations (6 per session) and target parameters.
        sigma_pos_m / sigma_rot_rad: noise scales estimated from the residuals.
        rank, condition, selection, dropped, correlated: identifiability report.
        outliers: (file line, robust score) of rows flagged as outliers (:mod:`pincal.fit.outliers`).
        removed_lines: lines removed before the final fit (``reject_outliers``).
        rows_used: file lines of the rows in the final fit.
        fit_seconds: time of the final least-squares fit [s].
        total_seconds: time including selection [s].
        rms_m: RMS point residual of the final fit [m].
        notes: things the user should know.
        session_names: the sessions, in the order of ``target.registrations``.
        used_index: rows of the data given to :func:`calibrate_chain` in the final fit (indices).
        outlier_files / removed_files: the file of each outlier / removed row.
        outlier_by: the error that flags each outlier, ``position`` or ``orientation``.
        prior_sigma: with ``--select prior``, σ_i of every kinematic parameter of ``params`` in its
            own unit (m or rad) (:func:`pincal.fit.prior.prior_sigmas`), (n,); None without a prior.
        chain_placements: the calibrated chain's joint and tip placements (4×4 each, as
            :meth:`pincal.model.chain.KinematicChain.placements`): the model as a value, to evaluate
            with ``chain.placed(result.chain_placements)``.
        held / point_basis: the target directions held and the target points' free ones
            (:mod:`pincal.fit.target_hold`); held_rotations / registration_basis: the registration
            rotations held and the registrations' free unknowns (:mod:`pincal.fit.registration_hold`).
    """

    level: ChainLevel
    params: ChainParameters | None
    vector: np.ndarray
    std: np.ndarray
    status: tuple[str, ...]
    target: TargetEstimate
    target_std: np.ndarray
    sigma_pos_m: float
    sigma_rot_rad: float | None
    rank: int
    condition: float
    selection: Selection | None
    dropped: tuple[Dropped, ...]
    correlated: tuple[tuple[str, str, float], ...]
    outliers: tuple[tuple[int, float], ...]
    removed_lines: tuple[int, ...]
    rows_used: tuple[int, ...]
    fit_seconds: float
    total_seconds: float
    rms_m: float
    kept: np.ndarray = field(default_factory=lambda: np.array([], dtype=int))
    solution: np.ndarray = field(default_factory=lambda: np.array([]))
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    start: TargetEstimate | None = None
    fit_target: bool = True
    notes: tuple[str, ...] = field(default=())
    session_names: tuple[str, ...] = ()
    used_index: np.ndarray = field(default_factory=lambda: np.array([], dtype=int))
    outlier_files: tuple[str, ...] = ()
    removed_files: tuple[str, ...] = ()
    outlier_by: tuple[OutlierError, ...] = ()
    prior_sigma: np.ndarray | None = None
    held: tuple[HeldDirection, ...] = ()
    point_basis: np.ndarray | None = None
    chain_placements: tuple[np.ndarray, ...] = ()
    held_rotations: tuple[HeldRotation, ...] = ()
    registration_basis: np.ndarray | None = None

    def outlier_errors(self) -> tuple[OutlierError, ...]:
        """The error that flags each of :attr:`outliers`: :attr:`outlier_by`, or ``position`` for every one
        where it was not given."""
        position: OutlierError = "position"
        return self.outlier_by or tuple(position for _ in self.outliers)

    def predicted_point_rms(self, chain: KinematicChain, q: np.ndarray) -> float:
        """Linearised prediction of the RMS error of the target points at
        configurations ``q`` due to the parameters' estimation noise [m]
        (covariance of the fit propagated through the measurement Jacobian;
        with several sessions, in the first session's registration)."""
        params = self.params if self.params is not None else NoParameters(chain)
        k, n_points = len(q), len(self.target.points)
        cache = KinematicsCache(params, self.kept, self.vector, q)
        assert self.start is not None  # calibrate_chain always sets it
        objective = SensorResidual(
            cache,
            np.zeros((k, n_points, 3)),
            np.tile(np.eye(3), (k, 1, 1)) if self.sigma_rot_rad is not None else None,
            self.start,
            fitted=FittedBlocks(points=self.fit_target, rotation=self.fit_target, point_basis=self.point_basis,
                                registration_basis=self.registration_basis),
            sessions=np.zeros(k, dtype=int),
        )
        jac = objective.jacobian(self.solution)[: 3 * k * n_points]
        variance = np.einsum("ij,jk,ik->i", jac, self.covariance, jac)
        return float(np.sqrt(variance.sum() / (k * n_points)))


def row_weights(data: MeasurementSet, sigma_column: str | None) -> np.ndarray:
    """Relative row weights from a per-row noise column (median 1), or ones."""
    if sigma_column is None:
        return np.ones(data.n_rows)
    if sigma_column in data.dropped_extra:  # in some of the session files only
        lacking = data.dropped_extra[sigma_column]
        raise CalibrationError(
            f"{', '.join(lacking)}: no column '{sigma_column}' for --sigma-column, which the other session file(s) "
            f"have; add it to {'this file' if len(lacking) == 1 else 'these files'}, or leave out --sigma-column"
        )
    if sigma_column not in data.extra:
        raise CalibrationError(
            f"{data.source}: no column '{sigma_column}' for --sigma-column; "
            f"{did_you_mean(sigma_column, data.extra, 'numeric extra columns')}"
        )
    sigma = np.asarray(data.extra[sigma_column], dtype=float)
    bad = ~(np.isfinite(sigma) & (sigma > 0))
    if np.any(bad):
        line = int(data.lines[np.flatnonzero(bad)[0]])
        raise CalibrationError(
            f"{data.source}, line {line}, column '{sigma_column}': sigma must be a positive number [mm]"
        )
    relative = sigma / np.median(sigma)
    return 1.0 / relative


@dataclass(frozen=True)
class ChainFitOptions:
    """How :func:`calibrate_chain` fits (and :func:`pincal.fit.level_choice.choose_level` each level): a value.

    Attributes:
        tool_known: the chain's tool is the measured point (and frame) and is not estimated;
            otherwise the target points are estimated in the tool frame.
        sigma_column: extra column holding a per-row noise scale [mm] (weights).
        reject_outliers: refit without the rows flagged as outliers.
        sigma_iterations: refits re-estimating the position/orientation noise scales (with a
            prior: up to eq P2's fixed point instead, :data:`pincal.fit.prior.MAX_SCALE_ITERATIONS`).
        selection: criterion choosing how many identifiable parameters to keep
            (:data:`SELECTION_CRITERIA`); ``"prior"`` (or a :class:`pincal.fit.prior.Prior`
            with its scales) keeps all of them in a MAP fit.
        refit_offered: whether the caller can refit without outliers (``calibrate --reject-outliers``);
            else (``diagnose``) the outlier note says to check the rows instead.
    """

    tool_known: bool = False
    sigma_column: str | None = None
    reject_outliers: bool = False
    sigma_iterations: int = 2
    selection: SelectionCriterion | Prior = "aic"
    refit_offered: bool = True


def calibrate_chain(chain: KinematicChain, data: MeasurementSet, level: ChainLevel,
                    options: ChainFitOptions = ChainFitOptions(), progress: Progress | None = None
                    ) -> ChainCalibration:
    """Calibrate ``chain`` at ``level`` on the non-validation rows of ``data``.

    Args:
        chain: the chain; its tool is the target frame (see :attr:`ChainFitOptions.tool_known`).
        data: measurements (rows with role ``validation`` are not used).
        level: one of :data:`CHAIN_LEVELS`.
        options: how to fit (:class:`ChainFitOptions`; default: AIC, two noise-scale refits).
        progress: ``progress(done, total)`` after the registration, each subset scored, the fit.

    The chain is not changed: the calibrated model is the result's ``chain_placements`` (evaluate
    it with ``chain.placed(result.chain_placements)``).
    """
    if level not in CHAIN_LEVELS:
        raise CalibrationError(f"level must be one of {CHAIN_LEVELS}, got '{level}'")
    expect_value(options, ChainFitOptions, "calibrate_chain")
    if options.selection not in SELECTION_CRITERIA:
        raise CalibrationError(f"selection must be one of {tuple(SELECTION_CRITERIA)}, got '{options.selection}'")
    started = time.perf_counter()
    index = np.flatnonzero(data.roles != "validation")  # rows of ``data`` in the fit
    rows = data.select(index)
    if rows.n_rows < 3:
        raise CalibrationError(
            f"{data.source}: {rows.n_rows} calibration row(s) (rows with role 'validation' are not used); "
            "a calibration needs at least 3"
        )
    if options.tool_known and rows.n_points != 1:
        raise CalibrationError(
            f"{data.source}: a known --tool is one point; this file has {rows.n_points} points "
            "per row — leave out --tool to estimate the target's points"
        )
    check_registrable(rows)
    params = LEVELS[level](chain) if level in LEVELS else None
    notes: list[str] = []
    flagged: list[int] = []  # outlier rows, as indices into ``data``
    removed: list[int] = []
    counter = Counter(progress)
    for attempt in range(2):
        result, point_errors, rotation_errors = _calibrate_rows(chain, params, rows, level, options, counter)
        outliers = find_row_outliers(point_errors, index, rotation_errors)  # rows of ``data``
        flagged = [o.row for o in outliers]
        if not (options.reject_outliers and outliers and attempt == 0):
            break
        removed = flagged
        keep = ~np.isin(index, removed)
        index, rows = index[keep], rows.select(keep)
        check_registrable(rows)
        notes.append(f"removed {len(removed)} outlier row(s) at {rows_at(data, removed)}"
                     f"{by_orientation(data, outliers)} and refitted")
    if flagged and not removed:
        notes.append(
            f"{len(flagged)} row(s) look like outliers ({rows_at(data, flagged)}{by_orientation(data, outliers)}); "
            + ("rerun with --reject-outliers to refit without them" if options.refit_offered else
               "they stay in the fit: check them and remove the bad ones from the file (an effect found "
               "later may explain the others)")
        )
    if result.held:
        notes.append(f"target not determined: {held_reason(result.held)}")
    notes.extend(f"registration not determined: {rotation_reason(h)}" for h in result.held_rotations)
    if result.selection is not None:
        notes.extend(result.selection.notes)
    counter.settle()
    return replace(
        result, rows_used=tuple(int(line) for line in rows.lines), used_index=index,
        total_seconds=time.perf_counter() - started, notes=tuple(notes),
        outliers=tuple((int(data.lines[o.row]), o.score) for o in outliers), outlier_files=tuple(data.files[flagged]),
        outlier_by=tuple(o.by for o in outliers),
        removed_lines=tuple(int(data.lines[k]) for k in removed), removed_files=tuple(data.files[removed]),
    )


def _calibrate_rows(chain: KinematicChain, params: ChainParameters | None, rows: MeasurementSet, level: ChainLevel,
                    options: ChainFitOptions, counter: Counter, hold: tuple[HeldDirection, ...] = ()
                    ) -> tuple[ChainCalibration, np.ndarray, np.ndarray | None]:
    """One calibration of ``rows``; returns the result (without the outlier
    bookkeeping), each target point's distance from the model (K, P) [m] and, with
    orientations, each row's orientation error (K,) [rad] (else None).
    ``counter`` counts the registration fits, each subset scored and the final fits as one each.
    ``hold``: target directions to hold besides those the rows leave free (:mod:`pincal.fit.target_hold`);
    a calibration whose target comes out weakly determined is done again with those held."""
    tool_known = options.tool_known
    nominal = chain.placements()
    start = initial_target(chain, rows, fit_points=not tool_known)
    if tool_known:
        start = replace(start, points=np.zeros((1, 3)), rotation=np.eye(3))
    problem = FitProblem(chain, params, rows, start, fit_target=not tool_known,
                         row_weight=row_weights(rows, options.sigma_column))
    held: tuple[HeldDirection, ...] = ()
    if not tool_known:
        held, problem = hold_target(problem, extra=hold)
    # with the target held: what is left free is the registration's
    rotations, problem = hold_registration(problem)
    size = params.size if params is not None else 0
    base = np.zeros(size)
    empty = np.array([], dtype=int)
    # registration and target first, with the nominal kinematics
    counter.expect(2)
    objective, solution = problem.fit(empty, base, what="registration")
    if size and solution.residual.size <= solution.x.size:
        raise CalibrationError(
            f"{rows.source}: {rows.n_rows} calibration row(s) give {solution.residual.size} measured coordinates and "
            f"the registration and target alone take {solution.x.size}: none is left for the kinematics; "
            "add calibration rows"
        )
    for _ in range(options.sigma_iterations):
        problem = problem.rescaled(objective, solution)
        objective, solution = problem.fit(empty, base, solution.x, what="registration")
    counter.tick()
    problem = replace(problem, start=objective.estimate(solution.x))
    analysis: Analysis | None = None
    dropped: tuple[Dropped, ...] = ()
    if size:
        full = problem.objective(np.arange(size), base)
        kinematic_cols = np.arange(full.blocks["kinematic"].start, full.blocks["kinematic"].stop)
        other_cols = np.setdiff1d(np.arange(full.n_params), kinematic_cols)
        # a held target direction is not estimated, and neither is what only it would explain
        # (the tip placement's translation): its columns join the always-estimated ones here
        jac, held_cols = analysis_jacobian(problem, held, size)
        analysis = Analysis(np.hstack([jac, held_cols]), kinematic_cols,
                            np.concatenate([other_cols, full.n_params + np.arange(held_cols.shape[1])]))
    fit = fit_kinematics(problem, analysis, rows, options.selection, level, options.sigma_iterations, counter)
    problem = cast(FitProblem, fit.problem)  # at the scales and prior the final fit was made with
    if analysis is not None:  # what absorbs a dropped parameter: the model as it is, the target where it is
        real = jac if rows.rotations is None else full.jacobian(full.start_vector())
        dropped = dropped_parameters(real, cast(Ordering, fit.ordering), fit.kept, other_cols,
                                     _column_names(full, params, np.arange(size), problem.session_names))
    objective, solution, kept, covariance = fit.objective, fit.solution, fit.kept, fit.covariance
    x = solution.x
    names = _column_names(objective, params, kept, problem.session_names)
    correlated = tuple((names[a], names[b], c) for a, b, c in correlated_pairs(covariance))
    k, p = rows.n_rows, rows.n_points
    point_residual = (solution.residual[: 3 * k * p].reshape(k, p, 3) * problem.sigma_pos
                      / problem.row_weight[:, None, None])
    point_errors = np.linalg.norm(point_residual, axis=2)
    rotation_errors = None if problem.sigma_rot is None else np.linalg.norm(  # the angle of log(E_k)
        solution.residual[3 * k * p: 3 * k * (p + 1)].reshape(k, 3), axis=1) * problem.sigma_rot / problem.row_weight
    result = ChainCalibration(
        level=level,
        params=params,
        vector=fit.vector,
        std=fit.std,
        status=fit.status,
        target=objective.estimate(x),
        target_std=fit.std_all[len(kept):],
        sigma_pos_m=problem.sigma_pos,
        sigma_rot_rad=problem.sigma_rot,
        rank=fit.rank,
        condition=condition_number(data_rows(solution.jacobian, objective)),  # the data's, not the prior rows'
        selection=fit.selection,
        dropped=dropped,
        correlated=correlated,
        outliers=(),
        removed_lines=(),
        rows_used=tuple(int(line) for line in rows.lines),
        fit_seconds=fit.fit_seconds,
        total_seconds=0.0,
        rms_m=float(np.sqrt(np.mean(np.sum(point_residual**2, axis=2)))),
        kept=kept,
        solution=x,
        covariance=covariance,
        start=problem.start,
        fit_target=not tool_known,
        session_names=problem.session_names,
        prior_sigma=problem.prior,
        held=held,
        point_basis=problem.point_basis,
        chain_placements=tuple(params.placements(fit.vector)) if params is not None and size else tuple(nominal),
        held_rotations=rotations,
        registration_basis=problem.registration_basis,
    )
    weak = () if tool_known or hold else weak_target(problem, kept, covariance)
    if weak:  # the kinematics took what the target was left to explain: again, with it held
        return _calibrate_rows(chain, params, rows, level, options, counter, hold=weak)
    return result, point_errors, rotation_errors


def _column_names(objective: SensorResidual | PriorResidual, params: ChainParameters | None, kept: np.ndarray,
                  sessions: Sequence[str] = ()) -> list[str]:
    names = [params.info[i].name for i in kept] if params is not None else []
    if objective.registration_basis is not None:  # the free unknowns of a held rotation (registration_hold)
        names += [f"registration.free{i + 1}" for i in range(objective.registration_basis.shape[1])]
    elif objective.blocks["registration"].stop > objective.blocks["registration"].start:
        prefixes = ["registration"] if objective.n_sessions == 1 else [f"registration[{n}]" for n in sessions]
        names += [f"{prefix}.{axis}" for prefix in prefixes for axis in ("rx", "ry", "rz", "x", "y", "z")]
    pts = objective.blocks["points"]
    if objective.point_basis is None:
        names += [f"target.point{i // 3 + 1}.{'xyz'[i % 3]}" for i in range(pts.stop - pts.start)]
    else:  # the free directions of a held target (pincal.fit.target_hold)
        names += [f"target.points.free{i + 1}" for i in range(pts.stop - pts.start)]
    rot = objective.blocks["rotation"]
    names += [f"target.r{'xyz'[i]}" for i in range(rot.stop - rot.start)]
    return names
