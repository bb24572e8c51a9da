"""What `diagnose` and `evaluate` say about the temperature and pause inputs they cannot use (a review of
heat and pauses): a temperature column in some session files only, `--temperature-column` where
no thermal expansion applies, a malformed `pauses` entry, the text of a position-only effect, and the
evaluate page's record of the thermal and pause-step corrections.

No fit here: the CSV reader, the readers of the report's entries and the page's renderer on small inputs
(the end-to-end runs are tests/test_thermal.py's)."""

from __future__ import annotations

import html
import re

import numpy as np
import pytest

from pincal.diagnosis.conditions import read_readings, search_conditions
from pincal.errors import PincalError
from pincal.measurements.csv_v1 import read_sessions
from pincal.measurements.data import JointSpec

JOINTS = [JointSpec("j1", "revolute"), JointSpec("j2", "revolute")]


def _session(path, temperature: str | None = "temperature_c", extra: str = ""):
    """A CSV v1 session file of 4 rows a minute apart, its temperature in column ``temperature`` (None: none)
    and one more numeric column ``extra``."""
    columns = ["j1", "j2", "x", "y", "z", "time"] + ([temperature] if temperature else []) + ([extra] if extra else [])
    rows = [[0.1 * k, -0.2 * k, 1.0 + k, 0.5, 0.2, 60.0 * k] + ([20.0 + k] if temperature else []) + (
        [k] if extra else []) for k in range(4)]
    path.write_text("\n".join([",".join(columns)] + [",".join(map(repr, r)) for r in rows]) + "\n", encoding="utf-8")
    return path


def _notes(data, column=None):
    readings = read_readings(data, None, column)
    return search_conditions(data.extra.get("time"), data.sessions.tolist(), readings, np.ones(data.n_rows, bool))


def test_a_temperature_column_in_some_session_files_only_is_named_not_dropped(tmp_path):
    """A default temperature column in 2 of 3 files: one note names the file without it (not the generic 'add
    a column' line, which would tell the user to add what they have); named with --temperature-column: refused,
    naming the file. Every file with it, or a generic extra column in some files only: no such note."""
    with_it = [_session(tmp_path / "a.csv"), _session(tmp_path / "b.csv", extra="shipped_row")]
    without = _session(tmp_path / "c.csv", temperature=None)
    data, _ = read_sessions([*with_it, without], JOINTS)
    assert data.dropped_extra == {"temperature_c": (str(without),), "shipped_row": (str(with_it[0]), str(without))}
    search = _notes(data)
    (thermal,) = [n for n in search.notes if n.startswith("thermal")]
    assert thermal.startswith(f"thermal cannot be tested: {without} lack(s) the temperature column 'temperature_c'")
    assert "add it to that file" in thermal and "add a column" not in thermal
    (generic,) = [n for n in _notes(read_sessions([without], JOINTS)[0]).notes if n.startswith("thermal")]
    assert "add a column" in generic  # the line above is not: no file has the column
    refused = f"^{re.escape(str(without))}: no temperature column 'temperature_c', which the other session"
    with pytest.raises(PincalError, match=refused):
        _notes(data, "temperature_c")
    data, _ = read_sessions(with_it, JOINTS)  # shipped_row in one file only: dropped, no note of it
    search = _notes(data)
    assert search.column == "temperature_c" and not any("shipped_row" in n for n in search.notes), search.notes
    assert [e.type for e in search.candidates] == ["thermal"]
    data, _ = read_sessions([tmp_path / "a.csv"], JOINTS)
    assert data.dropped_extra == {}


def test_a_time_or_sigma_column_in_some_session_files_only_is_named(tmp_path):
    """The same for the time column a drift and a pause step need, and for --sigma-column: a default time
    column in 1 of 2 files gives one note naming the file without it (not 'add a column'); named with
    --time-column or --sigma-column it is refused, naming that file."""
    from pincal.fit.chain_calibration import row_weights
    from pincal.model.drift import time_column

    with_time = _session(tmp_path / "a.csv", extra="sigma_mm")
    without = tmp_path / "c.csv"  # no time, no sigma_mm
    rows = "".join(f"{0.1 * k},{0.2 * k},{1.0 + k},0.5,0.2,{20.0 + k}\n" for k in range(4))
    without.write_text("j1,j2,x,y,z,temperature_c\n" + rows, encoding="utf-8")
    data, _ = read_sessions([with_time, without], JOINTS)
    assert set(data.dropped_extra) == {"time", "sigma_mm"} and data.dropped_extra["time"] == (str(without),)
    assert time_column(data) is None
    readings = read_readings(data, None, None)
    search = search_conditions(None, data.sessions.tolist(), readings, np.ones(data.n_rows, bool))
    (timing,) = [n for n in search.notes if "pause_step" in n]
    assert timing.startswith(f"drift and pause_step cannot be tested: {without} lack(s) the time column 'time'")
    assert "add a column" not in timing
    alone, _ = read_sessions([without], JOINTS)  # no file has a time column: the generic line
    (generic,) = [n for n in search_conditions(None, alone.sessions.tolist(), read_readings(alone, None, None),
                                               np.ones(alone.n_rows, bool)).notes if "pause_step" in n]
    assert "add a column" in generic
    with pytest.raises(PincalError, match=f"^{re.escape(str(without))}: no time column 'time', which the other"):
        time_column(data, "time")
    with pytest.raises(PincalError, match=f"^{re.escape(str(without))}: no column 'sigma_mm' for --sigma-column, wh"):
        row_weights(data, "sigma_mm")


