"""The calibration methods of Franaszek & Marvel (2022), Sections 3–6.

All three methods start from the nominal DH table and estimate the link twists
alpha by circle point analysis (Section 3, eq 9) on the ``cpa`` rows. Then:

* Method 1 fits eps_2..N, r_1..N, d_2..N (3N − 2 parameters) to Err_pos, the
  pairwise TCP distances (eq 10–12);
* Method 2 fits eps_2..N to Err_rot, the pairwise relative rotations (eq 14–17),
  then r_1..N, d_2..N to Err_pos with those offsets;
* Method 3 fits eps_2..N, r_1..N, d_2..N to Err_full = Err_pos + w Err_rot (eq 18).

d_1 and eps_1 do not change distances or relative rotations; they keep their
nominal values and the registration absorbs them (Section 6). alpha_N is not
determined by CPA and keeps its nominal value. Registration 1 (Arun et al.
1987) maps positions, Registration 2 (the mean rotation of G_k R_k⁻¹, Moakher
2002) maps orientations; both take their translation from eq 19.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pincal.errors import CalibrationError
from pincal.fit.registration import register_orientations, register_points
from pincal.fit.solver import Solution, solve
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.dh.parameters import DHParameterSet
from pincal.model.dh.table import DHTable
from pincal.model.sensor import Registration
from pincal.paper.cpa import circle_axis, twists_from_axes
from pincal.residuals.base import KinematicsCache, Objective
from pincal.residuals.distance import DistanceResidual
from pincal.residuals.full_pose import FullPoseResidual
from pincal.residuals.rotation import RotationResidual

__all__ = [
    "METHODS", "CALIBRATED", "FROM_CPA", "ABSORBED", "NOT_BY_CPA", "NO_CPA_DATA", "Stage", "PaperCalibration",
    "cpa_groups", "estimate_twists", "calibrate_paper",
]

METHODS = (1, 2, 3)

#: Status of a DH parameter after calibration.
CALIBRATED = "calibrated"
FROM_CPA = "calibrated (CPA)"
ABSORBED = "not determined: absorbed by the registration"
NOT_BY_CPA = "not determined: alpha_N is not observable by CPA"
NO_CPA_DATA = "not determined: no CPA rows for this joint pair"


@dataclass(frozen=True)
class Stage:
    """One least-squares fit of a method.

    Attributes:
        name: which error function (``Err_pos``, ``Err_rot``, ``Err_full``).
        parameters: names of the fitted parameters.
        rms: RMS residual, in ``unit``.
        unit: unit of the residuals.
        n_evaluations: residual evaluations of the solver.
        condition: condition number of the Jacobian at the solution.
    """

    name: str
    parameters: tuple[str, ...]
    rms: float
    unit: str
    n_evaluations: int
    condition: float


@dataclass(frozen=True)
class PaperCalibration:
    """Outcome of one paper method.

    Attributes:
        method: 1, 2 or 3 (``"ml"`` for :mod:`pincal.paper.ml_estimator`).
        weight: w of Method 3 [mm²/deg²], None otherwise.
        nominal: the starting DH table.
        table: the calibrated DH table.
        std: standard deviation of each flat DH parameter (4N,), NaN where not estimated.
        status: per flat parameter, one of the status strings of this module.
        registration_position: Registration 1 (maps base to sensor coordinates).
        registration_orientation: Registration 2 (Methods 2, 3); Registration 1 for Method 1.
        stages: the fits that were run, in order.
        notes: things the user should know.
        chain_placements: the chain placements realising ``table`` (4×4 each, N joints + tip, as
            :meth:`pincal.model.chain.KinematicChain.placements`), to evaluate with
            ``chain.placed(result.chain_placements)``.
    """

    method: int | str
    weight: float | None
    nominal: DHTable
    table: DHTable
    std: np.ndarray
    status: tuple[str, ...]
    registration_position: Registration
    registration_orientation: Registration
    stages: tuple[Stage, ...]
    notes: tuple[str, ...] = field(default=())

    @property
    def chain_placements(self) -> tuple[np.ndarray, ...]:
        return tuple(self.table.joint_origins())


def cpa_groups(q: np.ndarray, lines: np.ndarray | None = None) -> dict[int, np.ndarray]:
    """Split CPA rows into runs in which exactly one joint moves.

    Consecutive rows belong to the same run while each step between them moves
    the same single joint. Returns {joint index: row indices}.

    Args:
        q: joint readings of the CPA rows (R, N).
        lines: file line numbers of those rows, for messages (default 1..R).

    Raises:
        CalibrationError: a row belongs to no run of at least 3 rows, or two
            runs move the same joint.
    """
    q = np.asarray(q, dtype=float)
    lines = np.arange(1, len(q) + 1) if lines is None else np.asarray(lines)
    changed = np.abs(np.diff(q, axis=0)) > 1e-12  # (R-1, N)
    mover = np.where(changed.sum(axis=1) == 1, changed.argmax(axis=1), -1).tolist()
    groups: dict[int, np.ndarray] = {}
    row = 0
    while row < len(q):
        end = row  # last row of the run starting at `row`
        while end < len(mover) and mover[end] >= 0 and mover[end] == mover[row]:
            end += 1
        if end - row < 2:
            raise CalibrationError(
                f"CPA row at line {lines[row]}: each joint needs a run of at least 3 rows "
                "in which only that joint moves"
            )
        joint = mover[row]
        if joint in groups:
            raise CalibrationError(
                f"CPA rows at lines {lines[row]}..{lines[end]}: joint {joint + 1} already had a run"
            )
        groups[joint] = np.arange(row, end + 1)
        row = end + 1
    return groups


def estimate_twists(
    chain: KinematicChain, nominal: DHTable, cpa: MeasurementSet
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Link twists from CPA rows (Section 3, eq 9).

    Returns:
        alpha (N,) with CPA estimates where both axes were measured and nominal
        values elsewhere, a boolean mask of the estimated entries, and notes.
    """
    n = chain.n_joints
    alpha = nominal.alpha.copy()
    estimated = np.zeros(n, dtype=bool)
    notes: list[str] = []
    if cpa.n_rows == 0:
        notes.append("no CPA rows: link twists keep their nominal values")
        return alpha, estimated, notes
    groups = cpa_groups(cpa.q, cpa.lines)
    axes: dict[int, np.ndarray] = {}
    for joint, rows in groups.items():
        try:
            axes[joint] = circle_axis(cpa.points[rows, 0, :], cpa.q[rows, joint])
        except CalibrationError as error:
            lines, files = cpa.lines[rows], " + ".join(dict.fromkeys(cpa.files[rows].tolist()))
            raise CalibrationError(f"{files}, CPA arc of joint '{chain.joints[joint].name}' "
                                   f"(lines {lines.min()}-{lines.max()}): {error}") from None
    for i in range(n - 1):
        if i in axes and i + 1 in axes:
            pair = twists_from_axes(np.stack([axes[i], axes[i + 1]]), nominal.alpha[i : i + 2])
            alpha[i] = pair[0]
            estimated[i] = True
    missing = [chain.joints[i].name for i in range(n) if i not in axes]
    if missing:
        notes.append(f"no CPA run for {', '.join(missing)}: their twists keep nominal values")
    return alpha, estimated, notes


