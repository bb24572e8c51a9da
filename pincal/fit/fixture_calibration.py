"""Calibration of a serial chain from a ball seated in fixture sockets (no external sensor).

The model is eq F1 of :mod:`pincal.residuals.fixture`: one kinematic model
(levels ``registration``, ``offsets``, ``full`` of
:mod:`pincal.fit.chain_calibration`), one ball centre m in the tip frame, and
one pose of the fixture per placement, of which only what the placement's
sockets determine is estimated (two sockets: the position and the direction
of their line, never the turn about it).

The start comes from the nominal model by linear least squares: every row of
socket i in placement s satisfies t_k + R_k m = p_si, linear in m and the socket
centres p_si (pivot calibration); each placement's pose then maps the
fixture's sockets onto its p_si (Arun et al. 1987 for sockets spanning a plane,
the shortest turn of the socket line onto the measured one for collinear
sockets). The fit with the nominal kinematics (level ``registration``) is the
"before" of a calibration. From there the calibration is the one pipeline of
:mod:`pincal.fit.pipeline`, as for sensor data: which kinematic parameters the data
determine, how many weak ones to keep (AIC by default), the fit and its covariance, on
the calibration placements only.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import cast

import numpy as np
import pinocchio as pin

from pincal.errors import CalibrationError
from pincal.fit.identifiability import Ordering, Selection, condition_number, correlated_pairs
from pincal.fit.outliers import find_outliers
from pincal.fit.pipeline import Analysis, Dropped, dropped_parameters, fit_kinematics
from pincal.fit.prior import SCALE_FLOOR, Prior, PriorResidual, data_rows, effective_scale, hat_diagonal, log_evidence
from pincal.fit.registration import register_points
from pincal.fit.selection import SELECTION_CRITERIA, SelectionCriterion
from pincal.fit.socket_metrics import FixtureMetrics, metrics_of_positions
from pincal.fit.solver import Solution, solve
from pincal.measurements.data import MeasurementSet
from pincal.measurements.fixture import FixtureData
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import CHAIN_LEVELS, LEVELS, ChainLevel, ChainParameters, NoParameters
from pincal.model.sensitivity import ParameterSlot, SensitivityModel
from pincal.residuals.base import KinematicsCache
from pincal.residuals.fixture import FixtureEstimate, FixtureResidual, rotation_basis

__all__ = [
    "DEPENDENT_COLUMNS", "PlacementEstimate", "FixtureCalibration", "initial_fixture", "FixtureProblem",
    "calibrate_fixture", "column_names",
]

#: Columns whose smallest singular value (unit columns) is below this fraction of the largest are dependent.
DEPENDENT_COLUMNS = 1e-8


@dataclass(frozen=True)
class PlacementEstimate:
    """What the data determine of one placement's pose, in the URDF root frame.

    Attributes:
        name: the placement.
        rows: its rows in the fit.
        sockets: names of the sockets it used.
        socket_positions: their centres c_s + R_s f_i [m], (M_s, 3).
        socket_std: standard deviations of those [m], (M_s, 3).
        line_direction: R_s u, the sockets' line in the root frame (collinear
            sockets; the turn about it is not determined), else None.
        rotation: R_s (sockets spanning a plane), else None.
        translation: c_s, the fixture frame's origin (sockets spanning a plane), else None.
    """

    name: str
    rows: int
    sockets: tuple[str, ...]
    socket_positions: np.ndarray
    socket_std: np.ndarray
    line_direction: np.ndarray | None
    rotation: np.ndarray | None
    translation: np.ndarray | None


@dataclass(frozen=True)
class FixtureCalibration:
    """Outcome of :func:`calibrate_fixture`.

    Attributes:
        level: ``registration``, ``offsets`` or ``full``.
        params: the kinematic parameter set (None at level ``registration``).
        vector / std / status: kinematic parameters (zero = nominal), their
            standard deviations (NaN where not estimated) and why not.
        ball / ball_std: the ball centre m in the tip (tool) frame and its std [m].
        placements: what each placement's pose is, as far as determined.
        nominal_ball: m fitted with the nominal kinematics (the "before") [m].
        training / nominal_training: consistency and distortion of the fit and of
            the nominal kinematics on the calibration rows.
        rank, condition, selection, dropped, correlated: identifiability report.
        rms_m / nominal_rms_m: RMS of eq F1 per coordinate at the solution, and
            with the nominal kinematics [m].
        outliers: (file, line, robust score) of rows far from the others (reported, kept in the fit).
        n_rows: rows in the fit.
        fit_seconds / total_seconds: the final fit; everything, selection included [s].
        kept: indices of the kinematic parameters estimated.
        notes: things the user should know.
        chain_placements: the calibrated chain's joint and tip placements (4×4 each, as
            :meth:`pincal.model.chain.KinematicChain.placements`), to evaluate with
            ``chain.placed(result.chain_placements)``.
        solution / covariance: the final fit's unknowns (kept kinematics, ball, placement poses)
            and their covariance (the posterior with a prior); ``start`` and ``bases`` define
            them (:class:`pincal.residuals.fixture.FixtureResidual`).
    """

    level: ChainLevel
    params: ChainParameters | None
    vector: np.ndarray
    std: np.ndarray
    status: tuple[str, ...]
    ball: np.ndarray
    ball_std: np.ndarray
    placements: tuple[PlacementEstimate, ...]
    nominal_ball: np.ndarray
    training: FixtureMetrics
    nominal_training: FixtureMetrics
    rank: int
    condition: float
    selection: Selection | None
    dropped: tuple[Dropped, ...]
    correlated: tuple[tuple[str, str, float], ...]
    rms_m: float
    nominal_rms_m: float
    outliers: tuple[tuple[str, int, float], ...]
    n_rows: int
    fit_seconds: float
    total_seconds: float
    kept: np.ndarray = field(default_factory=lambda: np.array([], dtype=int))
    notes: tuple[str, ...] = ()
    chain_placements: tuple[np.ndarray, ...] = ()
    solution: np.ndarray = field(default_factory=lambda: np.array([]))
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    start: FixtureEstimate | None = None
    bases: tuple[np.ndarray, ...] = ()

    def predicted_ball_rms(self, chain: KinematicChain, data: FixtureData) -> float:
        """Linearised prediction of the RMS distance between ball and socket on rows ``data`` of
        the calibrated placements due to the estimation noise alone [m] (the fit's covariance
        propagated through eq F1's Jacobian at those rows; the rows' own noise adds to it)."""
        params = self.params if self.params is not None else NoParameters(chain)
        cache = KinematicsCache(params, self.kept, self.vector, data.q)
        assert self.start is not None  # calibrate_fixture always sets it
        objective = FixtureResidual(cache, data.placement, data.socket_points, list(self.bases), self.start)
        jac = objective.jacobian(self.solution)[: 3 * data.n_rows]
        variance = np.einsum("ij,jk,ik->i", jac, self.covariance, jac)
        return float(np.sqrt(variance.sum() / data.n_rows))


def initial_fixture(chain: KinematicChain, data: FixtureData
                    ) -> tuple[FixtureEstimate, list[np.ndarray], list[np.ndarray | None]]:
    """Ball centre and placement poses from the chain as it is (pivot calibration, then the poses).

    Returns:
        The estimate, B_s of each placement (:func:`pincal.residuals.fixture.rotation_basis`)
        and each placement's line direction u in the fixture frame (None when not collinear).
    """
    poses = chain.poses(data.q)
    groups = data.placement * len(data.fixture.names) + data.socket  # one unknown centre per (s, i)
    labels, group = np.unique(groups, return_inverse=True)
    k = data.n_rows
    # R_k m − p_g = −t_k: 3K equations in m (3) and the group centres (3G)
    a = np.zeros((k, 3, 3 + 3 * len(labels)))
    a[:, :, :3] = poses.tool_rotations
    for row, g in enumerate(group):
        a[row, :, 3 + 3 * g : 6 + 3 * g] = -np.eye(3)
    solution = np.linalg.lstsq(a.reshape(3 * k, -1), -poses.tool_positions.reshape(-1), rcond=None)[0]
    ball, centres = solution[:3], solution[3:].reshape(-1, 3)
    rotations, positions, bases = [], [], []
    lines: list[np.ndarray | None] = []
    for s in range(len(data.placements)):
        mine = labels // len(data.fixture.names) == s
        f = data.fixture.points[labels[mine] % len(data.fixture.names)]
        measured = centres[mine]
        basis, line = rotation_basis(f)
        if line is None:
            registration = register_points(f, measured)  # measured ≈ R f + c
            rotation, position = registration.rotation, registration.translation
        else:
            direction = np.linalg.svd(measured - measured.mean(axis=0))[2][0]
            if ((f - f.mean(axis=0)) @ line) @ ((measured - measured.mean(axis=0)) @ direction) < 0:
                direction = -direction
            rotation = pin.Quaternion.FromTwoVectors(line, direction).matrix()
            position = measured.mean(axis=0) - rotation @ f.mean(axis=0)
        rotations.append(rotation)
        positions.append(position)
        bases.append(basis)
        lines.append(line)
    return FixtureEstimate(ball, np.array(rotations), np.array(positions)), bases, lines


@dataclass(frozen=True, eq=False)
class FixtureProblem:
    """Fits of eq F1 over subsets of the kinematic parameters (the interface the selection uses): a value,
    its variants new problems (:meth:`with_prior`, :meth:`with_scales`, :meth:`rescaled`, ``dataclasses.replace``).

    ``models``: sensitivity models by slots, a cache shared by every problem derived from this one.
    ``prior``: with ``--select prior``, σ_i of every kinematic parameter (:mod:`pincal.fit.prior`, eq P1).
    ``noise``: with a prior, the residuals' noise scale σ [m] weighting its rows.
    """

    chain: KinematicChain
    params: ChainParameters | None
    data: FixtureData
    start: FixtureEstimate
    bases: list[np.ndarray]
    models: dict[tuple[ParameterSlot, ...], SensitivityModel] = field(default_factory=dict)
    prior: np.ndarray | None = None
    noise: float = 1.0

    def objective(self, free: np.ndarray, base: np.ndarray) -> FixtureResidual | PriorResidual:
        params = self.params if self.params is not None else NoParameters(self.chain)
        cache = KinematicsCache(params, free, base, self.data.q, self.models)
        objective = FixtureResidual(cache, self.data.placement, self.data.socket_points, self.bases, self.start)
        return objective if self.prior is None else PriorResidual(objective, self.prior[free], self.noise)

    def fit(self, free: np.ndarray, base: np.ndarray, x0: np.ndarray | None = None,
            what: str = "fit") -> tuple[FixtureResidual | PriorResidual, Solution]:
        objective = self.objective(free, base)
        solution = solve(objective, objective.start_vector() if x0 is None else x0, what=what)
        return objective, solution

    def scales(self) -> tuple[float]:
        """The noise scale σ [m] weighting a prior's rows (:mod:`pincal.fit.pipeline`)."""
        return (self.noise,)

    def rescaled(self, objective: FixtureResidual | PriorResidual, solution: Solution) -> FixtureProblem:
        """This problem at σ [m] from a fit: with a prior, eq P2 from ``solution``'s data rows; without,
        their RMS (the residual is in metres and unweighted, σ weights only a prior's rows)."""
        if isinstance(objective, PriorResidual):
            return replace(self, noise=max(effective_scale(solution.residual[: -objective.n_prior],
                                                           hat_diagonal(solution.jacobian, objective.n_prior)),
                                           SCALE_FLOOR))
        # maximum likelihood: the residual's RMS
        return replace(self, noise=float(np.sqrt(np.mean(solution.residual**2))) or self.noise)

    def with_scales(self, scales: tuple[float | None, ...]) -> FixtureProblem:
        """This problem with a prior's rows weighted by ``scales`` (as :meth:`scales` gives them)."""
        (noise,) = scales
        return replace(self, noise=cast(float, noise))  # the one scale, of the ball centres: always measured

    def with_prior(self, prior: np.ndarray | None) -> FixtureProblem:
        """This problem with ``prior`` (σ_i of every kinematic parameter, eq P1; None: no prior)."""
        return replace(self, prior=prior)

    def fold_rows(self, objective: FixtureResidual | PriorResidual) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What the prior's folds deal (:func:`pincal.fit.prior_scales.scale_folds`): each row's joint
        readings (K, N), its placement and socket as one stratum (K,), its three residual entries (K, 3)."""
        data = self.data
        strata = data.placement * len(data.fixture.names) + data.socket
        return data.q, strata, np.arange(3 * data.n_rows).reshape(data.n_rows, 3)

    def scale_rows(self, objective: FixtureResidual | PriorResidual) -> tuple[slice, ...]:
        """The data rows the noise scale of :meth:`scales` weights: every ball-centre coordinate."""
        return (slice(0, 3 * self.data.n_rows),)

    def log_evidence(self, objective: FixtureResidual | PriorResidual, solution: Solution) -> float:
        """Eq P3 (:func:`pincal.fit.prior.log_evidence`) with the rows [m] divided by σ."""
        prior = cast(PriorResidual, objective)  # eq P3 is of a MAP fit
        rows = solution.residual.size - prior.n_prior
        return log_evidence(solution.jacobian / prior.noise, solution.residual / prior.noise,
                            rows * 2.0 * np.log(prior.noise))

    def rows_view(self) -> MeasurementSet:
        """The rows as one-point measurements (the socket in its fixture frame), for the selection's bookkeeping."""
        data = self.data
        return MeasurementSet(data.joint_names, data.q, data.socket_points[:, None, :], None,
                              np.full(data.n_rows, "calibration", dtype=object), data.lines, {},
                              ", ".join(data.sources))


