"""Which rotations of the registration the rows cannot determine: rows on one line.

Rows whose modelled target points lie on one line (a straight-line path at one tool orientation)
fix the registration's rotation Omega but about that line: turning the sensor about it turns every
measured point about the line, and the registration's translation tau takes the rest (offsets along
the line do not change). With orientations measured, the target's rotation R_T takes the turn of
G_k = Omega R_k R_T (Omega turned about the line, R_T turned back about the line's direction in the
tool frame), so a correct ``--tool`` (R_T known) fixes it; positions alone never do.

With Phi the Jacobian columns of the registrations' rotations (right perturbations,
Omega_s = Omega_s0 exp(phi_s): 3 per session, axes in the robot base frame) and P the projection onto
every other always-estimated column at the start (the translations, the target's free coordinates
and its rotation; nominal kinematics), the information on a rotation about a unit axis a is
aᵀ Phiᵀ (I − P) Phi a, and

    seen(a) = sqrt( aᵀ Phiᵀ (I − P) Phi a  /  λ_max )                              (H1)

with λ_max the largest eigenvalue of Phiᵀ (I − P) Phi: the lever the data give a rotation about a,
as a fraction of the best-seen rotation's. For points alone, Phiᵀ (I − P) Phi is the weighted
Σ_k [d_k]×ᵀ [d_k]× of the points' offsets d_k from their centroid, whose eigenvalues about their
principal axes are s₁² + s₂², s₀² + s₂² and s₀² + s₁² (s_i the RMS spreads along the axes,
largest first): seen(line) ≈ s₁ / s₀, the points' distance off their line per unit of spread along
it. An eigenvector of Phiᵀ (I − P) Phi with seen at most :data:`pincal.fit.sessions.LINE_RATIO`
(1e-4: 0.1 mm per metre, the path error of a straight line replayed through encoders, the test that
starts such a session by :func:`pincal.fit.registration.register_line`) is held at the start's value
— the rotation :func:`~pincal.fit.registration.register_line` states — and left out of the
registrations' unknowns (:class:`pincal.residuals.sensor.SensorResidual`'s ``registration_basis``);
everything else is calibrated. The held rotation only turns the rows' errors across the line, so
the rows along it are predicted as well as the data allow; rows off it (other positions, other
orientations) meet its error: the model is checked only near the path
(:func:`pincal.fit.plausibility.check_calibration`'s ``path`` warning).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg

from pincal.fit.sensor_problem import FitProblem
from pincal.fit.sessions import LINE_RATIO
from pincal.fit.target_hold import describe_direction, shift_grams

__all__ = ["HeldRotation", "held_rotations", "hold_registration", "rotation_reason", "path_warning"]


@dataclass(frozen=True)
class HeldRotation:
    """A rotation of a session's registration the rows leave free, held at the start's value.

    Attributes:
        session: the session's name ("" when there is only one).
        axis: unit vector in the robot base (URDF root) frame, (3,): the line's direction.
        seen: eq H1's fraction (0: not seen at all).
        frame: the URDF root link.
        orientations: whether the rows had orientations (the target's rotation took the turn).
        tool_known: whether the target was known (``--tool``).
    """

    session: str
    axis: np.ndarray
    seen: float
    frame: str
    orientations: bool
    tool_known: bool


def held_rotations(jacobian: np.ndarray, registration_columns: slice, other_columns: np.ndarray,
                   sessions: Sequence[str], frame: str, orientations: bool, tool_known: bool
                   ) -> tuple[tuple[HeldRotation, ...], np.ndarray]:
    """Eq H1 on a Jacobian (m, n) at the start: the held rotations and their vectors in the registrations'
    6S coordinates (6S, h), each the eigenvector's rotation part of the one session it turns most."""
    rotations = np.array([registration_columns.start + 6 * s + i for s in range(len(sessions)) for i in range(3)])
    absorbed, _ = shift_grams(jacobian, jacobian[:, rotations], other_columns)
    values, vectors = scipy.linalg.eigh(absorbed)
    seen = np.sqrt(np.clip(values, 0.0, None) / max(values[-1], np.finfo(float).tiny))
    held, columns = [], []
    for fraction, vector in zip(seen, vectors.T):
        if fraction > LINE_RATIO:
            break  # ascending
        per_session = vector.reshape(-1, 3)
        s = int(np.argmax(np.linalg.norm(per_session, axis=1)))
        axis = per_session[s] / np.linalg.norm(per_session[s])
        axis = axis if axis[int(np.argmax(np.abs(axis)))] > 0 else -axis  # one sign: the largest component +
        held.append(HeldRotation(sessions[s], axis, float(fraction), frame, orientations, tool_known))
        column = np.zeros(6 * len(sessions))
        column[(np.arange(len(sessions))[:, None] * 6 + np.arange(3)).ravel()] = vector
        columns.append(column)
    return tuple(held), np.column_stack(columns) if columns else np.zeros((6 * len(sessions), 0))


def hold_registration(problem: FitProblem) -> tuple[tuple[HeldRotation, ...], FitProblem]:
    """Hold the registration rotations a problem's rows leave free (eq H1, at its start with the nominal
    kinematics and the target held as it is): returns the held rotations and the problem with them held,
    its ``registration_basis`` the registrations' free unknowns (``problem`` itself when none is held)."""
    size = 0 if problem.params is None else problem.params.size
    objective = problem.objective(np.array([], dtype=int), np.zeros(size))
    jacobian = objective.jacobian(objective.start_vector())
    reg = objective.blocks["registration"]
    translations = [reg.start + 6 * s + 3 + i for s in range(objective.n_sessions) for i in range(3)]
    others = np.concatenate([translations, np.arange(reg.stop, objective.blocks["effects"].start)]).astype(int)
    names = problem.session_names if len(problem.session_names) > 1 else ("",)  # one: named in no message
    held, vectors = held_rotations(jacobian, reg, others, names, problem.chain.root_link,
                                   problem.data.rotations is not None, not problem.fit_target)
    if held:
        return held, replace(problem, registration_basis=scipy.linalg.null_space(vectors.T))
    return held, problem


def rotation_reason(held: HeldRotation) -> str:
    """Why a registration rotation is held, at what, and what would determine it."""
    which = f"session '{held.session}': " if held.session else ""
    line = describe_direction(held.axis, held.frame)
    if held.orientations:
        cannot = "cannot be told from the target's rotation on the tool about that line"
        rule = "where the target's rotation on the tool is the nearest the tool frame's (the smallest angle)"
        advice = "give --tool X,Y,Z,R,P,Y (the measured frame on the tip link fixes it), or add rows off the line"
    else:
        cannot = "cannot be told from positions on that line" + (" (the tool known or not)" if held.tool_known else "")
        rule = "where the robot base's z axis turns the nearest the sensor's z axis (a levelled sensor)"
        advice = "add rows off the line (a second line, an arc) or measure orientations (qx,qy,qz,qw) with --tool"
    return (f"{which}the modelled tool positions lie on one line ({line}) at one tool orientation: the sensor's "
            f"rotation about it {cannot}, so it is held {rule}; the rows along the line are predicted as well as "
            f"the data allow, rows off it are not checked; {advice}")


def path_warning(held: Sequence[HeldRotation]) -> str | None:
    """The plausibility warning of a calibration whose registration rotation was held (None if none was)."""
    if not held:
        return None
    lines = " and ".join(describe_direction(h.axis, h.frame) for h in held)
    return (f"the rows lie on one line ({lines}) at one tool orientation: the calibrated model is checked only near "
            "that path (the sensor's rotation about the line is held, identifiability.not_determined_rotations); "
            "other positions and orientations are predicted by a geometry no row tested. Before using it "
            "elsewhere, measure rows off the line (a second line, an arc, a raster) and calibrate again, or check "
            "it there with pincal evaluate")
