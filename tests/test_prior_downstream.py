"""``--select prior`` as diagnose, the socket fixture, the command line and pickling see it."""

from __future__ import annotations

import copy
import json
import pickle

import numpy as np
import pytest
from test_select_prior import SIGMA_M, UR5, _fixture_data, _heldout_m, _rows

from pincal.cli.commands import main
from pincal.diagnosis.diagnose import DiagnoseOptions, diagnose
from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.fixture_calibration import calibrate_fixture
from pincal.fit.prior import PRIOR_STATUS, SCALE_RANGE, Prior, prior_sigmas
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain
from pincal.model.effects import Effect
from pincal.model.parameter_sets import PlacementErrors


def test_diagnose_keeps_the_prior_of_the_calibration():
    """9 rows, 27 coordinates for 18 + 9 unknowns: unregularised, the full fit reproduces the noise
    (5.3 mm held-out on this seed); the MAP fit 0.46 mm. With no effect adopted (none offered),
    diagnose's fit is the calibration's."""
    chain, train, test = _rows(9, seed=3, sigma_m=SIGMA_M)
    nominal = chain.placements()
    unregularised = _heldout_m(chain, calibrate_chain(chain, train, "full", ChainFitOptions(selection="all")), test)
    chain.set_placements(nominal)
    calibration = calibrate_chain(chain, train, "full", ChainFitOptions(selection="prior"))
    held = _heldout_m(chain, calibration, test)
    assert calibration.prior_sigma is not None
    diagnosis = diagnose(chain, calibration, train, heldout=test, options=DiagnoseOptions(candidates=[]))
    kin = diagnosis.objective.blocks["kinematic"]
    std = calibration.std[calibration.kept]
    # the same MAP problem refitted from its solution: it moves by the solvers' stopping tolerance
    # (seen 1.8e-4 std); the fit without the prior moves by several std
    assert np.all(np.abs(diagnosis.solution_x[kin] - calibration.solution[kin]) < 1e-3 * std)
    assert np.allclose(diagnosis.solution_std[kin], std, rtol=1e-3)  # the posterior's std (seen 2.5e-5)
    assert diagnosis.heldout_errors.position.rms == pytest.approx(held * 1e3, rel=1e-3)  # mm, as above
    assert unregularised > 5 * held  # the data make the difference clear (5.29 vs 0.46 mm)


def test_diagnose_report_gives_the_posterior_std(tmp_path):
    """40 rows on which diagnose adopts no effect (on 9 or 15 it adopts one: fewer rows than unknowns
    leave the search room); the report's values and std are the calibration's MAP fit's."""
    data = tmp_path / "cal.csv"
    write_measurements(data, _rows(40, seed=2, sigma_m=SIGMA_M)[1])
    reports = {}
    for command in ("calibrate", "diagnose"):
        report = tmp_path / f"{command}.json"
        assert main([command, str(UR5), str(data), "--tip-link", "tool0", "--level", "full", "--select", "prior",
                     "--quiet", "--out", str(tmp_path / f"{command}.urdf"), "--report", str(report)]) == 0
        reports[command] = json.loads(report.read_text())
    assert not reports["diagnose"]["diagnosis"]["steps"]
    pairs = list(zip(reports["calibrate"]["parameters"], reports["diagnose"]["parameters"]))
    assert any(a["std"] is not None for a, _ in pairs)
    for a, b in pairs:  # the same MAP fit: values and posterior std to the solvers' tolerance (as above)
        assert a["status"] == b["status"]
        if a["std"] is not None:
            assert b["std"] == pytest.approx(a["std"], rel=1e-3)
            assert abs(b["calibrated"] - a["calibrated"]) < 1e-3 * a["std"]


def test_fixture_prior_notes_are_reported():
    chain, data = _fixture_data()
    tight = calibrate_fixture(chain, data, "full", selection=Prior(1e-6, 1e-6))  # the prior decides
    assert tight.status.count(PRIOR_STATUS) > 0
    assert any("determined mainly by the prior" in note for note in tight.notes)


