"""Which directions of the target's position the measurements cannot tell from the registration.

A target point m (in the tool frame) is sensed at Omega (t_k + R_k m) + tau. Shifting
every target point by the same d changes row k's sensed points by Omega R_k d; the
registration's translation tau absorbs the mean of that change, its rotation a
little more, and only the rest — the tool orientation's variation about axes across
d — tells d apart. With J_d the Jacobian columns of a common shift (3 columns) and
P the projection off every other always-estimated column (the registrations, the
target points' shape, the target rotation), the information on the shift along a
unit direction u of the tool frame is uᵀ J_dᵀ (I − P) J_d u, and

    turn(u) = sqrt( uᵀ J_dᵀ (I − P) J_d u  /  uᵀ J_dᵀ J_d u )          (T1)

is the fraction of the shift no registration can absorb: for small turns, the RMS
over rows of the tool's rotation about axes across u from its mean [rad]
(|(R_k − R̄) u| ≈ angle for a unit u). The eigenvectors of the symmetric
generalised problem (J_dᵀ (I − P) J_d) u = turn² (J_dᵀ J_d) u give the principal
directions.

Two rules hold a direction of the target's position at a stated value (the tool's origin; with
``--tool`` nothing is estimated) and let the registration's translation take it:

1. **Not seen at all**: its turn is below :data:`NO_TURN_RAD` (1e-6 rad: a robot program that
   holds the orientation in the controller's model — the nominal one — turns the modelled tool
   by nothing but rounding). The fit could not even start.
2. **Not determined**: after the calibration, the target's standard deviation along it
   (the fit's covariance: given the kinematic parameters kept, at the residual's scale) exceeds
   :data:`MAX_TARGET_STD_M`. The data then placed the target where the kinematics' own errors
   pushed it — metres, or hundreds of metres, away under a constant orientation — and the
   calibration is done again with it held, and with what only it would explain (the tip
   placement's translation) not estimated either.

The reason given names the turn the data had, and the turn that would determine the target:
the standard deviation falls as 1/turn, so turn × std / :data:`MAX_TARGET_STD_M`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg

from pincal.fit.sensor_problem import FitProblem

__all__ = [
    "NO_TURN_RAD", "MAX_TARGET_STD_M", "HeldDirection", "shift_grams", "principal_turns", "turn_along", "held_basis",
    "describe_direction", "held_reason", "hold_target", "analysis_jacobian", "held_columns", "weak_target",
]

#: Turn (eq T1) below which a direction of the target is not seen at all [rad] (rule 1).
NO_TURN_RAD = 1e-6
#: Largest standard deviation of an estimated target direction [m] (rule 2): ten times the
#: physical prior scale of a placement translation (1 mm, :mod:`pincal.fit.prior`) — the target
#: is then known worse than a drawing of the tool gives it.
MAX_TARGET_STD_M = 10e-3


@dataclass(frozen=True)
class HeldDirection:
    """A direction of the target's position the data leave undetermined.

    Attributes:
        direction: unit vector in the tool frame, (3,).
        turn_rad: the tool's RMS turn across it over the rows (eq T1) [rad].
        value_m: the value the target's points are held at along it [m].
        frame: the link the direction is in (the tip link).
        std_m: the target's standard deviation along it when it was estimated [m] (inf: not seen at all).
        points: how many target points move together along it (their centroid is what is held).
    """

    direction: np.ndarray
    turn_rad: float
    value_m: float
    frame: str
    std_m: float = float("inf")
    points: int = 1


def shift_grams(jacobian: np.ndarray, shift_columns: np.ndarray, other_columns: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """Eq T1's two Gram matrices (3, 3): J_dᵀ (I − P) J_d (what no other column absorbs) and J_dᵀ J_d.

    Args:
        jacobian: (m, n) at the start, the always-estimated columns.
        shift_columns: (m, 3) the residual's change per unit common shift of the target points
            along the tool frame's x, y, z [1/m].
        other_columns: indices of ``jacobian``'s columns that can absorb a shift.
    """
    shift = np.asarray(shift_columns, dtype=float)
    others = np.asarray(jacobian, dtype=float)[:, np.asarray(other_columns, dtype=int)]
    rest = shift
    if others.shape[1]:
        basis, singular, _ = np.linalg.svd(others, full_matrices=False)
        basis = basis[:, singular > singular[0] * others.shape[0] * np.finfo(float).eps] if singular.size else basis
        rest = shift - basis @ (basis.T @ shift)
    return rest.T @ rest, shift.T @ shift


def principal_turns(absorbed: np.ndarray, total: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq T1's turns (3,) ascending [rad] and principal directions (3, 3) from its Gram matrices: the
    symmetric-definite generalised eigenproblem absorbed u = turn² total u (columns normalised)."""
    scale = np.sqrt(np.diag(total))
    if np.any(scale <= 0):
        return np.zeros(3), np.eye(3)
    values, vectors = scipy.linalg.eigh(absorbed / np.outer(scale, scale), total / np.outer(scale, scale))
    directions = vectors / scale[:, None]
    directions /= np.linalg.norm(directions, axis=0)
    return np.sqrt(np.clip(values, 0.0, None)), directions


