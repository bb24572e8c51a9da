"""What a DH table's numbers mean, as constants: the two conventions
(:func:`pincal.model.dh.table.dh_chain_origins` implements both) and the angle beyond which radians are
taken for degrees.

Constants only, importing nothing but :mod:`math`: the command line's parser takes the choices of
``urdf-from-dh --convention`` and the check of ``--tool`` and ``--flange`` from here without loading
the DH tables (numpy) or the chain (Pinocchio).
"""

import math

__all__ = ["DH_CONVENTIONS", "MAX_ANGLE_RAD", "RIGHT_ANGLE_TOL", "is_right_angles_in_radians"]

#: The two DH conventions of :func:`pincal.model.dh.table.dh_chain_origins`: ``standard`` (distal,
#: Rz(θ+q) Tz(d) Tx(a) Rx(α)) and ``modified`` (Craig's, Rx(α_i-1) Tx(a_i-1) Rz(θ_i+q) Tz(d_i)).
DH_CONVENTIONS = ("standard", "modified")
#: An angle beyond one turn [rad] is taken for degrees given as radians (DH table files,
#: :mod:`pincal.model.dh.files`; ``--tool`` and ``--flange``).
MAX_ANGLE_RAD = 2.0 * math.pi
#: How close to a multiple of π/2 a number is taken for right angles written in radians: k·π/2 to two
#: decimals (1.57, 3.14, 4.71, 6.28) is at most 5e-3 from it (3.2e-3 for 6.28), the rounding's half unit.
#: Read as degrees such a number (a 1.57° twist) is no design angle: DH twists and offsets of arms are
#: multiples of 90° (consecutive axes parallel or perpendicular), and calibrated deviations from them are
#: of the physical prior's scale, 0.5°.
RIGHT_ANGLE_TOL = 5e-3


def is_right_angles_in_radians(value: float) -> bool:
    """Whether ``value`` is a non-zero multiple of π/2 (up to one turn) to :data:`RIGHT_ANGLE_TOL`: a
    DH angle in radians, not degrees (:mod:`pincal.model.dh.files` refuses it with ``degrees``)."""
    turns = round(value / (math.pi / 2.0))
    return 1 <= abs(turns) <= 4 and abs(value - turns * math.pi / 2.0) <= RIGHT_ANGLE_TOL
