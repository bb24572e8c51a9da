"""When a search for effects has nothing left to work on: a model that reproduces its rows beyond what any
sensor resolves (noise-free rows, simulated). Its noise estimate is then rounding, and the BIC of
:mod:`pincal.diagnosis.screening`, computed in that noise, reads an improvement of picometres as strong
evidence: on noise-free coupled rows of a two-arm tree a sensor scale — nearly the geometry's lengths — was
adopted at −0.2 % (ΔBIC −63), and on noise-free UR5 rows at −0.16 %."""

from __future__ import annotations

import numpy as np

from pincal.diagnosis.verdicts import NEGLIGIBLE, NOISE_FLOOR

__all__ = ["REPRODUCED", "reproduced_note"]

#: Largest error [m or rad] below which a model reproduces its rows beyond what an effect could be told by:
#: NEGLIGIBLE of NOISE_FLOOR. An effect that explained such errors would change no measured coordinate by more,
#: which the NEGLIGIBLE rule already calls too small to matter. Below it the noise a fit estimates is rounding,
#: on which an improvement of picometres reads as a large ΔBIC.
REPRODUCED = NEGLIGIBLE * NOISE_FLOOR


def reproduced_note(position_m: np.ndarray, rotation_rad: np.ndarray | None, effects: int) -> str | None:
    """Why the search stops — the model (the geometry and ``effects`` adopted effects) reproduces every seen
    point, and every measured orientation, to within :data:`REPRODUCED` — or None.
    ``position_m``: each seen point's distance from the model [m] (NaN where not seen); ``rotation_rad``: each
    measured orientation's angle [rad] (NaN where not seen), or None."""
    def largest(values: np.ndarray | None) -> float | None:
        finite = None if values is None else np.asarray(values, dtype=float)[np.isfinite(values)]
        return None if finite is None or finite.size == 0 else float(np.max(finite))
    position, angle = largest(position_m), largest(rotation_rad)
    if position is None or position >= REPRODUCED or (angle is not None and angle >= REPRODUCED):
        return None
    model = "the geometry reproduces" if effects == 0 else f"the geometry and {effects} effect(s) reproduce"
    return (f"{model} every row to within {position:.2g} m" + ("" if angle is None else f" and {angle:.2g} rad")
            + f", below the {REPRODUCED:g} m (rad) an effect would have to change to be told: no further effect "
            "is sought")