@pytest.mark.parametrize("key, index", [("pauses", 0), ("pause_spans_s", 1)])
@pytest.mark.parametrize("session", [3, None, ["A"], ""])
def test_a_pause_or_span_whose_session_is_not_a_name_is_refused_by_its_key(key, index, session):
    """A REPORT.json `pauses` or `pause_spans_s` entry whose session is not a name would apply to no row
    (str(3) = '3' names no session): refused in one line naming the key; the well-formed report applies."""
    from pincal.measurements.data import MeasurementSet
    from pincal.model.drift import read_time_spans
    from pincal.model.effects import Effect
    from pincal.workflows.conditions import applied_conditions

    time = np.array([0.0, 500.0, 4000.0])
    data = MeasurementSet(joint_names=("j",), q=np.zeros((3, 1)), points=np.zeros((3, 1, 3)), rotations=None,
                          roles=np.array(["validation"] * 3, dtype=object), lines=np.arange(2, 5),
                          extra={"time": time}, source="v.csv")
    report = {"time_column": "time", "pause_spans_s": [{"session": "A", "first": 0.0, "last": 5e3, "mean": 2e3}],
              "pauses": [{"pause": 1, "session": "A", "before_s": 100.0, "after_s": 3000.0}]}
    steps = [(Effect("pause_step", pause=1), np.array([0.0, 1e-5, 0.0]))]
    held = (np.array(["A"] * 3, dtype=object), np.zeros(3, dtype=np.intp))
    applied = applied_conditions(steps, report, data, held, None, "r.json")
    assert applied.conditions is not None and applied.conditions.steps[:, 1].tolist() == [0.0, 0.0, 1e-5]
    report[key] = [dict(report[key][0], session=session)]
    with pytest.raises(PincalError, match=rf"^r\.json: {key}\[\]\.session must be a session's name .* got "
                                          rf"{re.escape(repr(session))}: such an entry applies to no row"):
        applied_conditions(steps, report, data, held, None, "r.json")
    with pytest.raises(PincalError, match=r"^r\.json: time_spans_s\[\]\.session must be"):
        read_time_spans([{"session": session, "first": 0.0, "last": 1.0, "mean": 0.5}], "r.json")


def test_an_effect_that_cannot_turn_the_target_is_not_said_to_turn_it(tmp_path):
    """A thermal expansion scales lengths (eq T1: orientations unchanged), a pause step, a drift translate, a
    sensor scale scales: with 6D rows their turn is 0 by construction, so the console line and the report page
    say how far they move the target only; a joint effect keeps its turn."""
    from pincal.diagnosis.verdicts import TargetChange
    from pincal.model.effects import Effect
    from pincal.report.sections import effects_section

    change = TargetChange(41e-6, 84e-6, 0.0, 0.0)
    position_only = [Effect("thermal"), Effect("pause_step", pause=1), Effect("drift"), Effect("sensor_scale")]
    for effect in position_only:
        assert change.describe(effect) == "moves the target 0.041 mm RMS (0.084 mm at most)", effect
    turning = TargetChange(41e-6, 84e-6, 2e-4, 5e-4).describe(Effect("backlash", "j1", source="approach"))
    assert turning.endswith(", turns it 0.2 mrad RMS (0.5 at most)"), turning
    moved = {"rms_mm": 0.041, "max_mm": 0.084, "rms_mrad": 0.0, "max_mrad": 0.0}
    doc = {"diagnosis": {"steps": []}, "effects": [
        {"type": "thermal", "value": 1.2e-5, "std": 1e-6, "target_change": moved},
        {"type": "pause_step", "pause": 1, "value": [0.0, -7.6e-5, 0.0], "std": [3e-6] * 3, "target_change": moved},
        {"type": "backlash", "joint": "j1", "source": "approach", "value": -0.012, "std": 6e-4,
         "target_change": dict(moved, rms_mrad=0.2, max_mrad=0.5)}]}
    section = effects_section(doc, {"j1": "revolute"}, tmp_path, lambda *a: None)
    assert section is not None
    assert [e["moves"] for e in section["final"]] == ["0.041 mm RMS (0.084 at most)"] * 2 + [
        "0.041 mm RMS (0.084 at most), 0.2 mrad RMS"]