def calibrate_fixture(
    chain: KinematicChain, data: FixtureData, level: ChainLevel, selection: SelectionCriterion | Prior = "aic"
) -> FixtureCalibration:
    """Calibrate ``chain`` at ``level`` from the socket-fixture rows ``data``.

    The chain's tool frame is the frame the ball centre is estimated in. The chain is
    not changed: the calibrated model is the result's ``chain_placements``. ``selection`` as for
    :func:`pincal.fit.chain_calibration.calibrate_chain` (``"prior"``: the MAP fit of
    :mod:`pincal.fit.prior`, its rows weighted by the residuals' noise σ [m], eq P2).

    Raises:
        CalibrationError: an unknown level or criterion, too few rows for the
            unknowns, or a fit the data cannot determine.
    """
    if level not in CHAIN_LEVELS:
        raise CalibrationError(f"level must be one of {CHAIN_LEVELS}, got '{level}'")
    if selection not in SELECTION_CRITERIA:
        raise CalibrationError(f"selection must be one of {tuple(SELECTION_CRITERIA)}, got '{selection}'")
    started = time.perf_counter()
    params = LEVELS[level](chain) if level in LEVELS else None
    start, bases, lines = initial_fixture(chain, data)
    problem = FixtureProblem(chain, params, data, start, bases)
    size = params.size if params is not None else 0
    base, empty = np.zeros(size), np.array([], dtype=int)
    objective, solution = problem.fit(empty, base, what="ball and placements (nominal kinematics)")
    nominal = objective.estimate(solution.x)
    nominal_rms = solution.rms
    nominal_training = metrics_of_positions(objective.ball_positions(solution.x), data)
    # with a prior, its rows weighted by the nominal fit's noise at first (eq P1, P2)
    problem = replace(problem, start=nominal, noise=nominal_rms)
    analysis: Analysis | None = None
    dropped: tuple[Dropped, ...] = ()
    turn = 0
    if size:
        full = problem.objective(np.arange(size), base)
        jac, turn = _identifiability_jacobian(full)
        analysis = Analysis(jac, np.arange(size), np.arange(size, jac.shape[1]))
    fit = fit_kinematics(problem, analysis, problem.rows_view(), selection, level, refits=0, from_selection=False)
    if analysis is not None:
        names = column_names(full, params, np.arange(size), data) + [f"root_frame.r{a}" for a in "xyz"][:turn]
        dropped = dropped_parameters(analysis.jacobian, cast(Ordering, fit.ordering), fit.kept, analysis.always, names)
    objective, solution, kept, covariance = fit.objective, fit.solution, fit.kept, fit.covariance
    x = solution.x
    residual = solution.residual[: 3 * data.n_rows]  # without a prior's rows
    names = column_names(objective, params, kept, data)
    errors = np.linalg.norm(residual.reshape(-1, 3), axis=1)
    return FixtureCalibration(
        level=level,
        params=params,
        vector=fit.vector,
        std=fit.std,
        status=fit.status,
        ball=x[objective.blocks["ball"]].copy(),
        ball_std=np.sqrt(np.diag(covariance)[objective.blocks["ball"]]),
        placements=_placements(objective, x, covariance, data, lines),
        # size > 0 only with a parameter set
        chain_placements=(tuple(cast(ChainParameters, params).placements(fit.vector)) if size
                          else tuple(chain.placements())),
        nominal_ball=nominal.ball,
        training=metrics_of_positions(objective.ball_positions(x), data),
        nominal_training=nominal_training,
        rank=fit.rank,
        condition=condition_number(data_rows(solution.jacobian, objective)),  # the data's, not the prior rows'
        selection=fit.selection,
        dropped=dropped,
        correlated=tuple((names[a], names[b], c) for a, b, c in correlated_pairs(covariance)),
        rms_m=float(np.sqrt(np.mean(residual**2))),
        nominal_rms_m=nominal_rms,
        outliers=tuple((data.sources[data.files[k]], int(data.lines[k]), score)
                       for k, score in find_outliers(errors[:, None], np.arange(data.n_rows))),
        n_rows=data.n_rows,
        fit_seconds=fit.fit_seconds,
        total_seconds=time.perf_counter() - started,
        kept=kept,
        notes=() if fit.selection is None else tuple(fit.selection.notes),  # the selection's (and a prior's) notes
        solution=x.copy(), covariance=covariance, start=problem.start, bases=tuple(bases),
    )