def turn_along(absorbed: np.ndarray, total: np.ndarray, direction: np.ndarray) -> float:
    """Eq T1 for one unit direction [rad]."""
    return float(np.sqrt(max(direction @ absorbed @ direction, 0.0) / (direction @ total @ direction)))


def held_basis(directions: np.ndarray, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """The common shifts of ``n_points`` points along ``directions`` (3, h), and an orthonormal
    basis of the point coordinates (3P, 3P − h) that leaves them out."""
    common = np.tile(directions, (n_points, 1)) / np.sqrt(n_points)  # (3P, h), orthonormal
    return common, scipy.linalg.null_space(common.T)


def describe_direction(direction: np.ndarray, frame: str) -> str:
    """``z of flange`` for an axis, else ``(0.71, 0.71, 0.00) in flange``."""
    axis = int(np.argmax(np.abs(direction)))
    if abs(direction[axis]) > 1.0 - 1e-6:
        return f"{'xyz'[axis]} of {frame}"
    return f"({', '.join(f'{v:.2f}' for v in direction)}) in {frame}"


def held_reason(held: Sequence[HeldDirection] | HeldDirection) -> str:
    """Why the target's position along the held direction(s) is not determined, and what to do:
    one sentence per rule (not seen at all; seen but not determined), each naming its own directions."""
    group = [held] if isinstance(held, HeldDirection) else list(held)
    unseen = [h for h in group if not np.isfinite(h.std_m)]
    weak = [h for h in group if np.isfinite(h.std_m)]
    parts = [_reason(part) for part in (unseen, weak) if part]
    frame = group[0].frame
    return ("; and ".join(why for why, _ in parts) + f", so it is held at {frame}'s origin and the registration "
            "takes it; give --tool X,Y,Z,R,P,Y, or " + " and ".join(advice for _, advice in parts))


def _reason(group: list[HeldDirection]) -> tuple[str, str]:
    """Why one rule's directions are not determined, and what would determine them."""
    frame = group[0].frame
    where = f"x, y and z of {frame}" if len(group) == 3 else " and ".join(
        describe_direction(h.direction, frame) for h in group)
    turn = max(np.degrees(h.turn_rad) for h in group)
    shown = "0" if turn < np.degrees(NO_TURN_RAD) else f"{turn:.2g}"
    them = "it" if len(group) == 1 else "them"
    what = "the target's position" if group[0].points == 1 else f"the centroid of the target's {group[0].points} points"
    if np.isfinite(group[0].std_m):
        need = max(np.degrees(h.turn_rad) * h.std_m / MAX_TARGET_STD_M for h in group)
        why = (f"the data fix {what} along {them} only to ±{max(h.std_m for h in group) * 1e3:.3g} mm (more than "
               f"{MAX_TARGET_STD_M * 1e3:g} mm)")
        advice = (f"vary the tool's orientation by ≥ {need:.2g}° across {them}" if need <= 90.0 else
                  f"vary the tool's orientation far more across {them} (by over 90°: if it did vary, check the "
                  "data's axes and units)")
    else:
        why = f"{what} along {them} cannot be told from the sensor's position"
        advice = f"turn the tool about axes across {them}"
    return f"the tool's orientation turns by {shown}° RMS across {where}: {why}", advice


def _start_grams(problem: FitProblem) -> tuple[np.ndarray, np.ndarray]:
    """Eq T1's Gram matrices at a problem's start with the nominal kinematics (every target coordinate free)."""
    objective = replace(problem, point_basis=None).objective(
        np.array([], dtype=int), np.zeros(0 if problem.params is None else problem.params.size))
    jac = objective.jacobian(objective.start_vector())
    n_points = problem.start.points.shape[0]
    pts, reg, rot = (objective.blocks[name] for name in ("points", "registration", "rotation"))
    common, shape = held_basis(np.eye(3), n_points)
    point_columns = jac[:, pts]
    shift = point_columns @ common * np.sqrt(n_points)  # per unit common shift along x, y, z
    others = np.hstack([jac[:, reg], point_columns @ shape, jac[:, rot]])
    return shift_grams(others, shift, np.arange(others.shape[1]))


def hold_target(problem: FitProblem, extra: Sequence[HeldDirection] = ()
                ) -> tuple[tuple[HeldDirection, ...], FitProblem]:
    """Hold the directions of the target's position a problem's rows do not see (rule 1), and
    ``extra`` (rule 2), at the tool's origin: returns the held directions and the problem with them held:
    its start's points moved to the tool's origin along them and its ``point_basis`` the free directions
    (``problem`` itself when none is held)."""
    turns, directions = principal_turns(*_start_grams(problem))
    n_points = problem.start.points.shape[0]
    held = [HeldDirection(direction=d, turn_rad=float(t), value_m=0.0, frame=problem.chain.tip_link, points=n_points)
            for d, t in zip(directions.T, turns) if t < NO_TURN_RAD]
    if len(held) == 3:  # all three: the frame's own axes
        held = [replace(h, direction=axis) for h, axis in zip(held, np.eye(3))]
    for more in extra:  # orthogonal to those held already (Gram–Schmidt)
        direction = more.direction - sum((more.direction @ h.direction) * h.direction for h in held)
        if np.linalg.norm(direction) > 1e-6:
            held.append(replace(more, direction=direction / np.linalg.norm(direction)))
    held = held[:3]
    if not held:
        return (), problem
    held_dirs = np.column_stack([h.direction for h in held])
    _, basis = held_basis(held_dirs, problem.start.points.shape[0])
    points = problem.start.points
    start = replace(problem.start, points=points - (points @ held_dirs) @ held_dirs.T)
    return tuple(held), replace(problem, start=start, point_basis=basis)


def analysis_jacobian(problem: FitProblem, held: Sequence[HeldDirection], size: int) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobian the identifiability analysis orders (:func:`pincal.fit.identifiability.order_parameters`)
    with all ``size`` kinematic parameters free, at ``problem``'s start, and the held directions' columns
    (:func:`held_columns`; (m, 0) without).

    With orientations measured, both are taken with the target points at the tip link's origin. A
    point at m moves by dt + dθ × R m: its lever only mixes in rotations the same rows measure, and the
    estimated target absorbs the difference, so what the data determine does not depend on m. Its
    column lengths do: a 2 m probe lengthens a wrist rotation's position rows 2 m/rad, and the pivoted
    QR then keeps another member of a group of parameters equivalent up to the target (a different
    corrected URDF for the same robot; tests/test_frame_invariance.py). Positions alone are analysed
    where they were measured: without orientations, the lever is what lets them see a rotation.
    """
    if problem.data.rotations is not None:
        problem = replace(problem, start=replace(problem.start, points=np.zeros_like(problem.start.points)))
    objective = problem.objective(np.arange(size), np.zeros(size))
    jacobian = objective.jacobian(objective.start_vector())
    return jacobian, held_columns(problem, held, size) if held else np.zeros((jacobian.shape[0], 0))


def held_columns(problem: FitProblem, held: Sequence[HeldDirection], size: int) -> np.ndarray:
    """The residual's change per unit common shift of the target points along each held direction (m, h),
    at ``problem``'s start with all ``size`` kinematic parameters free."""
    directions = np.column_stack([h.direction for h in held])
    common, _ = held_basis(directions, problem.start.points.shape[0])
    objective = replace(problem, point_basis=common).objective(np.arange(size), np.zeros(size))
    return objective.jacobian(objective.start_vector())[:, objective.blocks["points"]] * np.sqrt(
        problem.start.points.shape[0])


def weak_target(problem: FitProblem, kept: np.ndarray, covariance: np.ndarray) -> tuple[HeldDirection, ...]:
    """Rule 2: the principal directions of the estimated target's common position whose standard
    deviation in a fit of ``problem`` (its ``kept`` kinematic parameters, its unknowns' ``covariance``)
    exceeds :data:`MAX_TARGET_STD_M`, each with the turn the rows gave it (eq T1 at the problem's start)."""
    size = 0 if problem.params is None else problem.params.size
    objective = problem.objective(kept, np.zeros(size))
    pts = objective.blocks["points"]
    if pts.stop == pts.start or covariance.size == 0:
        return ()
    n_points = problem.start.points.shape[0]
    basis = np.eye(3 * n_points) if problem.point_basis is None else problem.point_basis
    covariance = basis @ covariance[pts, pts] @ basis.T  # of the points' 3P coordinates [m²]
    mean = np.tile(np.eye(3), (1, n_points)) / n_points  # the points' common position
    values, directions = np.linalg.eigh(mean @ covariance @ mean.T)
    std = np.sqrt(np.clip(values, 0.0, None))
    weak = std > MAX_TARGET_STD_M
    if not np.any(weak):
        return ()
    absorbed, total = _start_grams(problem)
    return tuple(HeldDirection(direction=d, turn_rad=turn_along(absorbed, total, d), value_m=0.0,
                               frame=problem.chain.tip_link, std_m=float(sd), points=n_points)
                 for d, sd in zip(directions.T[weak], std[weak]))