def test_temperature_column_for_a_report_without_thermal_expansion_is_refused():
    """evaluate --temperature-column on a report without a thermal effect would change nothing: refused in one
    line naming the flag and the report, as evaluate refuses --nominal without --fixture (with --fixture:
    tests/test_fixture.py). Without the flag, or with a thermal effect, it applies."""
    from pincal.measurements.data import MeasurementSet
    from pincal.model.effects import Effect
    from pincal.workflows.conditions import applied_conditions

    data = MeasurementSet(joint_names=("j",), q=np.zeros((2, 1)), points=np.zeros((2, 1, 3)), rotations=None,
                          roles=np.array(["validation"] * 2, dtype=object), lines=np.arange(2, 4),
                          extra={"temperature_c": np.array([20.0, 22.0])}, source="v.csv")
    held = (np.array(["A"] * 2, dtype=object), np.zeros(2, dtype=np.intp))
    backlash = [(Effect("backlash", "j", source="approach"), np.array([0.01]))]
    with pytest.raises(PincalError, match=r"^--temperature-column applies to a report with a thermal expansion, "
                                          r"and r\.json has none .*; drop it$"):
        applied_conditions(backlash, {}, data, held, "temperature_c", "r.json")
    assert applied_conditions(backlash, {}, data, held, None, "r.json").conditions is None
    report = {"temperature_column": "t_other", "temperature_range_c": {"min": 20.0, "max": 22.0, "mean": 21.0}}
    applied = applied_conditions([(Effect("thermal"), np.array([1e-5]))], report, data, held, "temperature_c",
                                 "r.json")
    assert applied.conditions is not None and applied.conditions.expansion.tolist() == pytest.approx([-1e-5, 1e-5])


def test_the_evaluate_page_says_which_thermal_and_pause_corrections_its_rows_took():
    """evaluate --html: the evaluated card names the thermal expansion (α, column, range, rows held) and the
    pause steps (rows stepped, pauses, rows outside the span) applied to its rows, from the document the
    command builds (pincal.report.row_errors.evaluation_document) and from an evaluate --json file alone;
    a page without them says neither."""
    from pincal.fit.metrics import PoseErrors
    from pincal.report.html import render_html
    from pincal.report.row_errors import EvaluatedRows, evaluation_document

    errors = PoseErrors(np.full((4, 1), 3e-5), None)
    thermal = {"alpha_per_k": 1.2e-5, "temperature_column": "temperature_c", "rows_applied": 3, "rows_held": 1,
               "temperature_range_c": {"min": 20.0, "max": 25.4, "mean": 23.1}, "held_rule": "held"}
    steps = {"pauses": [{"pause": 1, "session": "cal", "before_s": 1400.0, "after_s": 30200.0}], "rows_in_span": 4,
             "rows_outside": 0, "rule": "nearest", "rows_stepped": 2}
    said = ("thermal expansion applied (eq T1): α = 12 µm/m/K, each row at its temperature in column 'temperature_c' "
            "against 23.1 °C: 3 row(s) inside the fitted range 20–25.4 °C, 1 outside it held at its nearer end",
            "pause steps applied (eq T2): 2 row(s) after a pause of their session (pause 1 of session 'cal') take its "
            "registration step")
    rows = EvaluatedRows([2, 3, 4, 5])
    alone = dict(errors.as_dict(), skipped_cpa_rows=0, sessions=[], drift=None, thermal=thermal, pause_steps=steps)
    shown = evaluation_document("d.urdf", "v.csv", errors, alone, rows)  # the evaluate --json document
    for page in map(html.unescape, (render_html({}, evaluation=shown), render_html(alone))):
        for line in said:
            assert line in page, line
    plain = dict(errors.as_dict(), skipped_cpa_rows=0, sessions=[], drift=None)
    bare = render_html({}, evaluation=evaluation_document("d.urdf", "v.csv", errors, plain, rows))
    assert "thermal expansion applied" not in bare and "pause steps applied" not in bare
