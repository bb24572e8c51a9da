"""Temperature and pauses: thermal expansion and a registration step per pause.

The cell: the 6-axis arm of tests/conftest.py (its geometry off by 0.3 mm / 0.3 mrad per placement
parameter) measured by a laser tracker 3 m away in 6D (20 µm per axis, 0.003°), one target point
0.1 m off the flange, 150 calibration and 60 held-out postures interleaved in time, a row every
20 s (70 min). Noise floor of the held-out RMS point distance: √3 · 20 µm = 35 µm; bound 1.3× it
(the scenario suite's, scripts/scenarios.py: the estimation error of ~40 unknowns from 900
coordinates adds ~10 %, as in tests/test_couplings.py). The hidden effects:

* thermal: α = 12e-6/K (steel) under a warm-up 20 → 26 °C (τ = 30 min,
  :func:`pincal.simulation.sensor.warm_up`; 20 → 25.4 °C over the rows): the tool ~1.3 m from the
  base moves up to 12e-6 × 5.4 K × 1.3 m = 84 µm, 4 noise σ;
* pause: an 8 h stop halfway, the registration's translation stepped by 76 µm in y (as on a real
  laser-tracker raster).
"""

from __future__ import annotations

import contextlib
import csv
import html
import io
import json
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from conftest import assert_close, numeric_jacobian

from pincal.cli.commands import main
from pincal.diagnosis.verdicts import PLAUSIBLE
from pincal.errors import PincalError
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain
from pincal.model.effect_units import value_unit
from pincal.model.effects import Effect, EffectInputs, effect_from_dict, effect_to_dict, gravity_torques
from pincal.model.parameter_sets import PlacementErrors
from pincal.model.sensor import Registration
from pincal.model.thermal import (
    ALPHA_RANGE,
    Pause,
    RowConditions,
    TemperatureRange,
    find_pauses,
    implausible,
    pause_rows,
    temperature_column,
)
from pincal.residuals.base import KinematicsCache
from pincal.residuals.sensor import SensorResidual, TargetEstimate
from pincal.residuals.sensor_values import ModelledEffects, RowWeights
from pincal.simulation.cells import measure_truth, sensor_at
from pincal.simulation.sensor import (
    SimulatedEffects,
    SimulatedSensor,
    random_configurations,
    simulated_conditions,
    warm_up,
)

NOISE_M = 20e-6
BOUND_MM = 1.3 * np.sqrt(3) * NOISE_M * 1000.0
ALPHA = 12e-6  # 1/K
STEP_M = (0.0, -76e-6, 0.0)
GAP_S = 8 * 3600.0
ROW_S = 20.0
N_CAL, N_VAL = 150, 60


def _cell(urdf, folder, alpha: float = 0.0, step=None, seed: int = 21):
    """calibration and held-out CSVs of the cell of the module docstring (``time``, ``temperature_c``)."""
    chain = KinematicChain.from_urdf(urdf, "flange")
    params = PlacementErrors(chain)
    rng = np.random.default_rng(seed)
    truth = rng.normal(0.0, 3e-4, params.size)
    n = N_CAL + N_VAL
    q = random_configurations(chain, rng, n)
    time = ROW_S * np.arange(n)
    held = np.zeros(n, dtype=bool)
    held[np.round(np.linspace(0, n - 1, N_VAL + 2)[1:-1]).astype(int)] = True  # interleaved in time
    stepped = time >= time[n // 2]
    time = time + GAP_S * stepped  # an 8 h pause halfway
    temperature = warm_up(time)
    effects = ([(Effect("thermal"), np.array([alpha]))] if alpha else []) + (
        [(Effect("pause_step", pause=1), np.asarray(step))] if step is not None else [])
    rows = measure_truth(params, truth, q, sensor_at(3.0), rng,
                         SimulatedSensor(NOISE_M, np.radians(0.003), points=np.array([[0.03, 0.0, 0.1]])),
                         "calibration",
                         effects=SimulatedEffects(time=time,
                                                  conditions=simulated_conditions(effects, temperature, stepped),
                                                  temperature=temperature))
    folder.mkdir(parents=True, exist_ok=True)
    write_measurements(folder / "cal.csv", rows.select(~held))
    write_measurements(folder / "val.csv", replace(rows.select(held), roles=np.full(N_VAL, "validation", dtype=object)))
    return folder / "cal.csv", folder / "val.csv"


def _diagnose(urdf, folder, *flags):
    """diagnose the cell's CSVs in ``folder``: its REPORT.json and what it printed."""
    report, out, err = folder / "d" / "REPORT.json", io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):  # also from a module fixture
        code = main(["diagnose", str(urdf), str(folder / "cal.csv"), "--validation", str(folder / "val.csv"),
                     "--tip-link", "flange", "--quiet", "--out", str(folder / "d.urdf"), "--report", str(report),
                     "--plots", str(folder / "plots"), *flags])
    assert code == 0, err.getvalue()
    return json.loads(report.read_text(encoding="utf-8")), out.getvalue()