def calibrate_paper(
    chain: KinematicChain,
    data: MeasurementSet,
    method: int,
    weight: float = 1.0,
    nominal: DHTable | None = None,
    start: DHTable | None = None,
    twists: tuple[np.ndarray, np.ndarray, list[str]] | None = None,
    models: dict | None = None,
) -> PaperCalibration:
    """Run Method 1, 2 or 3 on the ``cpa`` and ``calibration`` rows of ``data``.

    Args:
        chain: the chain; its tool must be the measured target (the TCP). It is not
            changed: the calibrated table is the result's (``chain_placements`` in the chain's terms).
        data: measurements (``cpa`` rows optional, ``calibration`` rows used).
        method: 1, 2 or 3 (``"ml"`` for :mod:`pincal.paper.ml_estimator`).
        weight: w of Method 3 [mm²/deg²].
        nominal: the default table (read from the chain's placements if None);
            parameters the data cannot determine keep its values.
        start: starting values of the fitted eps, r, d (default: ``nominal``,
            as in the paper); alpha always starts from CPA.
        twists: ``estimate_twists(chain, nominal, data.with_role("cpa"))`` if the
            caller has it (fits of one data set share one CPA); computed if None.
        models: Pinocchio sensitivity models of ``chain`` by their slots, shared by
            many fits of one chain (:class:`pincal.residuals.base.KinematicsCache`);
            the fit adds those it builds. None: built for this fit only.
    """
    if method not in METHODS:
        raise CalibrationError(f"method must be one of {METHODS}, got {method}")
    if data.n_points != 1:
        raise CalibrationError(
            f"{data.source}: the paper's methods use one target point per row, "
            f"this file has {data.n_points}"
        )
    params = DHParameterSet(chain, nominal)
    nominal = params.nominal
    n = nominal.n_joints
    calibration = data.with_role("calibration")
    if calibration.n_rows < 2:
        raise CalibrationError(f"{data.source}: need calibration rows, found {calibration.n_rows}")
    if method in (2, 3) and not calibration.has_orientation:
        raise CalibrationError(
            f"{data.source}: Method {method} needs orientations (columns qx,qy,qz,qw); "
            "use --method 1 for positions only"
        )
    if twists is None:
        twists = estimate_twists(chain, nominal, data.with_role("cpa"))
    alpha, alpha_estimated, notes = twists[0].copy(), twists[1], list(twists[2])
    start_vector = nominal.to_vector()
    offsets = params.indices("epsilon", range(1, n))
    lengths = np.concatenate([params.indices("r"), params.indices("d", range(1, n))])
    if start is not None:
        fitted = np.concatenate([offsets, lengths])
        start_vector[fitted] = start.to_vector()[fitted]
    start_vector[params.indices("alpha")] = alpha
    std = np.full(params.size, np.nan)
    status = np.array([NO_CPA_DATA] * n + [CALIBRATED] * (3 * n), dtype=object)
    status[params.indices("alpha")[alpha_estimated]] = FROM_CPA
    if not alpha_estimated[-1]:
        status[params.indices("alpha", [n - 1])] = NOT_BY_CPA
    status[params.indices("epsilon", [0])] = ABSORBED
    status[params.indices("d", [0])] = ABSORBED

    q = calibration.q
    points = calibration.points[:, 0, :]
    rotations = calibration.rotations

    def fit(objective: Objective, cache: KinematicsCache, name: str, unit: str) -> Stage:
        solution: Solution = solve(objective, cache.base[cache.free], what=f"Method {method} {name}")
        cache.base[cache.free] = solution.x
        std[cache.free] = solution.std
        return Stage(
            name=name,
            parameters=tuple(params.info[i].name for i in cache.free),
            rms=solution.rms,
            unit=unit,
            n_evaluations=solution.n_evaluations,
            condition=solution.condition,
        )

    stages = []
    vector = start_vector
    if method == 1:
        cache = KinematicsCache(params, np.concatenate([offsets, lengths]), vector, q, models)
        stages.append(fit(DistanceResidual(cache, points), cache, "Err_pos", "m"))
        vector = cache.base
    elif method == 2:
        assert rotations is not None  # has_orientation checked above
        cache = KinematicsCache(params, offsets, vector, q, models)
        stages.append(fit(RotationResidual(cache, rotations), cache, "Err_rot", "rad"))
        cache = KinematicsCache(params, lengths, cache.base, q, models)
        stages.append(fit(DistanceResidual(cache, points), cache, "Err_pos", "m"))
        vector = cache.base
    else:
        assert rotations is not None  # has_orientation checked above
        cache = KinematicsCache(params, np.concatenate([offsets, lengths]), vector, q, models)
        objective = FullPoseResidual(cache, points, rotations, weight)
        stages.append(fit(objective, cache, "Err_full", "mm | sqrt(w) deg"))
        vector = cache.base

    poses, _ = cache.evaluate(vector[cache.free])  # tool poses at the solution
    registration_position = register_points(poses.tool_positions, points)
    if method in (2, 3):
        registration_orientation = register_orientations(
            poses.tool_rotations, rotations, poses.tool_positions, points
        )
    else:  # Method 1 uses positions only: one registration for both (Section 6)
        registration_orientation = registration_position
    return PaperCalibration(
        method=method,
        weight=weight if method == 3 else None,
        nominal=nominal,
        table=DHTable.from_vector(vector),
        std=std,
        status=tuple(status),
        registration_position=registration_position,
        registration_orientation=registration_orientation,
        stages=tuple(stages),
        notes=tuple(notes),
    )
