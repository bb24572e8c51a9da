"""One loader reads REPORT.json back (pincal.report.reading): a bad file is one line naming it and the key.

Real reports are written once (TIAGo at level registration, MUKCa's iiwa on the socket fixture,
~1 s each), then broken the ways a user's file breaks: gone, a folder, cut short, another kind of
document, a key deleted, a value of the wrong form. Each reader (``evaluate``, ``evaluate --fixture``,
``report``) says so in one line that names the file, and the key where one is at fault.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import report_kind

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.report.document import read_report
from pincal.report.fixture import read_fixture_block
from pincal.report.reading import KINDS, PAGE_KINDS, document_kind, load_report, value_at
from pincal.robots import example_robot_data_urdf

DATA = Path(__file__).resolve().parents[1] / "pincal" / "datasets"
TIAGO = DATA / "tiago_mocap" / "qualisys_2021-11-30_static_postures.csv"
MUKCA = DATA / "mukca"


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """A calibration's and a socket-fixture calibration's REPORT.json, as calibrate wrote them."""
    folder = tmp_path_factory.mktemp("reports")
    tiago = str(example_robot_data_urdf("tiago_description/robots/tiago.urdf"))
    assert main(["calibrate", tiago, str(TIAGO), "--tip-link", "wrist_ft_tool_link", "--level", "registration",
                 "--out", str(folder / "tiago.urdf"), "--report", str(folder / "tiago.json"), "--quiet"]) == 0
    assert main(["calibrate", str(MUKCA / "urdf" / "iiwa14.urdf"), str(MUKCA / "kuka_14" / "front.csv"),
                 "--fixture", str(MUKCA / "fixture.csv"), "--tip-link", "tool0", "--level", "registration",
                 "--out", str(folder / "iiwa.urdf"), "--report", str(folder / "iiwa.json"), "--quiet"]) == 0
    return {name: json.loads((folder / f"{name}.json").read_text(encoding="utf-8")) for name in ("tiago", "iiwa")}


def _one_line(excinfo) -> str:
    text = str(excinfo.value)
    assert "\n" not in text
    return text


def test_each_kind_is_told_apart_as_the_schema_does(reports):
    """The loader's kind is the schema's (tests/conftest.py tells them apart on its own)."""
    for document in reports.values():
        assert KINDS[document_kind(document)][0].__name__ == report_kind(document)
    diagnosis = {**reports["tiago"], "diagnosis": {}}
    paper = {**reports["tiago"], "model": "dh"}
    assert [document_kind(d) for d in (diagnosis, paper)] == ["diagnosis", "paper"]
    assert KINDS[document_kind(diagnosis)][0].__name__ == report_kind(diagnosis)
    assert document_kind({"position": {}}) == "evaluation" and document_kind({"plan_version": 1}) == "plan"
    assert document_kind([1, 2]) is None and document_kind({"rows": 3}) is None


@pytest.mark.parametrize("case, message", [
    ("missing", "{path}: no such report file"),
    ("directory", "{path}: is a directory; give the REPORT.json file"),
    ("cut short", "{path}: not a readable JSON report (Expecting value at line 1, column 16)"),
    ("a list", "{path}: not a pincal report (no 'parameters'"),
])
def test_a_file_that_is_no_report_is_one_line(tmp_path, case, message):
    path = tmp_path / "REPORT.json"
    if case == "directory":
        path = tmp_path
    elif case == "cut short":
        path.write_text('{"parameters": ', encoding="utf-8")
    elif case == "a list":
        path.write_text("[1, 2, 3]", encoding="utf-8")
    with pytest.raises(PincalError) as excinfo:
        load_report(path, PAGE_KINDS)
    assert _one_line(excinfo).startswith(message.format(path=path))


def test_another_kind_is_named_with_what_to_do(tmp_path, reports):
    fixture, sensor, plan = tmp_path / "fixture.json", tmp_path / "sensor.json", tmp_path / "PLAN.json"
    fixture.write_text(json.dumps(reports["iiwa"]), encoding="utf-8")
    sensor.write_text(json.dumps(reports["tiago"]), encoding="utf-8")
    plan.write_text(json.dumps({"plan_version": 1}), encoding="utf-8")
    with pytest.raises(PincalError) as excinfo:
        read_report(fixture)
    assert _one_line(excinfo) == (f"{fixture}: is a socket-fixture calibration's REPORT.json; evaluate it with "
                                  "--fixture FIXTURE.csv")
    with pytest.raises(PincalError) as excinfo:
        read_report(plan)
    assert _one_line(excinfo) == f"{plan}: is a PLAN.json; pass the REPORT.json written by 'pincal calibrate'"
    with pytest.raises(PincalError) as excinfo:
        load_report(sensor, ("fixture",), hint="pass the REPORT.json written by 'pincal calibrate --fixture'")
    assert _one_line(excinfo) == (f"{sensor}: is a calibration's REPORT.json; pass the REPORT.json written by "
                                  "'pincal calibrate --fixture'")
    assert load_report(sensor, PAGE_KINDS) == reports["tiago"]


def test_a_report_reads_back_as_written(tmp_path, reports):
    path = tmp_path / "REPORT.json"
    document = reports["tiago"]
    path.write_text(json.dumps(document), encoding="utf-8")
    model = read_report(path)
    for which, registration in (("position", model.registration_position),
                                ("orientation", model.registration_orientation)):
        assert registration.as_dict() == document["registration"][which]
    assert model.tool_parent == document["tool"]["parent_link"] == "wrist_ft_tool_link"
    assert model.points.tolist() == document["tool"]["points_m"] and model.urdf_sha256 == document["urdf_sha256"]
    assert model.nominal_urdf == document["sources"]["urdf"] and len(model.sessions) == len(document["sessions"])


def _broken(document: dict, key: str, value=None) -> dict:
    """``document`` with the dotted ``key`` deleted (value None) or set to ``value``."""
    broken = json.loads(json.dumps(document))
    *path, last = key.split(".")
    inner = broken
    for part in path:
        inner = inner[part]
    if value is None:
        del inner[last]
    else:
        inner[last] = value
    return broken


@pytest.mark.parametrize("key, value, message", [
    ("registration", None, "no key 'registration.position'"),
    ("registration.position", None, "no key 'registration.position'"),
    ("registration.position.translation_m", None,
     "key 'registration.position' has an unexpected form (registration needs numeric 'rotation_xyzw' and "),
    ("tool.parent_link", None, "no key 'tool.parent_link'"),
    ("tool.points_m", [[0.1, 0.2]], "key 'tool.points_m' has an unexpected form (a list of [x, y, z] expected)"),
    ("tool.xyz_m", [0.1, 0.2], "key 'tool.xyz_m' has an unexpected form (3 numbers expected)"),
    ("tool", [1, 2], "key 'tool' is not an object (got list)"),
    ("urdf_sha256", "abc", "key 'urdf_sha256' has an unexpected form (64 hexadecimal digits expected)"),
    ("sessions", [{"name": "a"}], "key 'sessions' has an unexpected form (no key 'registration')"),
])
def test_a_missing_or_malformed_key_is_named(tmp_path, reports, key, value, message):
    path = tmp_path / "REPORT.json"
    path.write_text(json.dumps(_broken(reports["tiago"], key, value)), encoding="utf-8")
    with pytest.raises(PincalError) as excinfo:
        read_report(path)
    line = _one_line(excinfo)
    assert line.startswith(f"{path}: {message}") and line.endswith("pass a REPORT.json as pincal wrote it")


@pytest.mark.parametrize("key, value, message", [
    ("fixture.nominal", None, "no key 'fixture.nominal.ball_centre_m'"),
    ("fixture.ball_centre_m", [1.0, 2.0], "key 'fixture.ball_centre_m' has an unexpected form (cannot reshape"),
])
def test_a_fixture_report_names_its_key(reports, key, value, message):
    with pytest.raises(PincalError) as excinfo:
        read_fixture_block(_broken(reports["iiwa"], key, value), "iiwa.json")
    assert _one_line(excinfo).startswith(f"iiwa.json: {message}")
    tip, ball, nominal, sha = read_fixture_block(reports["iiwa"], "iiwa.json")
    assert tip == "tool0" and ball.shape == nominal.shape == (3,) and len(sha) == 64


def test_value_at_reads_the_dotted_key():
    document = {"a": {"b": {"c": 3}}, "d": None}
    assert value_at(document, "a.b.c", "x.json") == 3 and value_at(document, "a.b.z", "x.json", default=7) == 7
    assert value_at(document, "a.b.c", "x.json", float) == 3.0 and value_at(document, "d", "x.json") is None


def test_the_commands_print_the_line_and_exit_2(tmp_path, reports, capsys):
    """evaluate, evaluate --fixture and report read through the loader: one line, exit 2, no traceback."""
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps(_broken(reports["tiago"], "registration.position")), encoding="utf-8")
    fixture = tmp_path / "fixture.json"
    fixture.write_text(json.dumps(reports["iiwa"]), encoding="utf-8")
    tiago = str(example_robot_data_urdf("tiago_description/robots/tiago.urdf"))
    runs = [
        (["evaluate", tiago, str(broken), str(TIAGO)], f"{broken}: no key 'registration.position'"),
        (["evaluate", str(MUKCA / "urdf" / "iiwa14.urdf"), str(broken), str(MUKCA / "kuka_14" / "front.csv"),
          "--fixture", str(MUKCA / "fixture.csv")], f"{broken}: is a calibration's REPORT.json"),
        (["report", str(tmp_path / "nothing.json"), "--out", str(tmp_path / "x.html")],
         f"{tmp_path / 'nothing.json'}: no such report file"),
    ]
    for argv, start in runs:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"pincal: error: {start}") and "\n" not in err, err
