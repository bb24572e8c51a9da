"""The HTML report's page-wide promises, checked on the HTML (no browser): one colour per
model, effects drawn as functions, one unit per parameter column, whole tables in print,
changes that do not read −100 % unless the error is zero, and the page of a PLAN.json."""

from __future__ import annotations

import base64
import json
import re
from pathlib import Path

import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.diagnosis.plots import GRID_POINTS, effect_curve
from pincal.model.effects import Effect
from pincal.palette import CALIBRATED, NOMINAL, WITH_EFFECTS, model_colour
from pincal.report.html import render_html
from pincal.report.sections import change_text

ROOT = Path(__file__).resolve().parent.parent


def _errors(rms: float) -> dict:
    return {"rows": 3, "position": {"mean_mm": rms, "rms_mm": rms, "max_mm": rms}}


def _document(models: dict[str, float]) -> dict:
    """A minimal report: one calibration set with ``models`` (name → RMS [mm]), two parameters."""
    return {
        "level": "full", "model": "joint placements",
        "parameters": [
            {"name": "j1.tx", "joint": "j1", "unit": "m", "nominal": 0.0, "calibrated": 0.0004477545, "std": 1e-5},
            {"name": "j1.rx", "joint": "j1", "unit": "rad", "nominal": 0.5, "calibrated": 0.501, "std": 1e-4},
            {"name": "j2.ty", "joint": "j2", "unit": "m", "nominal": 0.1, "calibrated": 0.1002, "std": 2e-5},
        ],
        "row_errors": [{"set": "calibration", "file": "rows.csv", "lines": [2, 3, 4],
                        "models": [{"model": name, "errors": _errors(rms), "position_mm": [rms] * 3,
                                    "orientation_deg": None} for name, rms in models.items()]}],
    }


def _svgs(page: str) -> list[str]:
    return [base64.b64decode(m).decode("utf-8") for m in re.findall(r"data:image/svg\+xml;base64,([A-Za-z0-9+/=]+)",
                                                                    page)]


def _fills(svg: str) -> set[str]:
    return set(re.findall(r"fill: (#[0-9a-f]{6})", svg)) | set(re.findall(r"stroke: (#[0-9a-f]{6})", svg))


def test_one_colour_per_model_in_every_section():
    diagnose = render_html(_document({"nominal geometry": 3.0, "calibrated geometry": 2.4,
                                      "geometry and effects": 1.7}))
    calibrate = render_html(_document({"nominal geometry": 3.0, "calibrated geometry": 2.4}))
    for page, models in ((diagnose, ("nominal geometry", "calibrated geometry", "geometry and effects")),
                         (calibrate, ("nominal geometry", "calibrated geometry"))):
        overview, rows = _svgs(page)[:2]
        for name in models:  # the summary bars, the per-row plot and the legend: the same hex
            assert model_colour(name) in _fills(overview), name
            assert model_colour(name) in _fills(rows), name
            assert f'data-colour="{model_colour(name)}"' in page
    assert WITH_EFFECTS not in _fills(_svgs(calibrate)[0])
    # the calibrated geometry is blue whether it is the last model (calibrate) or not (diagnose)
    assert re.search(rf'class="big" style="color: {CALIBRATED}"', calibrate)
    assert re.search(rf'class="big" style="color: {WITH_EFFECTS}"', diagnose)
    assert len({NOMINAL, CALIBRATED, WITH_EFFECTS}) == 3


def test_diagnose_plots_take_the_palette():
    source = (ROOT / "pincal" / "diagnosis" / "plots.py").read_text(encoding="utf-8")
    assert "color=CALIBRATED, label=f\"geometry only" in source and "color=WITH_EFFECTS, label=f\"with effects" \
        in source


@pytest.mark.parametrize("effect", [Effect("cyclic", "j", harmonic=2), Effect("backlash", "j", source="approach"),
                                    Effect("backlash", "j", source="gravity"), Effect("compliance", "j")])