def _identifiability_jacobian(full: FixtureResidual | PriorResidual) -> tuple[np.ndarray, int]:
    """The Jacobian at the start, with the turn of the root frame appended to the
    always-estimated columns (:meth:`FixtureResidual.root_rotation_columns`), unless
    the placements already absorb it column for column (sockets spanning a plane
    and a consistent model): dependent columns would give the projection of
    :func:`pincal.fit.identifiability.order_parameters` arbitrary directions.

    Returns:
        (3K, n + t) and t, the number of root-frame columns appended (3 or 0).
    """
    x = full.start_vector()
    jac = full.jacobian(x)
    turn = full.root_rotation_columns(x)
    always = np.hstack([jac[:, full.blocks["kinematic"].stop:], turn])
    always = always / np.linalg.norm(always, axis=0)
    singular = np.linalg.svd(always, compute_uv=False)
    if singular[-1] <= DEPENDENT_COLUMNS * singular[0]:
        return jac, 0
    return np.hstack([jac, turn]), 3


def _placements(objective: FixtureResidual | PriorResidual, x: np.ndarray, covariance: np.ndarray, data: FixtureData,
                lines: list[np.ndarray | None]) -> tuple[PlacementEstimate, ...]:
    """Socket centres (with their spread, propagated from the fit's covariance) and the
    determined part of each placement's pose."""
    estimate = objective.estimate(x)
    out = []
    for s, name in enumerate(data.placements):
        used = np.unique(data.socket[data.placement == s])
        f = data.fixture.points[used]
        rotation, position = estimate.rotations[s], estimate.positions[s]
        pos, rot = objective.position_slices[s], objective.rotation_slices[s]
        phi = objective.bases[s] @ x[rot]
        spread = []
        for point in f:  # d(c + R f) / d(c, a) = [I, -R [f]x Jexp3(phi) B]
            jac = np.zeros((3, objective.n_params))
            jac[:, pos] = np.eye(3)
            jac[:, rot] = -rotation @ pin.skew(point) @ pin.Jexp3(phi) @ objective.bases[s]
            spread.append(np.sqrt(np.clip(np.diag(jac @ covariance @ jac.T), 0.0, None)))
        collinear = lines[s] is not None
        out.append(PlacementEstimate(
            name=name,
            rows=int(np.sum(data.placement == s)),
            sockets=tuple(data.fixture.names[i] for i in used),
            socket_positions=position + f @ rotation.T,
            socket_std=np.array(spread),
            line_direction=rotation @ lines[s] if collinear else None,
            rotation=None if collinear else rotation,
            translation=None if collinear else position,
        ))
    return tuple(out)


def column_names(objective: FixtureResidual | PriorResidual, params: ChainParameters | None, kept: np.ndarray,
                 data: FixtureData) -> list[str]:
    """Names of the objective's columns: kinematic, ``ball.x`` …, ``placement[P].x`` …, ``placement[P].turn1`` …"""
    names = [params.info[i].name for i in kept] if params is not None else []
    names += [f"ball.{a}" for a in "xyz"]
    for s, name in enumerate(data.placements):
        names += [f"placement[{name}].{a}" for a in "xyz"]
        sl = objective.rotation_slices[s]
        names += [f"placement[{name}].turn{j + 1}" for j in range(sl.stop - sl.start)]
    return names
