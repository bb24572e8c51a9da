"""Gravity loads of a chain whose masses are unknown: linear in the links' mass moments.

At rest, the wrench joint i transmits to the links it carries is linear in their static inertial
parameters π_j = (m_j, m_j c_j) [kg, kg·m] (mass, and first mass moment about joint j's origin in its frame):

    F_i(q) = Σ_{j ≥ i} iX*_j Y_j(q) π_j                                         (eq M1)

with Y_j the 6 × 4 static part of Pinocchio's ``jointBodyRegressor`` after ``rnea`` at rest (the body's
gravity wrench in its joint frame, Pinocchio's sign: the wrench that holds it) and iX*_j the force transform
from joint j's frame to joint i's. Its parts, in joint i's frame at its origin:

    load along the axis a_i:   a_i · n_i (revolute, N·m), a_i · f_i (prismatic, N)   (eq M2)
    bending about u_i, v_i:    u_i · n_i, v_i · n_i (revolute; u_i, v_i ⟂ a_i)        (eq M3)

(f_i, n_i the force and moment of F_i); eq M2 is ``computeGeneralizedGravity``'s torque. Pinocchio's
``computeStaticRegressor`` is the centre of mass's regressor, not the joints' loads: eq M1 builds them.

A compliance c_i = 1/k_i turns a load into a deflection, so the deflection is linear in the
combinations π/k_i. :func:`gravity_loads` divides the loads by g₀ = |gravity| so that the fitted values
are g₀ · (mass moment) / k [rad for a revolute joint: N/kg · kg·m / (N·m/rad)], and the basis columns of
m·c are direction cosines (dimensionless), those of m lever arms [m] (their values in rad/m).
The data determine only some combinations (a link's moment along the joint axis loads nothing; the mass of a
link is a moment of the link before it): :func:`pincal.diagnosis.moment_candidates.base_combinations` keeps
those the rows determine.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.model.chain import KinematicChain

__all__ = ["MOMENT_PARAMETERS", "LOAD_COMPONENTS", "moment_names", "chain_mass_kg", "lateral_axes", "payload_model",
           "gravity_loads", "bending_moments"]

#: The static inertial parameters of a body, in Pinocchio's order: m [kg], m·c_x, m·c_y, m·c_z [kg·m].
MOMENT_PARAMETERS = ("m", "mx", "my", "mz")
#: The load components of :func:`gravity_loads`: along the joint's axis (eq M2), about the two axes
#: orthogonal to it (eq M3).
LOAD_COMPONENTS = ("axis", "u", "v")


def moment_names(chain: KinematicChain) -> tuple[str, ...]:
    """``PARAMETER:LINK`` of every static parameter of the model's moving bodies (4 per joint of the chain's
    Pinocchio model, in its order; the body named by the joint's child link, fixed links below it part of it),
    in :func:`gravity_loads`' column order."""
    model = chain.model
    links = []
    for jid in range(1, model.njoints):
        bodies = [f.name for f in model.frames if f.type == pin.FrameType.BODY and f.parentJoint == jid]
        links.append(bodies[0] if bodies else model.names[jid])
    return tuple(f"{p}:{link}" for link in links for p in MOMENT_PARAMETERS)


def chain_mass_kg(chain: KinematicChain) -> float:
    """The mass the URDF gives the chain model's moving bodies [kg] (0: a URDF without inertias)."""
    return float(sum(chain.model.inertias[jid].mass for jid in range(1, chain.model.njoints)))


