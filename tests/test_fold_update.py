"""--level auto at scale: each fold scored by one Gauss–Newton step from the fit of all rows
(pincal.fit.fold_update, eq L1) instead of a refit.

Tolerance: the step is the exact least-squares update of a quadratic model, so on rows that the
level fits the fold errors agree with refits to second order in the fold's parameter change;
5 % (the issue's bound on a choice's held-out error) on every fold, and the same level chosen.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pincal.fit import level_choice
from pincal.fit.chain_calibration import ChainFitOptions
from pincal.fit.level_choice import choose_level
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import PlacementErrors
from pincal.simulation.cells import measure_truth, sensor_at
from pincal.simulation.sensor import SimulatedSensor, random_configurations


@pytest.mark.parametrize("selection, sigma_column", [("prior", None), ("aic", None), ("prior", "sigma")],
                         ids=["prior", "aic", "prior-row-weights"])
def test_linearised_folds_agree_with_refits(industrial_arm_urdf, monkeypatch, selection, sigma_column):
    chain = KinematicChain.from_urdf(industrial_arm_urdf, "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(31)
    truth = rng.normal(0.0, 3e-4, params.size)
    rows = measure_truth(params, truth, random_configurations(chain, rng, 120), sensor_at(4.0), rng,
                         SimulatedSensor(20e-6, np.radians(0.003), points=np.array([[0.035, -0.02, 0.21]])))
    if sigma_column:  # rows of unequal noise, weighted by it: half of them twice as noisy as stated
        sigma = np.where(np.arange(rows.n_rows) % 2 == 0, 0.02, 0.04)
        rows = replace(rows, extra={**rows.extra, "sigma": sigma})
    monkeypatch.setattr(level_choice, "LINEARISED_FROM_ROWS", 10**9)
    refits = choose_level(chain, rows, ChainFitOptions(selection=selection, sigma_column=sigma_column))
    monkeypatch.setattr(level_choice, "LINEARISED_FROM_ROWS", 100)
    steps = choose_level(chain, rows, ChainFitOptions(selection=selection, sigma_column=sigma_column))
    assert "Gauss–Newton" in steps.scheme and "Gauss–Newton" not in refits.scheme
    for exact, step in zip(refits.scores, steps.scores):
        assert exact.level == step.level
        assert np.allclose(step.fold_errors_mm, exact.fold_errors_mm, rtol=0.05), exact.level
    assert steps.chosen == refits.chosen == "full"


def test_a_level_that_cannot_be_fitted_at_scale_is_no_candidate(industrial_arm_urdf, monkeypatch):
    """As with refits: a richer level whose fit fails is no candidate; the first level failing is one line."""
    from pincal.errors import CalibrationError
    from pincal.fit import fold_update

    chain = KinematicChain.from_urdf(industrial_arm_urdf, "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(32)
    rows = measure_truth(params, rng.normal(0.0, 3e-4, params.size), random_configurations(chain, rng, 120),
                         sensor_at(4.0), rng,
                         SimulatedSensor(20e-6, np.radians(0.003), points=np.array([[0.035, -0.02, 0.21]])))
    monkeypatch.setattr(level_choice, "LINEARISED_FROM_ROWS", 100)
    real = fold_update.calibrate_chain

    def failing(at):
        def calibrate(chain, rows, level, options):
            if level == at:
                raise CalibrationError("the solver gave up")
            return real(chain, rows, level, options)
        return calibrate

    monkeypatch.setattr(fold_update, "calibrate_chain", failing("full"))
    choice = choose_level(chain, rows)
    full = next(s for s in choice.scores if s.level == "full")
    assert not np.isfinite(full.cv_error_mm) and "the solver gave up" in full.failures[0]
    assert choice.chosen != "full"
    monkeypatch.setattr(fold_update, "calibrate_chain", failing("registration"))
    with pytest.raises(CalibrationError, match="cannot be calibrated even at level registration: the solver gave up"):
        choose_level(chain, rows)
