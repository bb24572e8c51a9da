"""``pincal evaluate`` and ``pincal report`` as workflows (pincal.workflows.evaluation_outputs, report_page): the
thresholds judged as structured values, the outputs written whole, and every refusal made before anything is
written."""

from __future__ import annotations

import json

import pytest

from pincal import (
    CalibrateSettings,
    EvaluateOutputs,
    EvaluateSettings,
    SimulationSettings,
    ThresholdFailure,
    calibrate_files,
    evaluate_and_write,
    evaluate_files,
    report_file,
    simulate_to_directory,
)
from pincal.errors import PincalError
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """A simulated KUKA calibrated at level offsets: (corrected URDF, REPORT.json, held-out rows, their errors)."""
    folder = tmp_path_factory.mktemp("pair")
    simulate_to_directory(folder, "small", SimulationSettings(sigma_pos_mm=0.05, sigma_rot_deg=0.05, seed=3))
    urdf, report = folder / "corrected.urdf", folder / "REPORT.json"
    calibrate_files(kuka_lwr4plus_urdf(), folder / "calibration.csv", urdf, report,
                    CalibrateSettings(KUKA_FLANGE_LINK, level="offsets"))
    data = folder / "validation.csv"
    return urdf, report, data, evaluate_files(urdf, report, data).errors


def test_thresholds_give_structured_failures_and_the_outputs_are_written(pair, tmp_path):
    urdf, report, data, errors = pair
    worst_pos, worst_rot = errors.position.max, errors.rotation.max
    outputs = EvaluateOutputs(tmp_path / "m.json")  # the page (~3 s to draw): tests/test_html_report.py
    run = evaluate_and_write(urdf, report, data, EvaluateSettings(max_pos_mm=worst_pos - 1e-4,
                                                                  max_rot_deg=worst_rot - 1e-4), outputs)
    assert run.failed == (ThresholdFailure("position", worst_pos, worst_pos - 1e-4, "mm"),
                          ThresholdFailure("orientation", worst_rot, worst_rot - 1e-4, "deg"))
    assert run.failed[0].text == f"max position error {worst_pos:.4f} mm > {worst_pos - 1e-4} mm"
    assert run.written == (outputs.json,)
    written = json.loads(outputs.json.read_text())
    assert written["position"]["max_mm"] == run.document["position"]["max_mm"] == worst_pos
    # just above the largest errors: passed; no output asked, none written
    passed = evaluate_and_write(urdf, report, data, EvaluateSettings(max_pos_mm=worst_pos + 1e-4,
                                                                     max_rot_deg=worst_rot + 1e-4))
    assert passed.failed == () and passed.written == ()


def test_every_refusal_comes_before_any_output(pair, tmp_path):
    urdf, report, data, _ = pair
    json_out = tmp_path / "m.json"
    # the page over an input, the --json over an input: refused, nothing written, the inputs unchanged
    before = data.read_bytes(), report.read_bytes()
    for outputs in (EvaluateOutputs(json_out, data), EvaluateOutputs(report, tmp_path / "page.html")):
        with pytest.raises(PincalError):
            evaluate_and_write(urdf, report, data, EvaluateSettings(), outputs)
        assert not json_out.exists() and not (tmp_path / "page.html").exists()
    assert (data.read_bytes(), report.read_bytes()) == before
    # a threshold the errors cannot judge (a registration re-estimated on one row's 6 residuals) is refused
    # before the outputs
    three = tmp_path / "one.csv"
    three.write_text("\n".join(data.read_text().splitlines()[:2]) + "\n")
    with pytest.raises(PincalError, match="--max-pos-mm: session"):
        evaluate_and_write(urdf, report, three, EvaluateSettings(new_session=True, max_pos_mm=1.0),
                           EvaluateOutputs(json_out, tmp_path / "page.html"))
    assert not json_out.exists() and not (tmp_path / "page.html").exists()
    # the same rows with no threshold: written
    assert evaluate_and_write(urdf, report, three, EvaluateSettings(new_session=True),
                              EvaluateOutputs(json_out)).written == (json_out,)


def test_a_threshold_is_a_non_negative_number():
    for bad in (-1.0, float("nan")):
        with pytest.raises(PincalError, match="--max-pos-mm must be a non-negative number"):
            EvaluateSettings(max_pos_mm=bad)
    assert EvaluateSettings(max_rot_deg=0.0).max_rot_deg == 0.0


def test_report_file_writes_the_page_and_never_over_its_document(pair, tmp_path):
    """pincal report on an evaluate --json (one row: a small page; REPORT.json's page is evaluate --html's, above)."""
    urdf, report, data, _ = pair
    one, metrics = tmp_path / "one.csv", tmp_path / "m.json"
    one.write_text("\n".join(data.read_text().splitlines()[:2]) + "\n")
    evaluate_and_write(urdf, report, one, EvaluateSettings(new_session=True), EvaluateOutputs(metrics))
    page = report_file(metrics, tmp_path / "m.html")
    assert page == tmp_path / "m.html" and "<html" in page.read_text().lower()
    text = metrics.read_bytes()
    with pytest.raises(PincalError):
        report_file(metrics, metrics)
    assert metrics.read_bytes() == text