def _evaluate(folder, data, capsys, name="e", *flags):
    out = folder / f"{name}.json"
    code = main(["evaluate", str(folder / "d.urdf"), str(folder / "d" / "REPORT.json"), str(data),
                 "--json", str(out), *flags])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    return json.loads(out.read_text(encoding="utf-8")), printed.err


@pytest.fixture(scope="module")
def thermal_run(industrial_arm_urdf, tmp_path_factory):
    """The cell with the hidden expansion, diagnosed: its folder, REPORT.json and console."""
    folder = tmp_path_factory.mktemp("thermal")
    _cell(industrial_arm_urdf, folder, alpha=ALPHA)
    return (folder, *_diagnose(industrial_arm_urdf, folder))


def test_hidden_expansion_is_named_measured_and_removed(thermal_run, capsys):
    """(a) thermal named first, α within 3 std of the truth, held-out at the noise floor; evaluate
    reproduces it, and the same model without the expansion is off the floor."""
    thermal_run, doc, printed = thermal_run
    effect = doc["effects"][0]
    assert effect["type"] == "thermal", doc["effects"]
    assert abs(effect["value"] - ALPHA) <= 3 * effect["std"], effect
    (final,) = [line for line in printed.splitlines() if line.startswith("final model: thermal = ")]
    assert " µm/m/K: moves the target " in final and final.endswith(" mm at most)"), final  # the move only:
    assert "turns it" not in final, final  # eq T1 turns nothing
    with open(thermal_run / "cal.csv", newline="", encoding="utf-8") as f:
        fitted = TemperatureRange.of([float(row["temperature_c"]) for row in csv.DictReader(f)])
    assert doc["temperature_column"] == "temperature_c"
    assert doc["temperature_range_c"] == pytest.approx(fitted.as_dict(), abs=1e-9)
    evaluated, _ = _evaluate(thermal_run, thermal_run / "val.csv", capsys, "e", "--html", str(thermal_run / "e.html"))
    page = html.unescape((thermal_run / "e.html").read_text(encoding="utf-8"))
    assert f"thermal expansion applied (eq T1): α = {effect['value'] * 1e6:.3g} µm/m/K" in page
    assert evaluated["position"]["rms_mm"] < BOUND_MM
    assert evaluated["position"]["rms_mm"] == pytest.approx(doc["diagnosis"]["heldout_errors"]["position"]["rms_mm"],
                                                           rel=1e-9)
    assert evaluated["thermal"]["rows_held"] == 0 and evaluated["thermal"]["rows_applied"] == N_VAL
    without = dict(doc, effects=[e for e in doc["effects"] if e["type"] != "thermal"])
    (thermal_run / "d" / "REPORT.json").write_text(json.dumps(without), encoding="utf-8")
    try:
        bare, _ = _evaluate(thermal_run, thermal_run / "val.csv", capsys, "bare")
        code = main(["evaluate", str(thermal_run / "d.urdf"), str(thermal_run / "d" / "REPORT.json"),
                     str(thermal_run / "val.csv"), "--temperature-column", "temperature_c"])
        err = capsys.readouterr().err  # the flag would change nothing: refused
        assert code == 2 and err.count("\n") == 1 and "--temperature-column applies to a report with a thermal" in err
    finally:
        (thermal_run / "d" / "REPORT.json").write_text(json.dumps(doc), encoding="utf-8")
    assert bare["position"]["rms_mm"] > evaluated["position"]["rms_mm"]


def test_evaluate_holds_a_row_beyond_the_fitted_range_at_its_end(thermal_run, capsys):
    """(e) held-out rows 5 K above the fitted range are evaluated at its upper end: the same errors
    as the rows at exactly that end, counted and said once on stderr."""
    thermal_run, doc, _ = thermal_run
    high = doc["temperature_range_c"]["max"]
    lines = (thermal_run / "val.csv").read_text(encoding="utf-8").splitlines()
    column = lines[0].split(",").index("temperature_c")

    def with_temperature(name, value):
        rows = [line.split(",") for line in lines[1:]]
        for row in rows:
            row[column] = repr(value)
        (thermal_run / name).write_text("\n".join([lines[0]] + [",".join(r) for r in rows]) + "\n", encoding="utf-8")
        return thermal_run / name

    beyond, err = _evaluate(thermal_run, with_temperature("hot.csv", high + 5.0), capsys, "hot")
    at_end, end_err = _evaluate(thermal_run, with_temperature("end.csv", high), capsys, "end")
    assert beyond["position"] == at_end["position"]
    assert beyond["thermal"]["rows_held"] == N_VAL and beyond["thermal"]["rows_applied"] == 0
    assert at_end["thermal"]["rows_held"] == 0
    assert err.count("thermal expansion is not extrapolated") == 1 and "up to 5 K away" in err
    assert "thermal expansion is not extrapolated" not in end_err