def test_effect_is_drawn_as_its_function_on_a_dense_grid(effect):
    rng = np.random.default_rng(1)
    if effect.type == "cyclic":
        driver = rng.uniform(-1.0, 2.0, 12)  # sparse rows
        fitted = 0.003 * np.sin(2 * driver) - 0.001 * np.cos(2 * driver)
    elif effect.source == "approach":
        driver = rng.choice([-1.0, 1.0], 12)
        fitted = 0.012 * driver
    else:
        driver = rng.uniform(-20.0, 15.0, 12)
        fitted = (0.004 * np.sign(driver)) if effect.type == "backlash" else 1e-4 * driver
    grid, curve = effect_curve(effect, driver, fitted)
    assert grid.size == GRID_POINTS >= 100
    assert grid.min() <= driver.min() and grid.max() >= driver.max()  # over the range in the data
    if effect.type == "cyclic":  # a smooth curve, not a polyline through the rows
        assert np.allclose(curve, 0.003 * np.sin(2 * grid) - 0.001 * np.cos(2 * grid))
    elif effect.type == "backlash":  # a step at the flank change (0), flat on each side
        assert np.allclose(curve[grid < 0], -curve[grid > 0][0]) and np.ptp(curve[grid > 0]) == 0.0
        assert grid.min() < 0.0 < grid.max()


def test_parameter_columns_have_one_unit_each():
    page = render_html(_document({"calibrated geometry": 1.0}))
    tables = re.findall(r'<table class="data sortable parameters" data-unit="(\w+)">(.*?)</table>', page, re.S)
    assert [unit for unit, _ in tables] == ["m", "rad"]
    for unit, body in tables:
        headers = re.findall(r"<th[^>]*>([^<]*)</th>", body)
        expected = ["[mm]"] * 4 if unit == "m" else ["[deg]", "[deg]", "[mrad]", "[mrad]"]
        assert [h[h.index("["):] for h in headers if "[" in h] == expected
        # no unit inside the cells: the header says it
        assert not re.search(r"<td[^>]*>[^<]*\b(mm|mrad|deg|m|rad)</td>", body)
    lengths = tables[0][1]
    assert ">0.4478</td>" in lengths and "0.0004477545" not in page  # 0.4478 mm, not 0.0004477545 m
    assert ">100.2000</td>" in lengths
    assert f">{np.degrees(0.501):.4f}</td>" in tables[1][1]


def test_print_shows_every_table_whole():
    page = render_html(_document({"calibrated geometry": 1.0}))
    match = re.search(r"@media print \{(.*?)\n\}", page, re.S)
    assert match, "no print styles"
    rules = match.group(1)
    assert re.search(r"\.scroll \{[^}]*max-height: none[^}]*overflow: visible", rules)
    assert not re.search(r"overflow: (auto|hidden|scroll)", rules)
    assert "break-inside: avoid" in rules and "position: static" in rules  # rows whole; no sticky header
    assert "beforeprint" in page  # folded tables open to print


def test_percent_change_reads_minus_100_only_for_zero():
    assert change_text(4.0, 0.0) == "−100 %"
    assert change_text(100.0, 0.3) == "333× smaller"  # −99.7 % would round to −100 %
    assert change_text(2.4, 1.7) == "−29 %" and change_text(2.0, 2.01) == "+0.5 %"
    assert change_text(1.0, 3.5) == "3.50× larger"
    assert change_text(0.0, 1.0) is None and change_text(None, 1.0) is None
    near = render_html(_document({"nominal geometry": 100.0, "calibrated geometry": 0.001}))
    cards = re.findall(r'class="change">([^<]*)<', near)
    assert cards == ["100,000× smaller from nominal geometry"]
    assert 'id="change-note"' in near
    exact = render_html(_document({"nominal geometry": 100.0, "calibrated geometry": 0.0}))
    assert re.findall(r'class="change">([^<]*)<', exact) == ["−100 % from nominal geometry"]


