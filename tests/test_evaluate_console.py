"""What ``pincal evaluate`` tells a new user following the README on the real TIAGo data: the marker-1
row the README quotes, a report of another robot named before its chain is built, and a warning when
the evaluated error is implausible against the calibration's own (pincal.fit.plausibility)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import said, unaccepted_flags

from pincal.cli.commands import EXIT_USAGE, EXIT_WARNING, main
from pincal.errors import ModelError
from pincal.model.chain import KinematicChain
from pincal.robots import example_robot_data_urdf, kuka_lwr4plus_urdf

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data" / "tiago_mocap"
TRAIN = DATA / "qualisys_2021-11-30_static_postures.csv"
HELD_OUT = DATA / "qualisys_2021-11-26_static_postures.csv"
#: How a warning starts on stderr (pincal.cli): the tests that expect one and those that expect none check it alike.
WARNING = "pincal: warning: "


@pytest.fixture(scope="module")
def tiago(tmp_path_factory):
    """The README's calibrate command: (folder, corrected URDF, REPORT.json, what calibrate printed)."""
    folder = tmp_path_factory.mktemp("tiago")
    urdf, report = folder / "tiago_calibrated.urdf", folder / "REPORT.json"
    assert main(["calibrate", str(example_robot_data_urdf("tiago_description/robots/tiago.urdf")), str(TRAIN),
                 "--tip-link", "wrist_ft_tool_link", "--level", "full", "--out", str(urdf), "--report",
                 str(report), "--quiet"]) == 0
    return folder, urdf, report


def _row(text: str, label: str) -> list[float]:
    """The numbers of the printed table row starting with ``label`` (position mean, RMS, max [mm], ...)."""
    (line,) = [line for line in text.splitlines() if line.startswith(f"{label} ")]
    return [float(v) for v in line[len(label):].split()[:3]]


def test_evaluate_prints_the_marker_1_row_the_readme_quotes(tiago, capsys):
    folder, urdf, report = tiago
    capsys.readouterr()
    metrics = folder / "m.json"
    assert main(["evaluate", str(urdf), str(report), str(HELD_OUT), "--json", str(metrics)]) == 0
    out = capsys.readouterr().out
    doc = json.loads(metrics.read_text())
    # every point's row, as printed to four decimals, is the --json file's (mean, RMS, max) [mm]
    for p, point in enumerate(doc["position_per_point"]):
        expected = [point[k] for k in ("mean_mm", "rms_mm", "max_mm")]
        assert _row(out, f"  point {p + 1}") == pytest.approx(expected, abs=0.5e-4 + 1e-9)
    # the all-rows line is kept as scripts parse it, above the points' rows
    lines = out.splitlines()
    assert lines.index(next(ln for ln in lines if ln.startswith("62 rows "))) + 1 == lines.index(
        next(ln for ln in lines if ln.startswith("  point 1 ")))
    # the README's sentence names that row and its number
    readme = " ".join((ROOT / "README.md").read_text(encoding="utf-8").split())
    quoted = re.search(r"`point 1` row's `pos RMS`\) is ([0-9.]+) mm", readme)
    assert quoted, "README.md: the held-out sentence points at the `point 1` row"
    assert float(quoted[1]) == round(_row(out, "  point 1")[1], 2)


def test_calibrate_prints_the_same_point_rows(tmp_path, capsys):
    """calibrate's table has the rows evaluate's has, for its calibration rows (REPORT.json's numbers)."""
    urdf = example_robot_data_urdf("tiago_description/robots/tiago.urdf")
    assert main(["calibrate", str(urdf), str(TRAIN), "--tip-link", "wrist_ft_tool_link", "--level", "registration",
                 "--out", str(tmp_path / "o.urdf"), "--report", str(tmp_path / "r.json"), "--quiet"]) == 0
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "r.json").read_text())
    for p, point in enumerate(doc["fit"]["calibration_errors"]["position_per_point"]):
        assert _row(out, f"  point {p + 1}") == pytest.approx([point[k] for k in ("mean_mm", "rms_mm", "max_mm")],
                                                               abs=0.5e-4 + 1e-9)


@pytest.mark.parametrize("allow", [[], ["--allow-other-urdf"]], ids=["plain", "allow-other-urdf"])
def test_a_report_of_another_robot_is_named_first(tiago, capsys, allow):
    """Another robot's URDF beside a REPORT.json: one line saying the report was written for another URDF
    (its chain ends at a link this URDF lacks), exit 2, before the chain is built (no 'no link named')."""
    folder, _, report = tiago
    capsys.readouterr()
    code = main(["evaluate", str(kuka_lwr4plus_urdf()), str(report), str(HELD_OUT), *allow])
    err = capsys.readouterr().err.strip()
    assert code == EXIT_USAGE and len(err.splitlines()) == 1, err
    assert "written for another URDF" in err and "wrist_ft_tool_link" in err and "tiago_calibrated.urdf" in err, err
    # the message the chain would have given, had it been built first (so the check above can fail)
    with pytest.raises(ModelError, match="no link named 'wrist_ft_tool_link'"):
        KinematicChain.from_urdf(kuka_lwr4plus_urdf(), "wrist_ft_tool_link")
    assert "no link named" not in err


