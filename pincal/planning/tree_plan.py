"""``pincal plan`` with several ``--tip-link LINK:POINTS``: the configurations of a tree worth measuring.

The candidates are configurations of every joint of the tree (the union of the targets' chains,
:class:`pincal.model.tree.KinematicTree`). Each candidate's information is the Jacobian of the tree's
residual (:class:`pincal.residuals.tree.TreeResidual`: every target's points, the shared joints' parameters
once), weighted by 1/σ_p: its columns are the tree's kinematic parameters (those the calibration estimates)
and, as nuisance, the registration of each session and every point in its tip link — what
``calibrate --tip-link A:1 --tip-link B:2`` fits. From there on the plan is one chain's
(:func:`pincal.planning.planner.choose`: the same criteria, selection, random comparison and order), its
workspace rows every target's points; each target's predicted error is the mean over its own points
(:attr:`pincal.planning.planner.Plan.targets`).

Not (yet) for a tree: a known ``--tool``, orientation (``--measure pose``), ``--level dh``, ``--coupling``.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import cast

import numpy as np
import numpy.typing as npt

from pincal.errors import PincalError
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.prior import Prior, prior_sigmas
from pincal.fit.tree_calibration import calibrate_tree, initial_tree_target, tree_rows
from pincal.measurements.data import MeasurementSet
from pincal.model.parameter_sets import ChainLevel, ChainParameters, ParameterLevel
from pincal.model.sensor import Registration
from pincal.model.tree import KinematicTree, TreePlacements
from pincal.model.tree_parameters import TreeParameters
from pincal.planning.design import DesignProblem, TargetPrediction
from pincal.planning.information import SensorModel, default_target_points
from pincal.planning.planner import (
    DEFAULT_SIGMA_POS_MM,
    Joints,
    Plan,
    PlanContext,
    PlanSettings,
    choose,
    usable_pool,
    velocity_limits,
    workspace_sample,
)
from pincal.progress import Progress
from pincal.residuals.sensor import REGISTRATION_NAMES
from pincal.residuals.sensor_values import RowWeights, TargetEstimate
from pincal.residuals.tree import TreeResidual, TreeRows

__all__ = ["TREE_PLAN_LEVELS", "TreeMeasurementModel", "plan_tree_measurements"]

#: The levels a tree's plan takes: those of its calibration.
TREE_PLAN_LEVELS = ("registration", "offsets", "full")


class TreeMeasurementModel:
    """Weighted measurement Jacobians of a tree's points at its current placements.

    Args:
        tree: the tree; its chains' placements as they are now are the linearisation point.
        level: ``registration``, ``offsets`` or ``full``.
        points: every measured point in its tip link [m], (P, 3), in the order of the point numbers.
        sigma_pos_m: σ_p, position noise per axis [m].
        sessions: the sessions' names (one registration each; the candidates are in the last).
    """

    def __init__(self, tree: KinematicTree, level: str, points: npt.ArrayLike, sigma_pos_m: float,
                 sessions: tuple[str, ...] = ("plan",)) -> None:
        self.tree, self.level, self.sessions = tree, level, sessions
        self.params = TreeParameters(tree, cast(ParameterLevel, level)) if level in ("offsets", "full") else None
        self.points = np.atleast_2d(np.asarray(points, dtype=float))
        self.sigma_pos_m = float(sigma_pos_m)
        size = 0 if self.params is None else self.params.size
        self.kinematic = np.arange(size)
        names = [] if self.params is None else [i.name for i in self.params.info]
        names += [f"registration{'' if len(sessions) == 1 else f'[{s}]'}.{a}" for s in sessions
                  for a in REGISTRATION_NAMES]
        self.names = tuple(names + [f"target.point{p + 1}.{a}" for p in range(len(self.points)) for a in "xyz"])

    def prior_precision(self, prior: Prior) -> np.ndarray:
        """Λ's diagonal, 1/σ_i² for each kinematic column and zero for the others (eq P1), (n,)."""
        precision = np.zeros(len(self.names))
        if self.params is not None:
            precision[self.kinematic] = 1.0 / prior_sigmas(cast(ChainParameters, self.params), prior) ** 2
        return precision

    def jacobian(self, q: npt.ArrayLike, sessions: npt.ArrayLike | None = None, seen: npt.ArrayLike | None = None,
                 chunk: int = 1000) -> np.ndarray:
        """Noise-weighted Jacobian blocks F_k of tree readings ``q`` (K, N), (K, 3P, n): each row's points' x, y, z
        (dimensionless); ``sessions``: each row's session index (default: the last); ``seen`` (K, P): a point not
        seen in a row has zero rows (no information)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        k, n_points = len(q), len(self.points)
        sessions = np.full(k, len(self.sessions) - 1) if sessions is None else np.asarray(sessions, dtype=np.intp)
        blocks = [self._jacobian(q[s:s + chunk], sessions[s:s + chunk]) for s in range(0, k, chunk)]
        out = np.concatenate(blocks) if blocks else np.zeros((0, 3 * n_points, len(self.names)))
        if seen is not None:
            out = (out.reshape(k, n_points, 3, -1) * np.asarray(seen, dtype=float)[:, :, None, None]).reshape(out.shape)
        return out

    def _jacobian(self, q: np.ndarray, sessions: np.ndarray) -> np.ndarray:
        k, n_points = len(q), len(self.points)
        rows = TreeRows(q, np.zeros((k, n_points, 3)), np.ones((k, n_points), dtype=bool), sessions)
        identity = Registration(np.eye(3), np.zeros(3))
        start = TargetEstimate(identity, self.points, np.eye(3), tuple(identity for _ in self.sessions))
        size = len(self.kinematic)
        objective = TreeResidual(self.tree, self.params, np.arange(size), np.zeros(size), rows, start,
                                 RowWeights(np.full(k, 1.0 / self.sigma_pos_m)))
        return objective.jacobian(objective.start_vector()).reshape(k, 3 * n_points, -1)

    def error_jacobian(self, q: npt.ArrayLike) -> tuple[np.ndarray, None]:
        """Unweighted position rows A_e at tree readings ``q`` [m per parameter unit], (E, P, 3, n), and None (no
        orientation)."""
        blocks = self.jacobian(q) * self.sigma_pos_m
        return blocks.reshape(len(blocks), len(self.points), 3, -1), None


def plan_tree_measurements(
    tree: KinematicTree,
    candidates: np.ndarray,
    settings: PlanSettings,
    existing: MeasurementSet | None = None,
    workspace: np.ndarray | None = None,
    allowed: np.ndarray | None = None,
    progress: Progress | None = None,
) -> Plan:
    """Choose ``settings.count`` of the ``candidates`` (K, tree joints) for every target of ``tree`` and order them,
    as :func:`pincal.planning.planner.plan_measurements` does for one chain (module docstring); the plan's
    ``targets`` hold each target's predicted errors.

    Raises:
        PincalError: what a tree's plan does not take (a known tool, orientation, ``dh``), target points that
            are not one per measured point, recorded data not of the targets' points, a count the candidates
            cannot meet.
    """
    started = time.perf_counter()
    n_points = tree.n_points
    sensor = SensorModel("points", n_points)
    for refused, what in ((settings.tool_known, "a known --tool (each target's points are estimated)"),
                          (settings.level not in TREE_PLAN_LEVELS, f"--level {settings.level}"),
                          (settings.sensor is not None and settings.sensor != sensor,
                           f"--measure {settings.sensor.label if settings.sensor else ''} (the targets' "
                           f"{n_points} points are measured: points:{n_points})")):
        if refused:
            raise PincalError(f"several --tip-link: {what} is not supported by plan; leave it out")
    settings = replace(settings, sensor=sensor)
    candidates, allowed = usable_pool(candidates, allowed, settings.count)
    rng = np.random.default_rng(settings.seed)
    placements, points, sigma, source, recorded = _linearisation(tree, settings, existing)
    workspace = workspace_sample(candidates, allowed, workspace, settings, rng)
    sessions: tuple[str, ...] = ("plan",)
    recorded_q, recorded_rows = np.zeros((0, tree.n_joints)), None
    if recorded is not None:  # the candidates continue the session of the last recorded row: its registration
        recorded_rows = tree_rows(tree, recorded)
        names = recorded.session_names
        last = int(recorded_rows.sessions[-1])
        order = [s for s in range(len(names)) if s != last] + [last]
        sessions, recorded_q = tuple(names[s] for s in order), recorded_rows.q
        renumbered = np.argsort(order)[recorded_rows.sessions]
    with tree.placed(placements):  # the parameters are errors about these placements
        model = TreeMeasurementModel(tree, settings.level, points, sigma, sessions)
        blocks = model.jacobian(candidates)
        recorded_blocks = (np.zeros((0,) + blocks.shape[1:]) if recorded_rows is None
                           else model.jacobian(recorded_q, renumbered, recorded_rows.seen))
        errors = model.error_jacobian(workspace)
    precision = None if settings.prior is None else model.prior_precision(settings.prior)
    problem = DesignProblem(blocks, model.kinematic, recorded_blocks, *errors, prior_precision=precision)
    joints = Joints(tree.joints, velocity_limits(tree.model, [tree.model.getJointId(n) for n in tree.joint_names]))
    context = PlanContext(settings, candidates, allowed, recorded_q, model.names, joints,
                          (sigma * 1000.0, None, source), points, started)
    plan, draws = choose(problem, context, rng, progress)
    return replace(plan, targets=_target_predictions(tree, problem, plan.candidates, draws))


def _linearisation(tree: KinematicTree, settings: PlanSettings, existing: MeasurementSet | None
                   ) -> tuple[TreePlacements, np.ndarray, float, str, MeasurementSet | None]:
    """Where the plan is linearised: the recorded rows' calibration (its placements, points and noise, each
    unless given) or the tree as it is with the default points; the noise's source; the recorded rows."""
    n_points = tree.n_points
    points = None if settings.target_points is None else np.asarray(settings.target_points, dtype=float)
    if points is not None and points.shape != (n_points, 3):
        raise PincalError(f"--target-points: {len(points)} given, the --tip-link values name {n_points} point(s); "
                          "give one X,Y,Z per point, in the order of their numbers")
    sigma = None if settings.sigma_pos_mm is None else settings.sigma_pos_mm / 1000.0
    source = "given" if sigma is not None else "default"
    placements = tree.placements()
    recorded = None
    if existing is not None:
        recorded = existing.select(np.flatnonzero(existing.roles != "validation"))
        if settings.level in ("offsets", "full"):
            result = calibrate_tree(tree, existing, cast(ChainLevel, settings.level),
                                    ChainFitOptions(selection=settings.selection))
            placements, estimated = result.tree_placements, result.target.points
            if sigma is None:
                sigma, source = result.sigma_pos_m, f"estimated from {existing.source}"
        else:
            estimated = initial_tree_target(tree, recorded, tree_rows(tree, recorded)).points
        points = estimated if points is None else points
    if points is None:  # each target's default layout in its tip link
        points = np.zeros((n_points, 3))
        for target in tree.targets:
            points[np.array(target.spec.points) - 1] = default_target_points(len(target.spec.points))
    sigma = DEFAULT_SIGMA_POS_MM / 1000.0 if sigma is None else sigma
    return placements, points, sigma, source, recorded


def _target_predictions(tree: KinematicTree, problem: DesignProblem, chosen: np.ndarray,
                        draws: list[np.ndarray]) -> tuple[TargetPrediction, ...]:
    """Each target's mean and largest expected error over its points, for the plan and the median over the
    random ``draws`` (a singular draw counts as infinitely bad; None when half of them or more are)."""
    plan = problem.point_errors(chosen)
    random = [problem.point_errors(d) for d in draws]
    good = [r for r in random if r is not None]
    out = []
    for target in tree.targets:
        index = np.array(target.spec.points) - 1
        mine = None if plan is None else (float(plan[:, index].mean()), float(plan[:, index].max()))
        median = None
        if len(good) > len(random) // 2:
            infinite = [np.inf] * (len(random) - len(good))
            median = (float(np.median([r[:, index].mean() for r in good] + infinite)),
                      float(np.median([r[:, index].max() for r in good] + infinite)))
        out.append(TargetPrediction(target.link, target.spec.points, mine, median))
    return tuple(out)