@pytest.fixture(scope="module")
def plan(tmp_path_factory):
    out = tmp_path_factory.mktemp("plan")
    assert main(["plan", str(ROOT / "urdf" / "kuka_lwr4plus.urdf"), "--tip-link", "lwr_flange", "--level", "full",
                 "--count", "12", "--target-points", "0.05,0,0.07", "--sigma-pos", "0.1", "--seed", "1",
                 "--out", str(out / "PLAN.csv"), "--report", str(out / "PLAN.json")]) == 0
    return out


def test_plan_page_has_poses_prediction_and_coverage(plan, capsys):
    document = json.loads((plan / "PLAN.json").read_text(encoding="utf-8"))
    before = (plan / "PLAN.json").read_bytes()
    assert main(["report", str(plan / "PLAN.json"), "--out", str(plan / "PLAN.html")]) == 0
    assert (plan / "PLAN.json").read_bytes() == before  # only read
    page = (plan / "PLAN.html").read_text(encoding="utf-8")
    poses = re.search(r'<table class="data sortable" id="poses-table">(.*?)</table>', page, re.S).group(1)
    assert poses.count("<tr>") == 1 + 12  # header + one row per pose
    first = (plan / "PLAN.csv").read_text(encoding="utf-8").splitlines()[1].split(",")
    assert f"<td>{np.degrees(float(first[0])):.3f}</td>" in poses and "lwr_joint_1 [deg]" in poses
    mean = document["predicted"]["plan"]["mean_position_mm"]
    assert f'id="predicted-mean">{mean:.3g}<' in page
    coverage = re.search(r'id="coverage-table">(.*?)</table>', page, re.S).group(1)
    assert coverage.count("<tr>") == 1 + len(document["chain"]["joints"])
    assert re.findall(r"<td>(\d+) %</td>", coverage) and 'id="figure-coverage"' in page
    assert "style.css" not in page and "@media print" in page  # the report's styles, inlined


def test_plan_page_without_its_csv_lists_the_additions(plan, tmp_path):
    (tmp_path / "PLAN.json").write_bytes((plan / "PLAN.json").read_bytes())  # no PLAN.csv beside it
    page = render_html(json.loads((tmp_path / "PLAN.json").read_text(encoding="utf-8")), base=tmp_path)
    assert 'id="poses-table"' not in page and page.count("</tr>") > 12 and "No PLAN.csv with SHA-256" in page


def test_joint_limits_are_the_robots_not_a_transmissions():
    """TIAGo's URDF names each joint again inside <transmission>, without a type or limits: the plan page
    read those, showed the prismatic torso in degrees and every limit as "—"."""
    from pincal.report.plan_html import joint_limits
    from pincal.robots import example_robot_data_urdf

    limits = joint_limits(example_robot_data_urdf("tiago_description/robots/tiago.urdf"),
                          ["torso_lift_joint", "arm_1_joint"])
    assert limits["torso_lift_joint"][0] == "prismatic" and None not in limits["torso_lift_joint"][1:]
    assert limits["arm_1_joint"][0] == "revolute" and None not in limits["arm_1_joint"][1:]


def test_the_prior_scales_the_fit_used_are_among_the_page_s_facts():
    """REPORT.json's identifiability.selection.prior_scale, as the console's 'prior scales:' line says it."""
    document = _document({"calibrated geometry": 1.0})
    document["identifiability"] = {"selection": {"criterion": "prior", "prior_scale": {
        "translation_mm": 10.0, "rotation_deg": 0.433, "joint_zero_deg": 10.0, "estimated": True, "reason": "r"}}}
    page = render_html(document)
    assert "prior scales" in page and "lengths 10 mm, angles 0.433°, joint zeros 10° (estimated)" in page
    assert "prior scales" not in render_html(_document({"calibrated geometry": 1.0}))  # none without a prior