def lateral_axes(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """u, v: unit vectors with (u, v, axis) right-handed; u the joint frame's axis least aligned with ``axis``
    made orthogonal to it (x for a z axis: u = x, v = y)."""
    axis = axis / np.linalg.norm(axis)
    seed = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = seed - axis * (seed @ axis)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def payload_model(chain: KinematicChain, payload_kg: float = 0.0, payload_point: np.ndarray | None = None) -> pin.Model:
    """The chain's Pinocchio model with a point mass ``payload_kg`` [kg] at ``payload_point`` (in the tool frame
    [m], default its origin) on the tip's joint; the model itself without a payload."""
    if payload_kg <= 0:
        return chain.model
    model = chain.model.copy()
    point = np.zeros(3) if payload_point is None else np.asarray(payload_point, dtype=float)
    tip = model.frames[chain.tip_frame_id]
    at_tool = tip.placement * pin.SE3(chain.tool) * pin.SE3(np.eye(3), point)
    model.appendBodyToJoint(tip.parentJoint, pin.Inertia(payload_kg, np.zeros(3), np.zeros((3, 3))), at_tool)
    return model


def bending_moments(chain: KinematicChain, q: npt.ArrayLike, payload_kg: float = 0.0,
                    payload_point: np.ndarray | None = None) -> np.ndarray:
    """Eq M3 of the URDF's inertias (plus a payload, :func:`payload_model`): the gravity moment each chain joint
    carries about its u and v axes (:func:`lateral_axes`), (K, N, 2) [N·m]; zero for a prismatic joint.
    Pinocchio's ``rnea`` at rest leaves in ``data.f`` the wrench each joint transmits to the links it carries, in
    its frame: the sum of eq M1 with the URDF's π."""
    model = payload_model(chain, payload_kg, payload_point)
    data = model.createData()
    configurations = chain.configurations(q)
    axes = np.array([lateral_axes(np.asarray(j.axis, dtype=float)) if j.kind != "prismatic" else np.zeros((2, 3))
                     for j in chain.joints])  # (N, 2, 3)
    zero = np.zeros(model.nv)
    out = np.zeros((len(configurations), chain.n_joints, 2))
    for k, configuration in enumerate(configurations):
        pin.rnea(model, data, configuration, zero, zero)
        moments = np.array([data.f[jid].angular for jid in chain.joint_ids])  # (N, 3)
        out[k] = np.einsum("nij,nj->ni", axes, moments)
    return out


def gravity_loads(chain: KinematicChain, q: npt.ArrayLike) -> np.ndarray:
    """The gravity loads of every chain joint per static parameter, divided by g₀ (module docstring),
    (K, N, 3, 4B): row k, joint i, component (:data:`LOAD_COMPONENTS`: eq M2, eq M3 about u_i, eq M3 about
    v_i; the bending parts are zero for a prismatic joint), column of :func:`moment_names` (B the model's
    moving bodies). Loads [N·m or N] = this × g₀ @ π.

    Eq M1's sum runs over each joint's subtree, children before parents (Pinocchio numbers a child after
    its parent): a serial chain and a tree of several tips alike."""
    model = chain.model
    data = model.createData()
    configurations = chain.configurations(q)
    n, bodies = chain.n_joints, model.njoints - 1
    g0 = float(np.linalg.norm(model.gravity.linear)) or 1.0
    ids = chain.joint_ids
    rows = np.zeros((len(configurations), n, 3, 4 * bodies))
    projections = []
    for joint in chain.joints:
        u, v = lateral_axes(np.asarray(joint.axis, dtype=float))
        a = np.asarray(joint.axis, dtype=float)
        if joint.kind == "prismatic":
            projections.append(np.vstack([np.r_[a, 0, 0, 0], np.zeros((2, 6))]))
        else:
            projections.append(np.vstack([np.r_[0, 0, 0, a], np.r_[0, 0, 0, u], np.r_[0, 0, 0, v]]))
    zero = np.zeros(model.nv)
    for k, configuration in enumerate(configurations):
        pin.forwardKinematics(model, data, configuration)
        pin.rnea(model, data, configuration, zero, zero)  # sets each body's acceleration with gravity
        carried = np.zeros((model.njoints, 6, 4 * bodies))  # eq M1 of each joint, in its frame
        for jid in range(model.njoints - 1, 0, -1):
            carried[jid, :, 4 * jid - 4 : 4 * jid] += pin.jointBodyRegressor(model, data, jid)[:, :4]
            parent = model.parents[jid]
            if parent > 0:
                carried[parent] += data.liMi[jid].toDualActionMatrix() @ carried[jid]
        for i, jid in enumerate(ids):
            rows[k, i] = projections[i] @ carried[jid]
    # a driver's torque carries its followers' (virtual work, eq M1 of the <mimic>: tau_d + m tau_f), as the
    # URDF-mass torques do (pincal.model.effects.gravity_torques); the bending parts are the joint's own
    rows[:, :, 0, :] = chain.followed_columns(rows[:, :, 0, :])
    return rows / g0