def _swapped(folder: Path) -> Path:
    """The held-out day with the x and y columns of every marker swapped."""
    lines = HELD_OUT.read_text().splitlines(keepends=True)
    names = lines[0].rstrip("\n").split(",")
    names = [f"y{n[1:]}" if n[:1] == "x" and n[1:].isdigit() else f"x{n[1:]}" if n[:1] == "y" and n[1:].isdigit()
             else n for n in names]
    path = folder / "swapped.csv"
    path.write_text(",".join(names) + "\n" + "".join(lines[1:]))
    return path


def test_the_real_held_out_day_does_not_warn(tiago, capsys):
    """TIAGo's other day: 4.1 mm RMS against the calibration's 2.4 mm (all markers): no warning, --strict exits 0."""
    folder, urdf, report = tiago
    capsys.readouterr()
    metrics = folder / "plain.json"
    assert main(["evaluate", str(urdf), str(report), str(HELD_OUT), "--json", str(metrics), "--strict"]) == 0
    assert WARNING not in capsys.readouterr().err
    assert json.loads(metrics.read_text())["warnings"] == []


def test_swapped_axes_warn_and_strict_exits_3_with_the_json_written(tiago, capsys):
    folder, urdf, report = tiago
    data = _swapped(folder)
    capsys.readouterr()
    assert main(["evaluate", str(urdf), str(report), str(data)]) == 0  # a warning alone keeps exit 0
    err = capsys.readouterr().err
    assert WARNING in err and "swapped" in err and "--new-session" in err, err
    assert unaccepted_flags("evaluate", err) == []  # what it says to try, evaluate takes
    metrics = folder / "swapped.json"
    page = folder / "swapped.html"
    assert main(["evaluate", str(urdf), str(report), str(data), "--json", str(metrics), "--html", str(page),
                 "--strict"]) == EXIT_WARNING
    warnings = json.loads(metrics.read_text())["warnings"]
    assert [w["code"] for w in warnings] == ["evaluation"]
    assert said(capsys.readouterr().err) == [warnings[0]["message"]]
    assert page.read_text(encoding="utf-8").count("callout warning") == 1  # the calibration itself gave none


def test_the_evaluation_check_takes_calibrates_thresholds():
    """20× the calibration's RMS (at least the best sensor's 0.05 mm), or 5 mm after a calibration below
    1 mm (calibrate's MAX_NOISE_RATIO and MAX_RMS_M; pincal.fit.plausibility gives their sources)."""
    from pincal.fit.plausibility import MAX_NOISE_RATIO, MAX_RMS_M, MIN_REFERENCE_RMS_M, check_evaluation

    mm = 1e-3
    assert check_evaluation(4.1 * mm, 2.4 * mm) == []  # TIAGo's real day
    ratio = MAX_NOISE_RATIO
    assert check_evaluation(ratio * 2.4 * mm * 0.99, 2.4 * mm) == []
    assert [f.code for f in check_evaluation(ratio * 2.4 * mm * 1.01, 2.4 * mm)] == ["evaluation"]
    assert check_evaluation(MAX_RMS_M * 0.99, 0.9 * mm) == []  # under 5 mm, under 20×
    assert [f.code for f in check_evaluation(MAX_RMS_M * 1.01, 0.9 * mm)] == ["evaluation"]  # 5.6× only
    assert check_evaluation(MAX_RMS_M * 1.01, 1.1 * mm) == []  # a coarse calibration: the ratio alone
    # a noise-free calibration (RMS ~0): the ratio is taken against the best sensor's accuracy
    assert check_evaluation(ratio * MIN_REFERENCE_RMS_M * 0.99, 1e-12) == []
    assert check_evaluation(ratio * MIN_REFERENCE_RMS_M * 1.01, 1e-12) != []
    assert check_evaluation(np.nan, 1 * mm) == [] and check_evaluation(1.0, None) == []
    reported = check_evaluation(1.0, 1 * mm, reported_registration=True)[0].message
    assert "--new-session" in reported and "--new-session" not in check_evaluation(1.0, 1 * mm)[0].message


def test_diagnose_prints_the_point_rows_of_both_sets(tmp_path, capsys):
    """diagnose's table, calibration and held-out rows, has the same rows (docs/diagnose.md's 2.47 mm marker 1)."""
    urdf = example_robot_data_urdf("tiago_description/robots/tiago.urdf")
    report = tmp_path / "REPORT.json"
    assert main(["diagnose", str(urdf), str(TRAIN), "--validation", str(HELD_OUT), "--tip-link", "wrist_ft_tool_link",
                 "--out", str(tmp_path / "d.urdf"), "--report", str(report), "--plots", str(tmp_path / "p"),
                 "--quiet"]) == 0
    out = capsys.readouterr().out.rsplit("\nheld-out rows ", 1)  # the table's row, not a note's words
    diagnosis = json.loads(report.read_text())["diagnosis"]
    for text, errors in zip(out, (diagnosis["calibration_errors"], diagnosis["heldout_errors"])):
        for p, point in enumerate(errors["position_per_point"]):
            assert _row(text, f"  point {p + 1}") == pytest.approx(
                [point[k] for k in ("mean_mm", "rms_mm", "max_mm")], abs=0.5e-4 + 1e-9)
