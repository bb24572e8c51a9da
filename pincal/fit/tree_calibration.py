"""Calibration of several targets on the chains of a tree, in one fit (two arms on one torso).

The rows measure P points per configuration (``x1,y1,z1 ...``); each point is carried by one
target's tip link (:class:`pincal.model.tree.KinematicTree`), an empty cell is a point not seen
in that row. The unknowns are those of :func:`pincal.fit.chain_calibration.calibrate_chain` over
the whole tree: one registration per session shared by every target, each point in its tip
link, and the tree's parameters (:class:`pincal.model.tree_parameters.TreeParameters`; a joint
shared by several chains is one set of parameters, fitted once). After the registration, the
steps are the one pipeline of :mod:`pincal.fit.pipeline` — identifiability ordered on the whole
tree's Jacobian, the selection, the refits, the prior — on :class:`pincal.fit.tree_problem.TreeProblem`.
A target whose orientation is measured (``qxN,qyN,qzN,qwN``, N one of its points:
:mod:`pincal.measurements.target_orientations`) adds its frame's rotation in its tip link to the
unknowns and its orientation residuals to the rows, weighted by the orientation noise scale as one
chain's are.

Outliers as one chain's (:mod:`pincal.fit.outliers`: each row's position error the RMS distance of its seen points,
its orientation error the RMS angle of its targets' measured orientations): noted, or with ``reject_outliers``
removed and the rows refitted once. Not yet: orientation columns without a
number (``qx,qy,qz,qw``: whose?), a known tool, ``--select press`` (leave-one-row-out over rows of different
sizes), the target and registration holds of :mod:`pincal.fit.target_hold` and
:mod:`pincal.fit.registration_hold` (refused or noted, never silently different).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np

from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainFitOptions, row_weights
from pincal.fit.identifiability import Ordering, Selection, condition_number, correlated_pairs
from pincal.fit.outliers import find_row_outliers
from pincal.fit.pipeline import Analysis, Dropped, dropped_parameters, fit_kinematics
from pincal.fit.prior import PriorResidual, data_rows
from pincal.fit.problem import KindProblem
from pincal.fit.registration import mean_rotation, register_points
from pincal.fit.sessions import by_orientation, registration_problem, rows_at, where
from pincal.fit.tree_problem import TreeProblem, registration_fit
from pincal.measurements.data import MeasurementSet
from pincal.measurements.target_orientations import target_quat_columns
from pincal.model.parameter_sets import CHAIN_LEVELS, ChainLevel, ParameterLevel
from pincal.model.sensor import Registration
from pincal.model.tree import KinematicTree, TreePlacements
from pincal.model.tree_parameters import TreeParameters
from pincal.progress import Counter, Progress
from pincal.residuals.sensor import TargetEstimate
from pincal.residuals.sensor_values import RowWeights
from pincal.residuals.tree import TreeResidual, TreeRows

__all__ = ["TreeCalibration", "calibrate_tree", "tree_rows", "initial_tree_target"]


@dataclass(frozen=True)
class TreeCalibration:
    """Outcome of :func:`calibrate_tree`.

    Attributes:
        level: ``registration``, ``offsets`` or ``full``.
        params: the tree's parameters (None at level ``registration``).
        vector / std: every tree parameter's value [m, rad] (zero: nominal, and where not kept) and its
            standard deviation (NaN where not estimated), (n,).
        status: per tree parameter, :data:`pincal.fit.pipeline.KEPT` or why it is not.
        target: the registrations (one per session), every point (P, 3) in its own tip link [m] and each target's
            frame rotation in its tip link (T, 3, 3) (the identity for a target without orientation).
        sigma_pos_m: the position noise scale estimated from the residuals [m].
        rank, condition, selection, dropped, correlated: the identifiability of the whole tree.
        point_errors: each calibration row's distance of each point from the model [m], NaN where not seen (K, P).
        session_names: the sessions, in the order of ``target.registrations``.
        row_sessions: each calibration row's session, an index into them (K,).
        used_index: the rows of the data in the fit (indices).
        tree_placements: each target's calibrated chain placements: the model as a value
            (``tree.placed(result.tree_placements)``).
        notes: what the user should know.
        total_seconds: the calibration's time [s].
        prior_sigma: σ_i of every tree parameter under ``--select prior`` (eq P1), None otherwise: the prior
            ``diagnose`` keeps on the geometry.
        kept: the tree parameters the fit had free (indices, sorted): those ``calibrated`` and, under a prior,
            those it holds near nominal (``status`` says which); the geometry ``diagnose`` refits; the kinematic
            columns of ``covariance``.
        covariance: of the fit's unknowns — the kept parameters, the registrations, the points, the targets'
            rotations — as the fit gives it (with a prior: the posterior) [m², rad², m·rad]; None: not known (a
            result made elsewhere).
        sigma_rot_rad: the orientation noise scale estimated from the residuals [rad]; None without orientations.
        orientation_errors: each calibration row's orientation error of each target [rad], NaN where not seen
            (K, T); None when no target's orientation is measured.
    """

    level: ChainLevel
    params: TreeParameters | None
    vector: np.ndarray
    std: np.ndarray
    status: tuple[str, ...]
    target: TargetEstimate
    sigma_pos_m: float
    rank: int
    condition: float
    selection: Selection | None
    dropped: tuple[Dropped, ...]
    correlated: tuple[tuple[str, str, float], ...]
    point_errors: np.ndarray
    session_names: tuple[str, ...]
    row_sessions: np.ndarray
    used_index: np.ndarray
    tree_placements: TreePlacements
    notes: tuple[str, ...]
    total_seconds: float
    prior_sigma: np.ndarray | None = None
    kept: np.ndarray = field(default_factory=lambda: np.array([], dtype=np.intp))
    covariance: np.ndarray | None = None
    sigma_rot_rad: float | None = None
    orientation_errors: np.ndarray | None = None

    @property
    def rms_m(self) -> float:
        """RMS distance of the seen points from the model [m]."""
        seen = self.point_errors[np.isfinite(self.point_errors)]
        return float(np.sqrt(np.mean(seen**2)))

    def predicted_point_rms(self, tree: KinematicTree, q: np.ndarray) -> float:
        """Linearised prediction of the RMS error of every target point at tree joint readings ``q`` (K, N) due to
        the estimation noise of the fit [m]: ``covariance`` propagated through the measurement Jacobian at the
        calibrated model, in the first session's registration (as
        :meth:`pincal.fit.chain_calibration.ChainCalibration.predicted_point_rms` for one chain)."""
        if self.covariance is None:
            return 0.0
        k, n_points = len(q), len(self.target.points)
        turns = None  # the oriented targets' rows: their rotation unknowns are columns of the covariance
        if self.orientation_errors is not None:
            oriented = np.any(np.isfinite(self.orientation_errors), axis=0)
            turns = np.broadcast_to(oriented, (k, oriented.size))
        rows = TreeRows(np.asarray(q, dtype=float), np.zeros((k, n_points, 3)), np.ones((k, n_points), dtype=bool),
                        np.zeros(k, dtype=np.intp), None if turns is None else np.tile(np.eye(3), (k, turns.shape[1],
                                                                                                   1, 1)), turns)
        objective = TreeResidual(tree, self.params, self.kept, self.vector, rows, self.target, RowWeights(np.ones(k)))
        jac = objective.jacobian(objective.start_vector())[: objective.n_positions]  # at the calibrated model
        variance = np.einsum("ij,jk,ik->i", jac, self.covariance, jac)
        return float(np.sqrt(variance.sum() / (k * n_points)))


def tree_rows(tree: KinematicTree, data: MeasurementSet, sessions: np.ndarray | None = None) -> TreeRows:
    """The rows of ``data`` as a tree residual reads them (``sessions``: each row's registration; default:
    its session's index in ``data``).

    Raises:
        CalibrationError: orientation columns without a number (whose?), a file's points that are not the targets'
            (naming both), a point with one or two of its three cells empty (naming the file and line), an
            orientation numbered with no target's point, or two for one target.
    """
    if data.rotations is not None:
        raise CalibrationError(f"{data.source}: orientation columns qx,qy,qz,qw name no target with several "
                               "--tip-link; give each target's as qxN,qyN,qzN,qwN, N one of its points (the point "
                               "xN,yN,zN its tracker reports with it)")
    numbers = sorted(p for t in tree.targets for p in t.spec.points)
    if numbers != list(range(1, data.n_points + 1)):
        raise CalibrationError(f"{data.source}: {data.n_points} measured point(s) per row, the --tip-link values "
                               f"name point(s) {', '.join(map(str, numbers))}; give each point 1..{data.n_points} "
                               "to one --tip-link LINK:POINTS")
    seen = np.all(np.isfinite(data.points), axis=2)
    partial = np.flatnonzero((np.any(np.isfinite(data.points), axis=2) & ~seen).ravel())
    if partial.size:
        k, p = divmod(int(partial[0]), data.n_points)
        raise CalibrationError(f"{data.files[k]}, line {int(data.lines[k])}: point {p + 1} has some of "
                               f"x{p + 1},y{p + 1},z{p + 1} empty; leave all three empty (not seen in this row) or "
                               "give all three")
    return TreeRows(data.q, data.points, seen, data.session_index if sessions is None else sessions,
                    *_target_turns(tree, data))


def _target_turns(tree: KinematicTree, data: MeasurementSet) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Each target's measured orientation (K, T, 3, 3) (the identity where not seen) and where it was seen (K, T)
    from ``data``'s ``qxN,qyN,qzN,qwN`` (N one of the target's points); (None, None) without them."""
    if not data.target_rotations:
        return None, None
    k, owner = data.n_rows, {p: t for t, target in enumerate(tree.targets) for p in target.spec.points}
    turns, seen = np.tile(np.eye(3), (k, len(tree.targets), 1, 1)), np.zeros((k, len(tree.targets)), dtype=bool)
    given: dict[int, int] = {}
    for number, rotations in sorted(data.target_rotations.items()):
        columns = ",".join(target_quat_columns(number))
        if number not in owner:
            raise CalibrationError(f"{data.source}: columns {columns}: there is no point {number} (the targets carry "
                                   f"points 1..{data.n_points}); number a target's orientation with one of its points")
        t = owner[number]
        if t in given:
            raise CalibrationError(f"{data.source}: columns {','.join(target_quat_columns(given[t]))} and {columns} "
                                   f"are both the orientation of {tree.targets[t].link} (points "
                                   f"{','.join(map(str, tree.targets[t].spec.points))}); a target has one, its link's: "
                                   "give one group of columns per target")
        given[t] = number
        seen[:, t] = np.all(np.isfinite(rotations), axis=(1, 2))
        turns[seen[:, t], t] = rotations[seen[:, t]]
    return turns, seen


def initial_tree_target(tree: KinematicTree, data: MeasurementSet, rows: TreeRows, iterations: int = 10
                        ) -> TargetEstimate:
    """Registrations (one per session, Arun et al. 1987 on the seen points) and the points in their tip links
    from the nominal model, alternated ``iterations`` times as :func:`pincal.fit.sessions.initial_target`.

    Raises:
        CalibrationError: a session whose seen points cannot fix a registration (:func:`registration_problem`).
    """
    poses = [t.chain.tool_poses(rows.q[:, t.columns]) for t in tree.targets]
    owner = np.empty(rows.seen.shape[1], dtype=np.intp)
    for t, target in enumerate(tree.targets):
        owner[np.array(target.spec.points) - 1] = t
    groups = [np.flatnonzero(rows.sessions == s) for s in range(len(data.session_names))]
    for name, group in zip(data.session_names, groups):
        problem = registration_problem(rows.points[group][rows.seen[group]], group.size, False)
        if problem:
            raise CalibrationError(f"{where(data, name)}: {problem}")
    points = np.zeros((rows.seen.shape[1], 3))
    registrations: list[Registration] = []
    for _ in range(iterations):
        world = np.stack([poses[owner[p]][1] + poses[owner[p]][0] @ points[p] for p in range(owner.size)], axis=1)
        registrations = [register_points(world[group][rows.seen[group]], rows.points[group][rows.seen[group]])
                         for group in groups]
        omega = np.stack([r.rotation for r in registrations])[rows.sessions]  # (K, 3, 3)
        tau = np.stack([r.translation for r in registrations])[rows.sessions]
        local = np.einsum("kji,kpj->kpi", omega, rows.points - tau[:, None, :])  # Ωᵀ(g − τ), base frame
        for p, carrier in enumerate(owner):
            rotations, positions = poses[carrier]
            mine = np.einsum("kji,kj->ki", rotations, local[:, p] - positions)
            points[p] = mine[rows.seen[:, p]].mean(axis=0)
    rotations = np.tile(np.eye(3), (len(tree.targets), 1, 1))
    for t in rows.oriented():  # R_T,t the mean of R_ktᵀ Omega_sᵀ G_kt over its seen rows (Moakher 2002)
        assert rows.rotations is not None and rows.rotation_seen is not None  # oriented: both given
        seen = rows.rotation_seen[:, t]
        omega = np.stack([r.rotation for r in registrations])[rows.sessions[seen]]
        turned = poses[t][0][seen].transpose(0, 2, 1) @ omega.transpose(0, 2, 1) @ rows.rotations[seen, t]
        rotations[t] = mean_rotation(turned)
    return TargetEstimate(registrations[0], points, rotations, tuple(registrations))


def calibrate_tree(tree: KinematicTree, data: MeasurementSet, level: ChainLevel,
                   options: ChainFitOptions | None = None, progress: Progress | None = None) -> TreeCalibration:
    """Calibrate ``tree`` at ``level`` on the non-validation rows of ``data`` (module docstring).

    The tree is not changed: the calibrated model is the result's ``tree_placements``.

    Raises:
        CalibrationError: a level, option or data the tree calibration does not take yet (one line each), too
            few rows, or a session that cannot be registered.
    """
    if level not in CHAIN_LEVELS:
        raise CalibrationError(f"level must be one of {CHAIN_LEVELS}, got '{level}'")
    options = ChainFitOptions() if options is None else options
    for refused, flag, instead in (
            (options.tool_known, "a known --tool", "leave it out: each target's points are estimated"),
            (options.selection == "press", "--select press", "use aic, bic, all or prior")):
        if refused:
            raise CalibrationError(f"several --tip-link: {flag} is not yet supported; {instead}")
    started = time.perf_counter()
    index = np.flatnonzero(data.roles != "validation")
    notes: list[str] = []
    flagged: list[int] = []  # outlier rows, as indices into ``data``
    removed: list[int] = []
    counter = Counter(progress)
    for attempt in range(2):  # as one chain's (pincal.fit.chain_calibration): a row's errors the RMS of its points
        result = _calibrate_tree_rows(tree, data, index, level, options, counter)  # and of its targets' angles
        points = _row_rms(result.point_errors)  # NaN: a row none of whose points was seen
        turns = None if result.orientation_errors is None else _row_rms(result.orientation_errors)
        seen = np.isfinite(points) if turns is None else np.isfinite(points) | np.isfinite(turns)  # or one angle
        outliers = find_row_outliers(points[seen, None], index[seen], None if turns is None else turns[seen])
        flagged = [o.row for o in outliers]
        if not (options.reject_outliers and flagged and attempt == 0):
            break
        removed = flagged
        index = index[~np.isin(index, removed)]
        notes.append(f"removed {len(removed)} outlier row(s) at {rows_at(data, removed)}"
                     f"{by_orientation(data, outliers)} and refitted")
    if flagged and not removed:
        notes.append(f"{len(flagged)} row(s) look like outliers ({rows_at(data, flagged)}"
                     + by_orientation(data, outliers) + "); "
                     + ("rerun with --reject-outliers to refit without them" if options.refit_offered else
                        "they stay in the fit: check them and remove the bad ones from the file"))
    return replace(result, notes=result.notes + tuple(notes), total_seconds=time.perf_counter() - started)


def _row_rms(errors: np.ndarray) -> np.ndarray:
    """Each row's RMS over its seen entries (K, N) — points' distances [m], targets' angles [rad] —, NaN for a
    row that sees none, (K,)."""
    out = np.full(len(errors), np.nan)
    seen = np.isfinite(errors).any(axis=1)
    out[seen] = np.sqrt(np.nanmean(errors[seen] ** 2, axis=1))
    return out


def _calibrate_tree_rows(tree: KinematicTree, data: MeasurementSet, index: np.ndarray, level: ChainLevel,
                         options: ChainFitOptions, counter: Counter) -> TreeCalibration:
    """One calibration of the rows ``index`` of ``data`` (:func:`calibrate_tree`'s, without the outlier step)."""
    started = time.perf_counter()
    used = data.select(index)
    if used.n_rows < 3:
        raise CalibrationError(f"{data.source}: {used.n_rows} calibration row(s) (rows with role 'validation' are "
                               "not used); a calibration needs at least 3")
    rows = tree_rows(tree, used)
    never = np.flatnonzero(~rows.seen.any(axis=0))
    if never.size:
        raise CalibrationError(f"{data.source}: point {never[0] + 1} is not seen in any calibration row (every cell of "
                               f"x{never[0] + 1},y{never[0] + 1},z{never[0] + 1} empty): nothing places it; give its "
                               "measurements or leave its --tip-link out")
    start = initial_tree_target(tree, used, rows)
    params = TreeParameters(tree, cast(ParameterLevel, level)) if level != "registration" else None
    size = 0 if params is None else int(params.size)
    counter.expect(1)
    problem = TreeProblem(tree, params, rows, start, row_weights(used, options.sigma_column), used.session_names)
    problem, _ = registration_fit(problem, size, options.sigma_iterations)
    counter.tick()
    observed, _ = np.nonzero(rows.seen)
    analysis, full, other = None, None, np.array([], dtype=int)
    if size:
        full = cast(TreeResidual, problem.objective(np.arange(size), np.zeros(size)))
        kinematic = np.arange(full.blocks["kinematic"].start, full.blocks["kinematic"].stop)
        other = np.setdiff1d(np.arange(full.n_params), kinematic)
        analysis = Analysis(full.jacobian(full.start_vector()), kinematic, other)
    # the selection counts the residual's entries in blocks of 3 per (row, point) seen
    pairs = used.select(np.concatenate([observed, np.nonzero(problem.orientation_seen())[0]]))  # an orientation: 3 too
    sensed = np.concatenate([rows.points[rows.seen], np.zeros((pairs.n_rows - observed.size, 3))])
    pairs = MeasurementSet(pairs.joint_names, pairs.q, sensed[:, None, :], None, pairs.roles,
                           pairs.lines, source=used.source, sessions=pairs.sessions, files=pairs.files)
    # TreeParameters has what the pipeline reads of a chain's parameter set (size, info, slots, chain)
    kind = cast("KindProblem[TreeResidual | PriorResidual]", problem)
    fit = fit_kinematics(kind, analysis, pairs, options.selection, level, options.sigma_iterations, counter)
    problem = cast(TreeProblem, fit.problem)
    objective = fit.objective
    tree_objective = cast(TreeResidual, getattr(objective, "objective", objective))
    names = [] if params is None else [i.name for i in params.info]
    names += [f"registration{'' if len(used.session_names) == 1 else f'[{n}]'}.{a}"
              for n in used.session_names for a in ("rx", "ry", "rz", "x", "y", "z")]
    names += [f"target.point{p + 1}.{a}" for p in range(rows.seen.shape[1]) for a in "xyz"]
    names += [f"target.{tree.targets[t].link}.r{a}" for t in rows.oriented() for a in "xyz"]
    columns = [names[i] for i in fit.kept] + names[size:]  # the fit's: the kept parameters, then the others
    dropped: tuple[Dropped, ...] = ()
    if analysis is not None and fit.ordering is not None:
        dropped = dropped_parameters(analysis.jacobian, cast(Ordering, fit.ordering), fit.kept, other, names)
    weights = problem.row_weight / problem.sigma_pos
    counter.settle()
    notes = [] if fit.selection is None else list(fit.selection.notes)
    return TreeCalibration(
        level=level, params=params, vector=fit.vector, std=fit.std, status=fit.status,
        target=tree_objective.estimate(fit.solution.x), sigma_pos_m=problem.sigma_pos, rank=fit.rank,
        condition=condition_number(data_rows(fit.solution.jacobian, objective)), selection=fit.selection,
        dropped=dropped, correlated=tuple((columns[a], columns[b], c) for a, b, c in correlated_pairs(fit.covariance)),
        row_sessions=rows.sessions, point_errors=tree_objective.point_errors(fit.solution.x, weights),
        session_names=used.session_names, used_index=index,
        tree_placements=params.placements(fit.vector) if params is not None else tree.placements(),
        notes=tuple(notes), total_seconds=time.perf_counter() - started, prior_sigma=problem.prior,
        kept=np.sort(np.asarray(fit.kept, dtype=np.intp)), covariance=fit.covariance, sigma_rot_rad=problem.sigma_rot,
        orientation_errors=None if problem.sigma_rot is None else tree_objective.orientation_errors(
            fit.solution.x, problem.row_weight / problem.sigma_rot))
