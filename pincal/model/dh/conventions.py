"""What a DH table's numbers mean, as constants: the two conventions
(:func:`pincal.model.dh.table.dh_chain_origins` implements both) and the angle beyond which radians are
taken for degrees.

Constants only, importing nothing but :mod:`math`: the command line's parser takes the choices of
``urdf-from-dh --convention`` and the check of ``--tool`` and ``--flange`` from here without loading
the DH tables (numpy) or the chain (Pinocchio).
"""

import math

__all__ = ["DH_CONVENTIONS", "MAX_ANGLE_RAD"]

#: The two DH conventions of :func:`pincal.model.dh.table.dh_chain_origins`: ``standard`` (distal,
#: Rz(θ+q) Tz(d) Tx(a) Rx(α)) and ``modified`` (Craig's, Rx(α_i-1) Tx(a_i-1) Rz(θ_i+q) Tz(d_i)).
DH_CONVENTIONS = ("standard", "modified")
#: An angle beyond one turn [rad] is taken for degrees given as radians (DH table files,
#: :mod:`pincal.model.dh.files`; ``--tool`` and ``--flange``).
MAX_ANGLE_RAD = 2.0 * math.pi
