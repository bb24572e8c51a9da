"""The continuous (approximate) design that bounds every plan (:func:`pincal.planning.design.continuous_design`).

Its certificate is the general equivalence theorem (Kiefer & Wolfowitz 1960; Pukelsheim 1993, §5.15):
weights w are optimal iff no candidate's directional derivative d_k exceeds Σ w_k d_k, and
max_k d_k bounds the efficiency of any w. Checked here with derivatives recomputed from a fresh
inverse, and against exact designs, which can never beat the continuous optimum.
"""

from __future__ import annotations

import numpy as np
import pytest

from pincal.errors import PincalError
from pincal.model.chain import KinematicChain
from pincal.planning.candidates import sample_candidates
from pincal.planning.design import DesignProblem, continuous_design, select
from pincal.planning.information import (
    MeasurementModel,
    SensorModel,
    default_target_points,
)
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf

#: Certified efficiency asked for; the equivalence check allows exactly this slack.
EFFICIENCY = 0.999


@pytest.fixture(scope="module")
def problem() -> DesignProblem:
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    model = MeasurementModel(chain, "full", SensorModel("point", 1), default_target_points(1), sigma_pos_m=1e-4)
    q = sample_candidates(chain, 150, seed=11)
    return DesignProblem(model.jacobian(q), model.kinematic, model.jacobian(q[:0]), *model.error_jacobian(q[:60]))


def _information(problem, weights):
    return np.einsum("k,kim,kin->mn", weights, problem.blocks, problem.blocks)


def test_accuracy_design_meets_the_equivalence_theorem_and_bounds_exact_designs(problem):
    design = continuous_design(problem, "accuracy", efficiency=EFFICIENCY)
    w = design.weights
    assert w.min() >= 0 and w.sum() == pytest.approx(1.0)
    P = np.linalg.inv(_information(problem, w))
    B = problem.workspace
    psi = np.trace(P @ B)
    H = np.einsum("kim,kin->kmn", problem.blocks, problem.blocks)
    d = np.trace(B @ P @ H @ P, axis1=1, axis2=2)  # tr(B P H_k P)
    assert psi == pytest.approx(design.value, rel=1e-9)
    assert np.dot(w, d) == pytest.approx(psi, rel=1e-9)  # Σ w_k d_k = ψ at any w
    assert d.max() <= psi / EFFICIENCY * (1 + 1e-9)  # equivalence theorem, within the certified slack
    uniform = np.full(problem.n_candidates, 1.0 / problem.n_candidates)
    assert psi < np.trace(np.linalg.solve(_information(problem, uniform), B))
    # no N configurations beat the bound: N tr(B M_N⁻¹) >= ψ* >= bound (planned ones and random ones)
    rng = np.random.default_rng(3)
    for count in (12, 30):
        for chosen in [select(problem, count, "accuracy").chosen] + [rng.choice(150, count, replace=False)]:
            assert count * np.trace(np.linalg.solve(problem.information(chosen), B)) >= design.bound


def test_d_design_meets_the_equivalence_theorem(problem):
    design = continuous_design(problem, "d", efficiency=EFFICIENCY)
    M = _information(problem, design.weights)
    d = np.einsum("kim,mn,kin->k", problem.blocks, np.linalg.inv(M), problem.blocks)  # tr(M⁻¹ H_k)
    assert d.max() <= problem.n / EFFICIENCY * (1 + 1e-9)  # Kiefer–Wolfowitz: max d = n at the optimum
    chosen = select(problem, 20, "d").chosen
    assert np.linalg.slogdet(problem.information(chosen))[1] <= problem.n * np.log(20) + design.bound


def test_recorded_rows_are_refused(problem):
    with_rows = DesignProblem.__new__(DesignProblem)
    with_rows.__dict__.update(problem.__dict__, existing=problem.blocks[:2])
    with pytest.raises(PincalError, match="recorded rows"):
        continuous_design(with_rows, "accuracy")
