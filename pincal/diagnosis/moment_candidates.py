"""Compliance candidates of a chain whose masses are unknown (``--masses unknown``, or a URDF without inertias).

A joint's deflection under gravity is its load over its stiffness, and without masses the load is linear in
the carried links' mass moments (eq M1–M2 of :mod:`pincal.model.mass_moments`): the candidate fits
θ = g₀ · (mass moments) / k_j instead of one compliance. The rows determine only some combinations:
:func:`base_combinations` keeps them (a pivoted QR of the load's columns over the rows, the project's
identifiability rule), :func:`moment_compliances` turns each joint's compliance candidate into one over its
combinations, and :func:`combination_words` says what each value stands for.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from pincal.fit.identifiability import RANK_TOLERANCE, order_parameters
from pincal.model.chain import KinematicChain
from pincal.model.effects import LATERAL_COMPONENTS, Effect, EffectInputs
from pincal.model.mass_moments import chain_mass_kg
from pincal.model.masses import Masses

__all__ = ["REGROUP_MIN", "NO_LOAD", "NO_TORQUE", "testable_pool", "MomentCombinations", "masses_unknown",
           "base_combinations", "moment_compliances", "combination_words", "needs_masses", "lateral_moments"]

#: Regrouping coefficients below this are not named in words: an m·c column is a direction cosine, an m column
#: a lever arm [m], so 1e-3 is 0.1 % of a moment or a millimetre of lever, the size of the calibrated geometry's
#: changes to a nominal link (the fit itself keeps every coefficient).
REGROUP_MIN = 1e-3
#: A load column whose RMS over the rows is below this carries no load [1 for m·c, m for m]: rounding of a
#: load that is zero in every row (about a vertical axis) is ~1e-16; 1e-9, as the 1e-9 N·m below which
#: diagnose calls a joint's URDF torque none (:data:`pincal.diagnosis.diagnose.NO_TORQUE`), is far above it.
NO_LOAD = 1e-9
#: Largest |gravity torque| [N·m or N] of a joint over the rows below which it has none: compliance and
#: gravity-flank backlash cannot be tested there (rounding of Pinocchio's RNEA is ~1e-12).
NO_TORQUE = 1e-9


def masses_unknown(chain: KinematicChain, masses: Masses, payload_kg: float) -> bool:
    """Whether compliances follow mass moments: ``--masses unknown``, or a URDF without any inertia on the chain
    and no payload (with ``--masses urdf``, a chain with some mass is today's torques)."""
    return masses == "unknown" or (chain_mass_kg(chain) == 0.0 and payload_kg == 0.0)


def needs_masses(effect: Effect) -> bool:
    """An effect that needs the URDF's gravity torques: a compliance under a load the URDF gives (its own or
    its driver's), a gravity backlash."""
    return (effect.type in ("compliance", "lateral") and not effect.moments) or effect.source == "gravity"


@dataclass(frozen=True)
class MomentCombinations:
    """The combinations of mass moments one load of one joint determines over some rows.

    Attributes:
        kept: the moments (``PARAMETER:LINK``) whose columns are independent, each standing for one combination.
        regrouped: for each kept moment, the others it stands for with their coefficients: the combination is
            kept + Σ coefficient × other (each other column is this combination of the kept ones').
    """

    kept: tuple[str, ...]
    regrouped: tuple[tuple[tuple[str, float], ...], ...]


def base_combinations(columns: np.ndarray, names: Sequence[str]) -> MomentCombinations:
    """The identifiable combinations of a load's columns over the rows (K, 4N): the m·c columns ordered by
    a pivoted QR first (:func:`pincal.fit.identifiability.order_parameters`: rank at ``RANK_TOLERANCE`` of
    the largest pivot), then the m columns those leave independent (a revolute chain's masses are moments
    of the links before them); each other column, by least squares, a combination of the kept."""
    columns = np.asarray(columns, dtype=float)
    used = [int(c) for c in np.flatnonzero(np.sqrt(np.mean(columns**2, axis=0)) > NO_LOAD)]
    moments = np.array([c for c in used if not names[c].startswith("m:")], dtype=int)
    masses = np.array([c for c in used if names[c].startswith("m:")], dtype=int)
    kept: list[int] = []
    if moments.size:
        order = order_parameters(columns, moments, np.array([], dtype=int))
        kept += [int(c) for c in order.order[: order.rank]]
    if masses.size:  # its pivots are of unit columns projected on the kept ones': 1 at most, so the tolerance holds
        order = order_parameters(columns, masses, np.asarray(kept, dtype=int))
        kept += [int(c) for c, pivot in zip(order.order[: order.rank], order.pivots) if pivot > RANK_TOLERANCE]
    dropped = [int(c) for c in used if c not in kept]
    coefficients = (np.linalg.lstsq(columns[:, kept], columns[:, dropped], rcond=None)[0] if dropped and kept
                    else np.zeros((len(kept), 0)))
    regrouped = tuple(
        tuple((names[d], float(coefficients[r, n])) for n, d in enumerate(dropped)
              if abs(coefficients[r, n]) >= REGROUP_MIN)
        for r in range(len(kept)))
    return MomentCombinations(tuple(names[c] for c in kept), regrouped)


def joint_combinations(effect: Effect, inputs: EffectInputs, component: int = 0) -> MomentCombinations:
    """The combinations the rows of ``inputs`` (with loads) determine for ``effect``'s joint's load: along its axis
    (``component`` 0, eq M2) or about its lateral axis u (1) or v (2) (eq M3)."""
    assert inputs.loads is not None  # with_loads
    j = inputs.joint_names.index(str(effect.joint))
    return base_combinations(inputs.loads[:, j, component, :], inputs.load_names)


def lateral_moments(effect: Effect, inputs: EffectInputs) -> tuple[str, ...]:
    """The mass moments a lateral compliance of unknown masses follows (eq L2 of :mod:`pincal.model.lateral`): the
    combinations the rows determine of its joint's load about u, then about v (``u/PARAMETER:LINK``)."""
    return tuple(f"{component}/{name}" for c, component in enumerate(LATERAL_COMPONENTS)
                 for name in joint_combinations(effect, inputs, 1 + c).kept)


def moment_compliances(pool: Sequence[Effect], inputs: EffectInputs,
                       chain: KinematicChain) -> tuple[list[Effect], list[Effect]]:
    """``pool`` with each joint's own compliance (and lateral compliance, :func:`lateral_moments`) turned into one
    over the mass-moment combinations its load has over the rows, and the candidates that cannot be tested without
    masses: a compliance whose load no combination moves (an axis along gravity in every row), a torque coupling,
    a gravity backlash."""
    out: list[Effect] = []
    untestable: list[Effect] = []
    for effect in pool:
        if effect.type in ("compliance", "lateral") and not effect.driver and not effect.moments:
            kept = joint_combinations(effect, inputs).kept if effect.type == "compliance" else lateral_moments(
                effect, inputs)
            (out if kept else untestable).append(replace(effect, moments=kept) if kept else effect)
        elif needs_masses(effect):
            untestable.append(effect)
        else:
            out.append(effect)
    return out, untestable


def testable_pool(pool: Sequence[Effect], inputs: EffectInputs, chain: KinematicChain,
                  unknown: bool) -> tuple[list[Effect], list[Effect]]:
    """``pool`` as the rows can test it, and the candidates they cannot: with ``unknown`` masses, compliances over
    mass-moment combinations (:func:`moment_compliances`); otherwise without the compliances and gravity backlash
    of a joint no gravity torque acts on in any row (a vertical axis; no mass beyond it), a torque coupling
    without its driver's torque, and the lateral compliance of a joint no moment bends about its lateral axes
    (eq M3)."""
    if unknown:
        return moment_compliances(pool, inputs, chain)
    weightless = {name for j, name in enumerate(inputs.joint_names) if np.max(np.abs(inputs.gravity[:, j])) < NO_TORQUE}
    unbent = {name for j, name in enumerate(inputs.joint_names)
              if inputs.bending is None or np.max(np.abs(inputs.bending[:, j]), initial=0.0) < NO_TORQUE}
    untestable = [e for e in pool if ((e.type == "compliance" or e.source == "gravity")
                                      and (e.driver or e.joint) in weightless)  # a torque coupling: its driver's
                  or (e.type == "lateral" and e.joint in unbent)]
    return [e for e in pool if e not in untestable], untestable


def _term(name: str, coefficient: float | None = None) -> str:
    """``m·x[link]`` for ``mx:link``, ``m[link]`` for ``m:link``; with a coefficient, signed."""
    parameter, link = name.split(":", 1)
    text = f"{'m·' + parameter[1] if len(parameter) == 2 else 'm'}[{link}]"
    if coefficient is None:
        return text
    return f"{'-' if coefficient < 0 else '+'} {abs(coefficient):.4g} {text}"


def combination_words(effect: Effect, inputs: EffectInputs, prismatic: bool) -> list[str]:
    """What each value of a compliance of unknown masses stands for, in its unit: ``g·(m·x[link_3] + 0.425
    m[link_4])/k[J2] [rad]`` (m·x: the link's mass moment along its joint frame's x [kg·m], m its mass [kg];
    g the gravity's magnitude [m/s²], k the joint's stiffness [N·m/rad]: rad, or rad/m for a combination led by
    a mass (its basis is a lever arm); m for a ``prismatic`` joint). A lateral compliance's (``u/...``, ``v/...``)
    are over its stiffness about that lateral axis, ``k_u[J3]`` (:mod:`pincal.model.lateral`)."""
    regrouped: dict[str, tuple[tuple[str, float], ...]] = {}
    for component in (0,) if effect.type != "lateral" else (1, 2):
        combos = joint_combinations(effect, inputs, component)
        prefix = "" if component == 0 else LATERAL_COMPONENTS[component - 1] + "/"
        regrouped.update({prefix + name: other for name, other in zip(combos.kept, combos.regrouped)})
    words = []
    for name in effect.moments:
        axis, _, moment = name.rpartition("/")
        terms = " ".join([_term(moment)] + [_term(other, c) for other, c in regrouped.get(name, ())])
        unit = "m" if prismatic else "rad/m" if moment.startswith("m:") else "rad"
        words.append(f"g·({terms})/k{'_' + axis if axis else ''}[{effect.joint}] [{unit}]")
    return words
