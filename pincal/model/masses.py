"""Where a chain's gravity loads come from, as constants: ``urdf`` (the URDF's inertias, Pinocchio's
``computeGeneralizedGravity``) or ``unknown`` (the carried links' mass moments, :mod:`pincal.model.mass_moments`).

Constants only, importing nothing but :mod:`typing`: the command line's parser takes the choices of
``diagnose --masses`` from here without loading Pinocchio.
"""

from typing import Literal

__all__ = ["Masses", "MASSES", "DEFAULT_MASSES"]

#: ``diagnose --masses``: ``urdf`` the URDF's inertias (a URDF without any, and no payload, counts as
#: ``unknown``); ``unknown``: compliances follow the carried links' mass moments.
Masses = Literal["urdf", "unknown"]
MASSES: tuple[Masses, ...] = ("urdf", "unknown")
DEFAULT_MASSES: Masses = "urdf"
