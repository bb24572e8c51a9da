"""A joint read against another, corrected in the readings: the convention tested and applied.

A ``coupling`` (:mod:`pincal.model.effects`, shift = c · q_i) whose fitted value is nearest ±1 may be a
controller's convention rather than a transmission's: a parallelogram arm's controller reads J3 from the
horizontal, so the reading is J3 − J2 (c = +1). The geometric calibration made on such readings was chosen
on the wrong joint values — the parameters it kept, the target directions it held, the prior's weight at a
noise scale a thousand times the sensor's — and a refit of geometry and coupling from it can stop far from
the noise floor: 59 mm RMS at c = 1.063 on 24 rows of circle point analysis of a 6-axis arm whose target
centroid had been held at the flange (tests/test_read_against.py).

So ``diagnose`` tests the convention itself (:func:`convention_for`): every row read is corrected by eq C1 of
:mod:`pincal.measurements.couplings` with the factor F = −sign(c) exactly, the geometry is calibrated again on
the corrected readings as it was at the start, and the convention is adopted when that model fits the
calibration rows better than the coupling's own fit, in the noise units of the step (:func:`chi_square`),
and, with held-out rows, passes their test against the model before it
(:func:`pincal.diagnosis.verdicts.held_out_verdict`). The search then goes on from the recalibrated
geometry on the corrected readings; REPORT.json records the convention in ``couplings`` as ``--coupling``
would, so ``evaluate`` corrects its rows the same way. A convention that fits worse leaves the coupling an
effect, as fitted.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, replace

import numpy as np

from pincal.diagnosis.effect_fits import EffectModel, heldout_errors, pose_errors_of
from pincal.diagnosis.held_out import fitted_scales, held_out_verdict
from pincal.diagnosis.screening import FitObjective
from pincal.diagnosis.verdicts import Judge
from pincal.fit.chain_calibration import ChainCalibration, row_weights
from pincal.fit.metrics import PoseErrors
from pincal.fit.solver import Solution
from pincal.measurements.couplings import ReadingCoupling
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect, EffectInputs

__all__ = ["CONVENTION_RANGE", "ConventionTrial", "convention_for", "chi_square", "adopted_trial",
           "read_against_words", "followers_of", "mimic_words"]

#: |c| of a fitted coupling for which the convention ±1 is tried: nearer 1 than 0 and within the plausible
#: 1.5 (:data:`pincal.diagnosis.verdicts.PLAUSIBLE`). A refit from a geometry chosen on the wrong readings
#: stops short of or beyond 1 (1.063 in the module docstring's cell, 0.88 after 50 evaluations on a
#: parallelogram arm's), a transmission's cross-coupling is a few percent.
CONVENTION_RANGE = (0.5, 1.5)


@dataclass(frozen=True)
class ConventionTrial:
    """A convention applied to the rows, and the geometry calibrated again on them.

    Attributes:
        coupling: the convention (eq C1's J = F × I, F = ±1).
        calibration: the geometric calibration of the corrected rows (as at the start of ``diagnose``).
        data / heldout: the rows with their readings corrected (``heldout`` None without held-out rows).
    """

    coupling: ReadingCoupling
    calibration: ChainCalibration
    data: MeasurementSet
    heldout: MeasurementSet | None


def convention_for(effect: Effect, value: float, corrected: Collection[str]) -> ReadingCoupling | None:
    """The convention a fitted coupling ``value`` may be (F = −sign(c), eq C1), or None: not a coupling, |c|
    outside :data:`CONVENTION_RANGE`, or a joint already corrected among ``corrected`` (the joints and drivers
    of the couplings applied: each correction takes its driver as read)."""
    if effect.type != "coupling" or not CONVENTION_RANGE[0] <= abs(value) < CONVENTION_RANGE[1]:
        return None
    joint, driver = str(effect.joint), str(effect.driver)
    if joint in corrected or driver in corrected:
        return None
    return ReadingCoupling(joint, -float(np.sign(value)), driver)


def followers_of(chain: KinematicChain) -> tuple[str, ...]:
    """The chain's joints that follow another (URDF ``<mimic>``): they have no reading to be read against
    anything, so no convention is tried on them (:func:`convention_for`'s ``corrected``)."""
    return tuple(j.name for j in chain.joints if j.mimic is not None)


def mimic_words(effect: Effect, value: float, chain: KinematicChain, flagged: Collection[str] = ()) -> str | None:
    """What an adopted coupling c of a joint that follows its driver (eq M1 of
    :mod:`pincal.measurements.mimics`) says: the joint moves by (m + c) x the driver, so the URDF's
    multiplier m (for a joint of ``flagged``, the factor of the ``--coupling`` that made it follow) is off by c
    (shift = c · q_driver); None for any other effect."""
    mimic = next((j.mimic for j in chain.joints if j.name == effect.joint), None)
    if effect.type != "coupling" or mimic is None or mimic.driver != effect.driver:
        return None
    if effect.joint in flagged:
        return (f"{effect.joint} follows {effect.driver} by {mimic.multiplier + value:.4g}, not by its --coupling "
                f"factor {mimic.multiplier:g}: give --coupling {effect.joint}={mimic.multiplier + value:.4g}*"
                f"{effect.driver}, and the coupling has nothing left to correct")
    return (f"{effect.joint} follows {effect.driver} by {mimic.multiplier + value:.4g}, not by its <mimic> multiplier "
            f"{mimic.multiplier:g}: set multiplier=\"{mimic.multiplier + value:.4g}\" in the URDF's <mimic> of "
            f"{effect.joint}, and the coupling has nothing left to correct")


def chi_square(errors: PoseErrors, sigma_pos_m: float, sigma_rot_rad: float | None) -> float:
    """Σ |e_kp|² / σ_pos² + Σ η_k² / σ_rot² over the rows (the orientation term with 6D rows): −2 × the
    Gaussian log-likelihood of the errors up to a constant, at given noise scales."""
    total = float(np.sum(errors.position_m**2)) / sigma_pos_m**2
    if errors.rotation_rad is not None and sigma_rot_rad:
        total += float(np.sum(errors.rotation_rad**2)) / sigma_rot_rad**2
    return total


def read_against_words(coupling: ReadingCoupling) -> str:
    """What a convention diagnose applied means, and where it is recorded, in words."""
    joint, driver = coupling.joint, coupling.driver
    sign = "−" if coupling.factor < 0 else "+"
    return (f"{joint} is read against {driver} (as parallelogram arms read J3 from the horizontal): its reading "
            f"is {joint} {sign} {driver}; diagnose corrected every row (--coupling {coupling.label}: a convention "
            "is exact) and calibrated the geometry again on the corrected readings; REPORT.json records it "
            "under couplings, and evaluate corrects its rows the same way")


def adopted_trial(trial: ConventionTrial, chain: KinematicChain, sigma_column: str | None,
                  inputs: EffectInputs, held_inputs: EffectInputs | None, candidate: tuple[FitObjective, Solution],
                  before_held: PoseErrors | None, judge: Judge
                  ) -> tuple[ConventionTrial, PoseErrors, PoseErrors | None] | None:
    """The trial with its errors on the corrected calibration and held-out rows, when it is adopted: its geometry
    fits the calibration rows better than the coupling's own fit ``candidate`` (objective, solution), both in
    the noise units the step's ``judge`` takes from the models that fit (:meth:`Judge.judged_noise`,
    :func:`chi_square`), and the held-out rows pass their test against the model before (``before_held``);
    None otherwise (module docstring)."""
    calibration = trial.calibration
    rows = trial.data.select(calibration.used_index)
    if rows.n_rows != inputs.q.shape[0]:
        return None
    probe = EffectModel.of(chain, calibration, rows, row_weights(rows, sigma_column), replace(inputs, q=rows.q))
    objective = probe.problem([]).objective(calibration.kept, calibration.vector)
    errors, fitted = pose_errors_of(objective, calibration.solution), pose_errors_of(candidate[0], candidate[1].x)
    noise = judge.judged_noise(fitted_scales(errors), fitted_scales(fitted))
    if chi_square(errors, *noise) >= chi_square(fitted, *noise):
        return None
    held = None
    if trial.heldout is not None:
        assert held_inputs is not None and before_held is not None  # both of the held-out rows, given with them
        held = heldout_errors(probe, objective, calibration.solution, trial.heldout,
                              replace(held_inputs, q=trial.heldout.q))
        if held is not None and held_out_verdict(before_held, held, *noise) != "adopted":
            return None
    return trial, errors, held