def test_jacobian_condition_is_the_data_rows():
    """A tight prior's rows (weight σ_pos / 1 µm ~ 50 against data rows of order 1) would change the
    condition number; the data rows' one moves only with the solution (seen 0.08 %)."""
    chain, train, _ = _rows(12, seed=5, sigma_m=SIGMA_M)
    nominal = chain.placements()
    every = calibrate_chain(chain, train, "full", ChainFitOptions(selection="all"))
    chain.set_placements(nominal)
    tight = calibrate_chain(chain, train, "full", ChainFitOptions(selection=Prior(1e-3, 1e-3)))
    assert np.array_equal(every.kept, tight.kept)
    assert tight.condition == pytest.approx(every.condition, rel=0.05)


def test_prior_scale_range():
    low, high = SCALE_RANGE
    Prior(low, high), Prior(high, low)  # inclusive
    for bad in ((1e-300, 1e-300), (1.0, high * 10), (low / 10, 0.5)):
        with pytest.raises(CalibrationError, match="must be from"):
            Prior(*bad)


def test_prior_pickles_copies_and_compares_with_its_scales():
    prior = Prior(2.0, 0.25)
    for twin in (pickle.loads(pickle.dumps(prior)), copy.copy(prior), copy.deepcopy(prior)):
        assert isinstance(twin, Prior) and twin.as_dict() == prior.as_dict() and twin == prior
    assert prior == "prior" and hash(prior) == hash("prior")  # still the criterion's name
    assert prior != Prior() and (prior == Prior(2.0, 0.3)) is False  # the scales count
    chain = KinematicChain.from_urdf(UR5, "tool0")
    params = PlacementErrors(chain)
    assert np.array_equal(prior_sigmas(params, pickle.loads(pickle.dumps(prior))), prior_sigmas(params, prior))


def _cli(tmp_path, *arguments):
    data = tmp_path / "cal.csv"
    if not data.exists():
        write_measurements(data, _rows(15, seed=6, sigma_m=SIGMA_M)[1])
    return main(["calibrate", str(UR5), str(data), "--tip-link", "tool0", "--quiet",
                 "--out", str(tmp_path / "ur5.urdf"), "--report", str(tmp_path / "REPORT.json"), *arguments])


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    return err


def test_cli_tiny_prior_scale_is_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_info:
        _cli(tmp_path, "--level", "full", "--select", "prior", "--prior-scale", "1e-300,1e-300")
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if "error" in line]  # argparse: usage, then one error line
    assert len(errors) == 1 and "--prior-scale" in errors[0] and "1e-06 to 1e+06" in errors[0]
    assert "Traceback" not in err


@pytest.mark.parametrize("arguments", [("--level", "registration", "--select", "prior"),
                                       ("--level", "registration", "--prior-scale", "1,0.5"),
                                       ("--level", "dh", "--select", "prior"),
                                       ("--method", "2", "--prior-scale", "1,0.5")])
def test_cli_prior_where_it_cannot_apply_is_refused(tmp_path, capsys, arguments):
    assert _cli(tmp_path, *arguments) == 2
    err = _one_line(capsys)
    assert "does not apply to --level" in err and not (tmp_path / "REPORT.json").exists()


def test_cli_prior_scale_without_any_select_is_the_default_prior(tmp_path):
    """The default selection at levels offsets and full is the prior (docs/defaults.md): its scale is taken."""
    assert _cli(tmp_path, "--level", "full", "--prior-scale", "1,0.5") == 0
    document = json.loads((tmp_path / "REPORT.json").read_text())
    assert document["identifiability"]["selection"]["prior_scale"] == {
        "translation_mm": 1.0, "rotation_deg": 0.5, "joint_zero_deg": 0.5, "estimated": False, "reason": "given"}


def test_cli_prior_scale_under_level_auto_needs_no_select(tmp_path):
    """Under --level auto the default selection is the prior, so its scale is accepted as is."""
    assert _cli(tmp_path, "--level", "auto", "--prior-scale", "2,0.5") == 0
    document = json.loads((tmp_path / "REPORT.json").read_text())
    assert document["identifiability"]["selection"]["prior_scale"] == {
        "translation_mm": 2.0, "rotation_deg": 0.5, "joint_zero_deg": 0.5, "estimated": False, "reason": "given"}


