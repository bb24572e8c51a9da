"""The catalogue of candidate effects ``diagnose`` tries on a chain (:mod:`pincal.model.effects`)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from pincal.model.chain import KinematicChain
from pincal.model.effects import BACKLASH_SOURCES, HARMONICS, Effect

__all__ = ["PARALLEL_AXES_RAD", "parallel_neighbours", "candidate_effects"]

#: Angle between two joint axes below which they count as parallel [rad]: 0.6°, so that a URDF pincal
#: calibrated (its axes turned by ~1e-4 rad) still qualifies.
PARALLEL_AXES_RAD = 1e-2


def parallel_neighbours(chain: KinematicChain) -> set[tuple[int, int]]:
    """Neighbouring revolute joints (i, i + 1) whose axes are parallel at the neutral configuration
    (within :data:`PARALLEL_AXES_RAD`): where a controller may read one joint against the other (a
    parallelogram arm's J3 from the horizontal, J2 ∥ J3), the couplings the catalogue offers."""
    model = chain.model
    data = model.createData()
    jacobian = pin.computeJointJacobians(model, data, pin.neutral(model))
    axes = [jacobian[3:, model.joints[i].idx_v] for i in chain.joint_ids]
    kinds = [spec.kind for spec in chain.joint_specs]
    return {(i, i + 1) for i in range(len(axes) - 1)
            if "prismatic" not in (kinds[i], kinds[i + 1])
            and np.linalg.norm(np.cross(axes[i], axes[i + 1])) < PARALLEL_AXES_RAD}


def candidate_effects(chain: KinematicChain, has_time: bool, lateral: bool = False) -> list[Effect]:
    """Every candidate on every joint of the chain (with ``lateral``, each revolute joint's lateral compliance
    too, :mod:`pincal.model.lateral`), plus the sensor's; couplings between the
    :func:`parallel_neighbours` only, of the reading and of the gravity torque (a compliance driven by the
    neighbour's torque): a parallelogram or a counterbalance links J2's and J3's loads."""
    out: list[Effect] = []
    names = list(chain.joint_names)
    parallel = parallel_neighbours(chain)
    for j, joint in enumerate(names):
        out.append(Effect("compliance", joint))
        if lateral and chain.joints[j].kind != "prismatic":  # a revolute joint bends about its lateral axes
            out.append(Effect("lateral", joint))
        out.append(Effect("encoder_scale", joint))
        out += [Effect("cyclic", joint, harmonic=h) for h in HARMONICS]
        out += [Effect("backlash", joint, source=s) for s in BACKLASH_SOURCES]
        out += [Effect(kind, joint, driver=names[i]) for i in (j - 1, j + 1) for kind in ("coupling", "compliance")
                if (min(i, j), max(i, j)) in parallel]
    if has_time:
        out.append(Effect("drift"))
    out.append(Effect("sensor_scale"))
    return out
