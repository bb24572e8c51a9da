"""Lateral (bending) compliance: a joint that deflects about the two axes orthogonal to its own under the gravity
moment it carries.

A revolute joint i with axis a_i and lateral axes u_i, v_i (:func:`pincal.model.mass_moments.lateral_axes`:
(u, v, a) right-handed, fixed in the joint's frame) carries the gravity wrench of the links beyond it (eq M1);
its moments about u_i and v_i (eq M3) bend it. Right after the joint's motion the chain turns

    about u_i by δ_u = c_u · M_u(q), then about v_i by δ_v = c_v · M_v(q)                       (eq L1)

(c_u, c_v [rad/(N·m)] the compliances, 1/stiffness; M_u, M_v [N·m] the URDF's inertias' moments, plus a payload,
:func:`pincal.model.mass_moments.bending_moments`), so that the next link's placement and everything beyond it
turn with the deflection. Without masses (``moments``) each moment is linear in the carried links' mass
moments (eq M1, M3 of :mod:`pincal.model.mass_moments`):

    δ_u = Σ_b θ_b · L_u,b(q),   δ_v = Σ_b θ'_b · L_v,b(q)                                      (eq L2)

θ = g₀ · (combination of mass moments) / k [rad, or rad/m for a combination led by a mass], the combinations of
each load its own (``u/PARAMETER:LINK``, ``v/PARAMETER:LINK``). A deflection is linear in the values:

    (δ_u, δ_v)_k = B_k · values,  B_k (2, n_values)                                             (eq L3)

and the tool's derivative by a value is its deflection's ``bend`` slot column
(:class:`pincal.model.sensitivity.SensitivityModel`, the twist about u_i or v_i through the joint's origin after
its motion) times B_k: exact at the deflected pose, as Pinocchio computes it there.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from pincal.errors import PincalError, did_you_mean
from pincal.model.chain import KinematicChain
from pincal.model.effects import BEND_EFFECTS, LATERAL_COMPONENTS, Effect, EffectInputs
from pincal.model.mass_moments import lateral_axes
from pincal.model.sensitivity import ParameterSlot, SensitivityModel, ToolPoses

__all__ = ["bend_slots", "lateral_basis", "bend_angles", "bent_tool_poses"]


def bend_slots(chain: KinematicChain) -> tuple[ParameterSlot, ...]:
    """The ``bend`` slots of every chain joint, u then v (eq L1): 2N, column 2j + c of :func:`bend_angles`."""
    return tuple(ParameterSlot(j, True, "bend", (float(axis[0]), float(axis[1]), float(axis[2])))
                 for j, joint in enumerate(chain.joints)
                 for axis in lateral_axes(np.asarray(joint.axis, dtype=float)))


def lateral_basis(effect: Effect, inputs: EffectInputs, joint: int) -> np.ndarray:
    """B_k of eq L3 at every row, (K, 2, n_values): the deflections (δ_u, δ_v) [rad] = B_k @ values; a value of
    unknown masses (``u/PARAMETER:LINK``) loads its own axis only."""
    k = len(inputs.q)
    out = np.zeros((k, 2, effect.n_values))
    if not effect.moments:  # eq L1
        if inputs.bending is None:
            raise PincalError(f"effect '{effect.label}': the rows' bending moments are missing")
        out[:, 0, 0], out[:, 1, 1] = inputs.bending[:, joint, 0], inputs.bending[:, joint, 1]
        return out
    names = [name.split("/", 1) for name in effect.moments]  # (component, PARAMETER:LINK)
    missing = [name for _, name in names if name not in inputs.load_names]
    if inputs.loads is None or missing:
        raise PincalError(f"effect '{effect.label}': no mass moment {', '.join(missing) or 'loads'} on the chain; "
                          f"{did_you_mean(missing[0] if missing else '', inputs.load_names, 'mass moments')}")
    for b, (component, name) in enumerate(names):  # eq L2: the loads about u and v are components 1 and 2
        c = LATERAL_COMPONENTS.index(component)
        out[:, c, b] = inputs.loads[:, joint, 1 + c, inputs.load_names.index(name)]
    return out


def bend_angles(effects: Sequence[Effect], values: Sequence[np.ndarray], inputs: EffectInputs,
                joint_names: Sequence[str]) -> np.ndarray | None:
    """The deflections of every chain joint's bend slots (:func:`bend_slots`) at every row, (K, 2N) [rad]; None
    without a lateral effect among ``effects``."""
    lateral = [(e, v) for e, v in zip(effects, values) if e.type in BEND_EFFECTS]
    if not lateral:
        return None
    out = np.zeros((len(inputs.q), 2 * len(joint_names)))
    for effect, value in lateral:
        if effect.joint not in joint_names:
            raise PincalError(f"effect '{effect.label}': no joint '{effect.joint}' on the chain; "
                              f"{did_you_mean(str(effect.joint), joint_names, 'joints')}")
        j = list(joint_names).index(str(effect.joint))
        out[:, 2 * j : 2 * j + 2] += lateral_basis(effect, inputs, j) @ np.atleast_1d(value)
    return out


def bent_tool_poses(chain: KinematicChain, q: npt.ArrayLike, bends: npt.ArrayLike) -> ToolPoses:
    """The chain's tool poses at readings ``q`` (K, N) with its joints deflected by ``bends`` (K, 2N) [rad]
    (:func:`bend_angles`, eq L1)."""
    model = SensitivityModel(chain, bend_slots(chain))
    model.set_state(chain.placements(), np.zeros((2 * chain.n_joints, 3)), chain.tool)
    return model.evaluate(q, bends)[0]
