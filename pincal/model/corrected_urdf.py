"""Write a calibrated chain back into the user's URDF.

Pinocchio merges fixed joints: the placement of a movable joint is the product
of the fixed-joint origins before it and its own URDF origin, and the tip
link's placement is the product of the fixed origins after the last movable
joint. A calibrated placement M' is written into the movable joint's own origin
as ``O' = O · M⁻¹ · M'`` (O, M nominal), which leaves every fixed joint and every
other element of the file untouched; the tip's change goes into the fixed joint
whose child is the tip link.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from pincal.errors import ModelError
from pincal.model.chain import KinematicChain
from pincal.model.description import read_description
from pincal.model.urdf import XacroArgs, write_urdf_with_origins
from pincal.model.urdf_elements import joint_origins, parent_joint

__all__ = ["corrected_origins", "write_corrected_urdf"]


def corrected_origins(
    urdf_path: str | Path,
    chain: KinematicChain,
    nominal_placements: Sequence[np.ndarray],
    xacro_args: XacroArgs = None,
) -> dict[str, np.ndarray]:
    """URDF joint origins realising the chain's current placements.

    Args:
        urdf_path: the URDF the chain was loaded from (or its ``*.xacro``).
        chain: the calibrated chain.
        nominal_placements: the chain's placements as loaded (see
            :meth:`KinematicChain.placements`).
        xacro_args: the arguments the chain's xacro file was expanded with.
    """
    urdf_path = Path(urdf_path)
    robot = read_description(urdf_path, xacro_args).root()
    origins = joint_origins(robot)
    current = chain.placements()
    out: dict[str, np.ndarray] = {}
    for name, nominal, new in zip(chain.joint_names, nominal_placements[:-1], current[:-1]):
        out[name] = origins[name] @ np.linalg.inv(nominal) @ new
    tip_nominal, tip_new = nominal_placements[-1], current[-1]
    tip_joint, fixed = parent_joint(robot, chain.tip_link)
    if tip_joint is not None and fixed:
        out[tip_joint] = origins[tip_joint] @ np.linalg.inv(tip_nominal) @ tip_new
    elif np.abs(tip_new - tip_nominal).max() > 0:
        raise ModelError(
            f"{urdf_path}: link '{chain.tip_link}' is not attached by a fixed joint, so its "
            "calibrated placement cannot be written; choose a tip link below a fixed joint"
        )
    return out


def write_corrected_urdf(
    source: str | Path,
    destination: str | Path,
    chain: KinematicChain,
    nominal_placements: Sequence[np.ndarray],
    comment: str | None = None,
    verify: Callable[[Path], None] | None = None,
    xacro_args: XacroArgs = None,
) -> None:
    """Write ``source`` with the chain's calibrated placements to ``destination``;
    ``verify`` checks the complete file before it replaces ``destination``. A
    ``*.xacro`` source (expanded with ``xacro_args``) gives a plain URDF that says
    in a comment which xacro file and arguments it came from."""
    origins = corrected_origins(source, chain, nominal_placements, xacro_args)
    write_urdf_with_origins(source, destination, origins, comment=comment, verify=verify, xacro_args=xacro_args)