def test_hidden_pause_step_is_named_not_drift_and_removed(industrial_arm_urdf, tmp_path, capsys):
    """(b) an 8 h pause stepping the registration by 76 µm in y: the step is named (a drift fits the two
    clusters of time as well, so it is not), measured within 3 std, held-out at the noise floor."""
    _cell(industrial_arm_urdf, tmp_path, step=STEP_M)
    doc, printed = _diagnose(industrial_arm_urdf, tmp_path)
    assert [e["type"] for e in doc["effects"]] == ["pause_step"], doc["effects"]
    effect = doc["effects"][0]
    assert effect["pause"] == 1 and np.all(np.abs(np.subtract(effect["value"], STEP_M)) <= 3 * np.array(effect["std"]))
    (pause,) = doc["pauses"]
    assert pause["after_s"] - pause["before_s"] > GAP_S and doc["pause_s"] == 1800.0
    (final,) = [line for line in printed.splitlines() if line.startswith("final model: pause_step:1 = ")]
    assert final.endswith(" mm at most)") and "turns it" not in final, final  # eq T2: a translation
    evaluated, _ = _evaluate(tmp_path, tmp_path / "val.csv", capsys, "e", "--html", str(tmp_path / "e.html"))
    assert evaluated["position"]["rms_mm"] < BOUND_MM
    assert evaluated["pause_steps"]["rows_in_span"] == N_VAL and evaluated["pause_steps"]["rows_outside"] == 0
    with open(tmp_path / "val.csv", newline="", encoding="utf-8") as f:  # the held-out rows after the pause
        after = sum(float(row["time"]) >= pause["after_s"] for row in csv.DictReader(f))
    assert 0 < after < N_VAL and evaluated["pause_steps"]["rows_stepped"] == after
    assert (f"pause steps applied (eq T2): {after} row(s) after a pause of their session (pause 1 of session "
            f"'{pause['session']}') take its registration step") in html.unescape((tmp_path / "e.html").read_text())


def test_clean_data_adopt_neither_and_missing_columns_are_named(industrial_arm_urdf, tmp_path):
    """(c) with a warm-up and an 8 h pause but no effect, neither is adopted; (d) without the temperature
    and time columns the lines say that they cannot be tested and which flag to give."""
    _cell(industrial_arm_urdf, tmp_path)
    doc, _ = _diagnose(industrial_arm_urdf, tmp_path)
    assert not any(e["type"] in ("thermal", "pause_step") for e in doc["effects"]), doc["effects"]
    said = " ".join(doc["diagnosis"]["notes"])  # both offered: neither is said to be untestable
    assert "thermal" not in said and "pause_step" not in said, said  # as (d)'s notes say them
    with pytest.raises(AssertionError, match="no temperature column 'temperature_k'; did you mean 'temperature_c'"):
        _diagnose(industrial_arm_urdf, tmp_path, "--temperature-column", "temperature_k")
    for name in ("cal.csv", "val.csv"):  # the same rows without time and temperature
        lines = (tmp_path / name).read_text(encoding="utf-8").splitlines()
        keep = [i for i, c in enumerate(lines[0].split(",")) if c not in ("time", "temperature_c")]
        (tmp_path / name).write_text("\n".join(",".join(line.split(",")[i] for i in keep) for line in lines) + "\n",
                                     encoding="utf-8")
    doc, printed = _diagnose(industrial_arm_urdf, tmp_path)
    said = " ".join(doc["diagnosis"]["notes"])
    assert "thermal cannot be tested: " in said and "pause_step cannot be tested: " in said, said
    assert "thermal cannot be tested: " in printed and "--temperature-column NAME" in printed
    assert "pause_step cannot be tested: " in printed and "--time-column NAME" in printed


