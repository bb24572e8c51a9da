"""What the adopted effects leave: a generic correction per joint, and an effect's partial residual.

After :func:`pincal.diagnosis.diagnose.diagnose` adopts what it can explain,
:func:`remaining_structure` fits per joint a generic correction of the joint
angle (its reading's scale, harmonics :data:`pincal.model.effects.HARMONICS`)
and reports strong evidence (ΔBIC < :data:`pincal.diagnosis.verdicts.EVIDENCE`)
that structure remains. :func:`partial_residual` gives, for an adopted joint
effect, its component-plus-residual against its driver, for the plots.
"""

from __future__ import annotations

from typing import cast

import numpy as np

from pincal.diagnosis.effect_fits import EffectModel
from pincal.diagnosis.screening import (
    SCREEN_CONDITION,
    FitObjective,
    Linearisation,
    bic,
    may_reach,
    n_prior_rows,
    testable,
)
from pincal.diagnosis.verdicts import EVIDENCE
from pincal.errors import CalibrationError
from pincal.fit.solver import Solution
from pincal.model.chain import KinematicChain
from pincal.model.effect_units import load_unit, shift_unit
from pincal.model.effects import HARMONICS, JOINT_EFFECTS, Effect, EffectInputs, joint_basis

__all__ = ["GENERIC_EVALUATIONS", "remaining_structure", "partial_residual"]

#: Evaluations allowed to the full fit of a generic correction (an ill-posed one
#: crawls along a valley of equivalent corrections; its linearised ΔBIC is then used). A fixed budget
#: here, unlike the candidates' (:func:`pincal.diagnosis.effect_fits.fit_while_gaining`): this fit is
#: never adopted, it only says that structure remains, and the better of the two ΔBIC errs towards saying so.
GENERIC_EVALUATIONS = 20


def remaining_structure(model: EffectModel, adopted: list[Effect], objective: FitObjective, solution: Solution,
                        chain: KinematicChain, freedom: tuple[int, float]) -> str | None:
    """Fit a generic joint-space correction per joint; report strong evidence of structure
    (``model``: the search's model, whose ``fit(effects, x0, values, max_evaluations)`` refits).

    Joints whose correction the fit's ``freedom`` (:func:`residual_freedom`) cannot test are
    left out; joints whose linearised test is far from significant are not refitted; a
    full fit stopped at :data:`GENERIC_EVALUATIONS` counts with the better of
    its ΔBIC and the linearised one."""
    base_bic = bic(solution.residual, solution.x.size, n_prior_rows(objective))
    names, corrections = [], []
    for name in chain.joint_names:
        generic = [Effect("encoder_scale", name)] + [Effect("cyclic", name, harmonic=h) for h in HARMONICS]
        generic = [e for e in generic if e not in adopted]
        # a joint whose generic terms are all adopted has nothing left to test
        if generic and testable(freedom, sum(e.n_values for e in generic), EVIDENCE):
            names.append(name)
            corrections.append(generic)
    if not corrections:
        return None
    columns = iter(objective.effect_columns(solution.x, [e for generic in corrections for e in generic]))
    blocks = [np.hstack([next(columns) for _ in generic]) for generic in corrections]
    scores = Linearisation(solution, n_prior_rows(objective)).test(blocks, base_bic)
    found = []
    for name, generic, score in zip(names, corrections, scores):
        if score.condition <= SCREEN_CONDITION and not may_reach(score.delta_bic, EVIDENCE):
            continue
        try:
            _, sol = model.fit(adopted + generic, solution.x[: objective.blocks["effects"].start],
                               [solution.x[sl] for sl in objective.effect_slices]
                               + [np.zeros(e.n_values) for e in generic],
                               max_evaluations=GENERIC_EVALUATIONS)
        except CalibrationError:
            continue
        delta = bic(sol.residual, sol.x.size, n_prior_rows(objective)) - base_bic
        if not sol.converged and score.condition <= SCREEN_CONDITION:  # the linear score is trusted there
            delta = min(delta, score.delta_bic)
        if delta < EVIDENCE:
            found.append(f"{name} (ΔBIC {delta:.1f})")
    if not found:
        return None
    return ("structure remains that no candidate explains: a generic correction of the joint angle "
            f"(linear + harmonics 1, 2) still fits much better on {', '.join(found)}")


_DRIVERS = {
    "encoder_scale": "joint reading q_j",
    "cyclic": "joint reading q_j",
}


def _load_label(chain: KinematicChain, driver: str | None, joint: str) -> str:
    """The axis label of a gravity load: a joint's own (``driver`` None) or ``driver``'s, a torque [N·m] of
    a revolute joint, a force [N] of a prismatic one (:mod:`pincal.model.effect_units`)."""
    force = chain.joint_kinds[joint if driver is None else driver] == "prismatic"
    subject = "tau_j" if driver is None else f"of {driver}"
    return f"{'gravity force' if force else 'gravity torque'} {subject} [{load_unit(force)}]"


def partial_residual(effect: Effect, objective: FitObjective, solution: Solution, inputs: EffectInputs,
                     chain: KinematicChain) -> tuple[np.ndarray | None, str, np.ndarray | None, np.ndarray | None]:
    """Component-plus-residual of a joint effect: per row, the fitted shift plus the
    remaining residual of the fit expressed as a shift of that joint (least
    squares on the joint's Jacobian column), against the effect's driver."""
    if effect.type not in JOINT_EFFECTS:
        return None, "", None, None
    joint = cast(str, effect.joint)  # every joint effect names its joint
    j = chain.joint_names.index(joint)
    basis = joint_basis(effect, inputs, j)
    fitted = basis @ solution.x[objective.effect_slices[-1]]
    _, sens, target, world = objective.state(solution.x)
    residual = objective.predicted_points(solution.x) - objective.g  # (K, P, 3)
    omega, _ = objective.row_frames(target)  # (3, 3), or (K, 3, 3) with several sessions

    def sensed(v: np.ndarray) -> np.ndarray:  # base-frame velocities (K, 3) in each row's sensor frame
        return v @ omega.T if omega.ndim == 2 else np.einsum("kij,kj->ki", omega, v)

    column = np.stack([sensed(sens.joint_point_velocity(world[:, p, :])[:, j, :])
                       for p in range(world.shape[1])], axis=1)  # (K, P, 3)
    a = column.reshape(len(column), -1)
    r = residual.reshape(len(residual), -1)
    shift = fitted - np.einsum("ki,ki->k", a, r) / np.maximum(np.einsum("ki,ki->k", a, a), 1e-300)
    if effect.type == "backlash" and effect.source == "gravity":  # shift = value · sign(tau_j): a step at 0
        driver, label = inputs.gravity[:, j], _load_label(chain, None, joint)
    elif effect.type == "backlash":
        driver, label = basis[:, 0], "approach direction (flank: −1 from above, +1 from below)"
    elif effect.moments:  # a compliance of unknown masses: no one load drives it, its fitted deflection does
        unit = shift_unit(chain.joint_kinds[joint] == "prismatic")
        driver, label = fitted, f"fitted deflection of {joint} under its mass moments' load [{unit}]"
    elif effect.type == "compliance":  # its own torque, or its driver's (a gravity-torque coupling)
        driver, label = basis[:, 0], _load_label(chain, effect.driver, joint)
    elif effect.type == "coupling":
        reading = shift_unit(chain.joint_kinds[cast(str, effect.driver)] == "prismatic")  # a coupling names it
        driver, label = basis[:, 0], f"reading of {effect.driver} [{reading}]"
    else:
        driver, label = inputs.q[:, j], _DRIVERS[effect.type]
    return driver, label, shift, fitted
