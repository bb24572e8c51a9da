"""Fits that crawl stop at their budget, without changing what is decided.

On a UR5 whose wrist never bends (tests/test_selection.py's straight-wrist session,
scripts/benchmark.py (f) with fewer rows) some combinations are determined only through
the model's curvature: Levenberg–Marquardt crawls along them for thousands of evaluations
(scipy's default budget is 100 per unknown) while the cost hardly moves.
"""

from __future__ import annotations

import numpy as np
from test_selection import _straight_wrist_session

import pincal.diagnosis.diagnose as diagnosis
import pincal.diagnosis.effect_fits as effect_fits
import pincal.fit.pipeline as pipeline
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.solver import solve


def _counting(monkeypatch, module) -> list[tuple[str, int, bool]]:
    """(what, evaluations, converged) of every fit ``module`` makes through ``solve``."""
    fits: list[tuple[str, int, bool]] = []

    def counted(objective, x0, what="fit", **options):
        solution = solve(objective, x0, what, **options)
        fits.append((what, solution.n_evaluations, solution.converged))
        return solution

    monkeypatch.setattr(module, "solve", counted)
    return fits


def test_the_data_scale_fit_of_a_prior_calibration_stops_at_its_budget(monkeypatch):
    """--select prior compares the prior's noise scale with the data's own, from an unregularised fit,
    within a factor DATA_SCALE_GAP = 2: its crawl (cost changes of ~1e-7 per evaluation) stops at
    SCALE_FIT_EVALUATIONS, and a budget twice as large gives the same calibration, bit for bit."""
    chain, data = _straight_wrist_session()
    fits = _counting(monkeypatch, pipeline)
    first = calibrate_chain(chain, data, "full", ChainFitOptions(selection="prior"))
    assert fits and max(n for _, n, _ in fits) <= pipeline.SCALE_FIT_EVALUATIONS
    assert any(not converged for _, _, converged in fits)  # the session does crawl
    monkeypatch.setattr(pipeline, "SCALE_FIT_EVALUATIONS", 2 * pipeline.SCALE_FIT_EVALUATIONS)
    second = calibrate_chain(chain, data, "full", ChainFitOptions(selection="prior"))
    assert np.array_equal(first.vector, second.vector) and np.array_equal(first.std, second.std, equal_nan=True)
    assert (first.sigma_pos_m, first.sigma_rot_rad) == (second.sigma_pos_m, second.sigma_rot_rad)


def test_a_candidate_whose_naming_fit_crawls_is_named_absorbed(monkeypatch):
    """A cyclic term on the straight wrist (sin q ≈ 0, cos q ≈ 1: its zero offset) is nearly
    inseparable from the geometry; its fit wanders to amplitudes of radians without converging. Its
    first chunk of NAMING_EVALUATIONS gains far less than GAIN_PER_CHUNK of BIC, so it stops there and
    is named as absorbed by the geometry, not ranked."""
    chain, data = _straight_wrist_session(600, seed=11)
    calibration = calibrate_chain(chain, data, "full", ChainFitOptions(selection="aic"))
    fits = _counting(monkeypatch, effect_fits)
    result = diagnosis.diagnose(chain, calibration, data)
    crawled = [n for what, n, converged in fits if not converged]
    assert crawled and max(crawled) <= diagnosis.NAMING_EVALUATIONS
    assert crawled.count(diagnosis.NAMING_EVALUATIONS) == 2  # one chunk each: h1 and h2 gain nothing
    absorbed = next(note for note in result.notes if note.startswith("not separable"))
    assert "cyclic:wrist_2_joint:h1" in absorbed and "cyclic:wrist_2_joint:h2" in absorbed
    assert not {"cyclic:wrist_2_joint:h1", "cyclic:wrist_2_joint:h2"} & {c.effect.label for c in result.last_candidates}
    assert result.effects == ()