def test_expansion_and_steps_in_the_sensor_residual_match_finite_differences(kuka_chain):
    """The Jacobian with thermal, two pause steps and the other sensor effects, in one and in two sessions,
    with and without fixed conditions, against central differences (step 1e-6; rounding ~1e-9 for
    residuals of O(10), a wrong term O(1e-3) or more); orientations near the model's (|log E| ≤ 1 rad,
    away from the π where log3's derivative is ill-conditioned); effect_columns give the columns a
    candidate would bring."""
    rng = np.random.default_rng(8)
    params = PlacementErrors(kuka_chain)
    k = 9
    q = rng.uniform(-1.5, 1.5, (k, 7))
    pauses = np.zeros((k, 2))
    pauses[4:, 0], pauses[7:, 1] = 1.0, 1.0
    inputs = EffectInputs(q=q, gravity=gravity_torques(kuka_chain, q), time=np.linspace(-600, 600, k),
                          order=np.arange(k), joint_names=tuple(kuka_chain.joint_names),
                          temperature=rng.uniform(-3, 3, k), pauses=pauses)
    effects = [Effect("compliance", "lwr_joint_2"), Effect("drift"), Effect("sensor_scale"), Effect("thermal"),
               Effect("pause_step", pause=1), Effect("pause_step", pause=2)]
    free = rng.permutation(params.size)[:12]
    for sessions in (None, np.array([0, 0, 1, 1, 0, 1, 0, 1, 1])):
        for fixed in (None, RowConditions(rng.normal(0, 1e-3, k), rng.normal(0, 1e-2, (k, 3)))):
            base = rng.normal(0, 1e-2, params.size)
            registrations = tuple(Registration(pin.exp3(rng.normal(size=3)), rng.normal(size=3))
                                  for _ in range(1 if sessions is None else 2))
            start = TargetEstimate(registrations[0], rng.normal(0, 0.1, (2, 3)), pin.exp3(rng.normal(size=3)),
                                   registrations)

            points = rng.normal(size=(k, 2, 3))

            def objective(chosen, rotations):
                return SensorResidual(KinematicsCache(params, free, base, q), points, rotations, start,
                                      RowWeights(rotation=2.0), effects=ModelledEffects(chosen, inputs, fixed),
                                      sessions=sessions)

            probe = objective(effects, np.stack([np.eye(3)] * k))
            x = probe.start_vector() + rng.normal(0, 0.01, probe.n_free)
            x[probe.blocks["effects"]] = rng.normal(0, 1e-2, probe.blocks["effects"].stop - probe.blocks["effects"].start)
            poses, _, target, _ = probe.state(x)
            near = (probe.row_frames(target)[0] @ poses.tool_rotations @ target.rotation
                    @ np.stack([pin.exp3(rng.normal(0, 0.3, 3)) for _ in q]))
            full = objective(effects, near)
            assert_close(full.jacobian(x), numeric_jacobian(full.residual, x), 1e-6, f"sessions {sessions}")
            without = objective(effects[:4] + effects[5:], near)  # pause 1 as a candidate
            y = np.delete(x, np.arange(3) + full.effect_slices[4].start)
            columns = without.effect_columns(y, [effects[4]])[0]
            added = objective(effects[:4] + effects[5:] + [effects[4]], near)
            brought = added.jacobian(np.concatenate([y, np.zeros(3)]))[:, added.effect_slices[-1]]
            assert_close(columns, brought, 1e-12, "pause step candidate")


def test_pauses_segments_and_the_temperature_column():
    """Pauses per session in time order; a row takes the steps of the pauses before it (in a gap: the
    segment before); the temperature column by name (did you mean) or default, non-finite refused."""
    time = np.array([0.0, 10.0, 5000.0, 5010.0, 0.0, 20.0, 9000.0, 9010.0])
    sessions = ["A"] * 4 + ["B"] * 4
    pauses = find_pauses(time, sessions, 1800.0)
    assert pauses == (Pause(1, "A", 10.0, 5000.0), Pause(2, "B", 20.0, 9000.0))
    assert find_pauses(time, sessions, 9000.0) == ()
    rows = pause_rows([5.0, 2000.0, 5000.0, 99999.0, 99999.0], ["A", "A", "A", "A", "B"], pauses)
    assert rows.tolist() == [[0, 0], [0, 0], [1, 0], [1, 0], [0, 1]]
    from pincal.measurements.data import MeasurementSet

    data = MeasurementSet(joint_names=("j",), q=np.zeros((2, 1)), points=np.zeros((2, 1, 3)), rotations=None,
                          roles=np.array(["calibration"] * 2, dtype=object), lines=np.array([2, 3]),
                          extra={"temperature_c": np.array([20.0, np.nan]), "temp": np.array([1.0, 2.0])},
                          source="d.csv")
    with pytest.raises(PincalError, match="d.csv, line 3, column 'temperature_c': empty or non-finite temperature"):
        temperature_column(data)
    with pytest.raises(PincalError, match="no temperature column 'tmp'; did you mean 'temp'"):
        temperature_column(data, "tmp")
    assert temperature_column(data, "temp")[0] == "temp"


