"""--level auto at scale: each fold scored by one Gauss–Newton step from the fit of all rows
(pincal.fit.fold_update, eq L1) instead of a refit.

Tolerance: the step is the exact least-squares update of a quadratic model, so on rows that the
level fits the fold errors agree with refits to second order in the fold's parameter change;
5 % (the issue's bound on a choice's held-out error) on every fold, and the same level chosen.
"""

from __future__ import annotations

import numpy as np
import pytest

from pincal.fit import level_choice
from pincal.fit.level_choice import choose_level
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import PlacementErrors
from pincal.simulation.cells import measure_truth, sensor_at
from pincal.simulation.sensor import random_configurations


@pytest.mark.parametrize("selection", ["prior", "aic"])
def test_linearised_folds_agree_with_refits(industrial_arm_urdf, monkeypatch, selection):
    chain = KinematicChain.from_urdf(industrial_arm_urdf, "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(31)
    truth = rng.normal(0.0, 3e-4, params.size)
    rows = measure_truth(params, truth, random_configurations(chain, rng, 120), sensor_at(4.0), rng, 20e-6,
                         np.radians(0.003), points=np.array([[0.035, -0.02, 0.21]]))
    monkeypatch.setattr(level_choice, "LINEARISED_FROM_ROWS", 10**9)
    refits = choose_level(chain, rows, selection=selection)
    monkeypatch.setattr(level_choice, "LINEARISED_FROM_ROWS", 100)
    steps = choose_level(chain, rows, selection=selection)
    assert "Gauss–Newton" in steps.scheme and "Gauss–Newton" not in refits.scheme
    for exact, step in zip(refits.scores, steps.scores):
        assert exact.level == step.level
        assert np.allclose(step.fold_errors_mm, exact.fold_errors_mm, rtol=0.05), exact.level
    assert steps.chosen == refits.chosen == "full"