def test_diagnose_bic_counts_the_data_rows_not_the_prior_rows():
    """BIC's m is the number of observations: counting the prior's pseudo-rows inflated ΔBIC by about
    m_all/m_data and adopted encoder_scale:wrist_2_joint (ΔBIC −11.9 against the −10 cut) on these 25
    effect-free rows (seed 3); with m the data rows it is −9.0 and nothing is adopted."""

    from pincal.diagnosis.screening import bic

    # the criterion itself: m is the data rows; prior rows add their squares to the RSS, not to m
    data, prior = np.random.default_rng(0).normal(size=60), np.zeros(20)
    assert bic(np.concatenate([data, prior]), 7, n_prior=20) == pytest.approx(
        60 * np.log(data @ data / 60) + 7 * np.log(60), rel=1e-12)
    assert bic(np.concatenate([data, prior]), 7, n_prior=20) != bic(np.concatenate([data, prior]), 7)
    # and in diagnose: on these effect-free rows nothing is adopted (ΔBIC −9.0 > −10) ...
    chain, train, _ = _rows(25, seed=3, sigma_m=SIGMA_M)
    calibration = calibrate_chain(chain, train, "full", ChainFitOptions(selection="prior"))
    candidates = [Effect("encoder_scale", "wrist_2_joint")]
    diagnosis = diagnose(chain, calibration, train, options=DiagnoseOptions(candidates=candidates))
    assert [step.effect.label for step in diagnosis.steps] == []
    # ... while the same rows with that effect hidden in them (2e-3, ~20 sigma at the tool) adopt it:
    # the search can adopt here, so "nothing" above is the criterion's verdict
    chain, hidden, _ = _rows(25, seed=3, sigma_m=SIGMA_M, effects=[(candidates[0], np.array([2e-3]))])
    calibration = calibrate_chain(chain, hidden, "full", ChainFitOptions(selection="prior"))
    diagnosis = diagnose(chain, calibration, hidden, options=DiagnoseOptions(candidates=candidates))
    assert [step.effect.label for step in diagnosis.steps] == [candidates[0].label]


def test_diagnose_does_not_test_effects_the_residual_freedom_cannot_carry():
    """9 effect-free rows under the prior leave ~1 residual degree of freedom (27 coordinates, tr H ~26):
    a 2-value cyclic effect fitted there drove the calibration residual to 0 (ΔBIC −89, adopted) and, on
    this seed, a refit failed with 'the data do not determine all 31 parameters'. Fitting e values to
    noise lowers BIC by m ln(1 − e/d) + e ln m in expectation; below the −10 cut nothing is tested."""
    chain, train, _ = _rows(9, seed=18, sigma_m=SIGMA_M)
    # the scales of that case
    calibration = calibrate_chain(chain, train, "full", ChainFitOptions(selection=Prior(1.0, 0.5)))
    diagnosis = diagnose(chain, calibration, train)
    assert not diagnosis.steps
    untested = [note for note in diagnosis.notes if note.startswith("not tested,")]
    assert len(untested) == 1 and "residual degrees of freedom" in untested[0]
    # the scales estimated from these rows (0.06 mm, 0.005 deg: the truth's 0.1 mm / 0.1 mrad) leave more
    # residual freedom; the candidates are tested and none is adopted
    assert not diagnose(chain, calibrate_chain(chain, train, "full", ChainFitOptions(selection="prior")), train).steps
    # the vertical shoulder pan feels no gravity torque: its compliance cannot be tested (more rows would not
    # help), not "not tested"
    assert "compliance:shoulder_pan_joint" not in untested[0]
    assert any("cannot be tested" in note and "compliance:shoulder_pan_joint" in note for note in diagnosis.notes)
    from pincal.diagnosis.screening import GENERIC_NOT_RUN

    assert diagnosis.unexplained is None and GENERIC_NOT_RUN in diagnosis.notes  # said, not "no structure left"