def test_evaluate_gives_each_row_the_steps_of_its_segment_or_the_nearest():
    """A row takes the steps of the pauses of its session before it: in a gap, the segment before; before
    the first fitted row, the first segment; after the last, the last — those two counted as outside, and
    said once; a row of a re-estimated registration (None) takes the session nearest its median time."""
    from pincal.measurements.data import MeasurementSet
    from pincal.workflows.conditions import applied_conditions

    time = np.array([-50.0, 0.0, 500.0, 4000.0, 9000.0, 20000.0])
    data = MeasurementSet(joint_names=("j",), q=np.zeros((6, 1)), points=np.zeros((6, 1, 3)), rotations=None,
                          roles=np.array(["validation"] * 6, dtype=object), lines=np.arange(2, 8),
                          extra={"time": time}, source="v.csv")
    report = {"time_column": "time", "pause_spans_s": [{"session": "A", "first": 0.0, "last": 10000.0, "mean": 5e3},
                                                       {"session": "B", "first": 9e4, "last": 1e5, "mean": 9.5e4}],
              "pauses": [Pause(1, "A", 100.0, 3000.0).as_dict(), Pause(2, "A", 3100.0, 8000.0).as_dict()]}
    steps = [(Effect("pause_step", pause=1), np.array([0.0, 1e-5, 0.0])),
             (Effect("pause_step", pause=2), np.array([0.0, 0.0, 2e-5]))]
    for names in (np.array(["A"] * 6, dtype=object), np.array([None] * 6, dtype=object)):
        applied = applied_conditions(steps, report, data, (names, np.zeros(6, dtype=np.intp)), None, "r.json")
        assert applied.conditions is not None and applied.pause_steps is not None
        assert applied.conditions.steps.tolist() == [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 1e-5, 0], [0, 1e-5, 2e-5],
                                                     [0, 1e-5, 2e-5]]
        assert (applied.pause_steps["rows_in_span"], applied.pause_steps["rows_outside"]) == (4, 2)
        assert len(applied.notes) == 1 and "2 of 6 row(s) lie outside" in applied.notes[0]
    with pytest.raises(PincalError, match="pause steps need pause_spans_s"):
        applied_conditions(steps, dict(report, pause_spans_s=None), data, (names, np.zeros(6, dtype=np.intp)), None,
                           "r.json")


def test_alpha_outside_steel_and_aluminium_beyond_its_std_is_implausible():
    """5–30 µm/m/K (steel and aluminium); a value outside by more than its standard deviation is named, with why."""
    thermal = Effect("thermal")
    assert ALPHA_RANGE == (5e-6, 30e-6) and PLAUSIBLE["thermal"]["1/K"] == np.inf
    assert implausible(thermal, np.array([12e-6]), np.array([1e-6])) is None
    assert implausible(thermal, np.array([31e-6]), np.array([2e-6])) is None  # within its std of the bound
    reason = implausible(thermal, np.array([45e-6]), np.array([3e-6]))
    assert reason is not None and "45 ± 3 µm/m/K is outside the physical range" in reason and "steel 11–13" in reason
    assert implausible(thermal, np.array([2e-6]), np.array([1e-6])) is not None
    assert implausible(Effect("drift"), np.array([1.0, 0, 0]), np.array([0.1, 0, 0])) is None


def test_report_forms_and_the_flags():
    """effect_to_dict round trips; --pause-s must be positive; a thermal effect is written in 1/K."""
    for effect, values in ((Effect("thermal"), np.array([1.2e-5])), (Effect("pause_step", pause=2),
                                                                     np.array([1e-6, -7.6e-5, 0.0]))):
        entry = effect_to_dict(effect, values, values / 10)
        back, read = effect_from_dict(entry)
        assert back == effect and np.array_equal(read, values)
    assert effect_to_dict(Effect("pause_step", pause=2), np.zeros(3))["pause"] == 2
    assert value_unit("thermal") == "1/K" and Effect("pause_step", pause=1).label == "pause_step:1"
    from pincal.workflows.settings import DiagnoseSettings

    with pytest.raises(PincalError, match="--pause-s must be a positive number of seconds"):
        DiagnoseSettings(tip_link="flange", pause_s=float("nan"))
