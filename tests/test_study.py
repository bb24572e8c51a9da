"""The simulation study: a tiny run writes every file, and executors agree seed for seed."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from distributed import Client, LocalCluster

from pincal.cli.commands import main
from pincal.model.chain import KinematicChain
from pincal.model.dh import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.robots import KUKA_FLANGE_LINK
from pincal.simulation.paper import SimulationSettings, simulate_experiment
from pincal.study.figures import FIGURES
from pincal.study.run import (
    FIGURE2_REPEAT,
    RESTART_SPREAD_DEG,
    RESTART_SPREAD_MM,
    STUDY_COLUMNS,
    SUMMARY_COLUMNS,
    ProgressBar,
    StudyConfig,
    noise_free_test_set,
    parameter_deviations,
    random_start,
    run_study,
    study_tasks,
    task_seed,
    write_study,
)

TINY = StudyConfig(levels=2, repeats=2, restarts=3, restart_cases=1, limit_pose_sets=1)
#: Executors are compared without the noise limit (its tasks take ~1 s each).
SMALL = StudyConfig(deviations=("large",), levels=2, repeats=2, restarts=2, restart_cases=1, limit_pose_sets=0)
ROWS_PER_TRIAL = 1 + 2 * 4  # Method 1: Registration 1 only; four estimators with both registrations
FINDINGS = {
    "method2_orientation_below_method1", "position_errors_comparable", "registrations_method2",
    "registrations_method3", "method3_worse_than_method2", "method3_sensitive_to_w",
    "largest_parameter_deviations", "restarts_same_solution", "ml_vs_method2", "method2_four_sigma",
    "deviation_size_irrelevant",
}


def _comparable(result):
    """Everything but the fit times, which differ from run to run."""
    rows = [{k: v for k, v in row.items() if k != "fit_ms"} for row in result.rows]
    return rows, result.limits, result.restarts, result.figure2


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    result = run_study(TINY, workers=2)
    out = tmp_path_factory.mktemp("study")
    return result, out, write_study(result, out)


def _read(path):
    with path.open(newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def test_tiny_study_writes_tables_with_expected_rows(tiny):
    result, out, paths = tiny
    rows = _read(out / "study.csv")
    assert tuple(rows[0]) == STUDY_COLUMNS
    assert len(rows) == 2 * TINY.levels * TINY.repeats * ROWS_PER_TRIAL
    assert {r["method"] for r in rows} == {"1", "2", "3", "ml"}
    assert {r["registration"] for r in rows if r["method"] == "1"} == {"1"}
    assert {r["weight"] for r in rows if r["method"] == "3"} == {"1.0", "100.0"}
    summary = _read(out / "summary.csv")
    assert tuple(summary[0]) == SUMMARY_COLUMNS
    assert len(summary) == 2 * TINY.levels * ROWS_PER_TRIAL
    assert {int(s["n_repeats"]) for s in summary} == {TINY.repeats}
    noisy = [s for s in summary if float(s["sigma_pos_mm"]) > 0]
    for s in noisy:
        for column in ("pos_mean_mm", "rot_mean_deg", "pos_truth_mean_mm", "rot_truth_mean_deg"):
            assert float(s[column]) > 0, column
        # the limit applies to positions through Registration 1, orientations through Registration 2
        assert (float(s["limit_pos_mm"]) > 0) == (s["registration"] == "1"), s
        assert (float(s["limit_rot_deg"]) > 0) == (s["registration"] == "2" or s["method"] == "1"), s
        ratio = float(s["pos_truth_over_limit"] if s["registration"] == "1" else s["rot_truth_over_limit"])
        assert 0.2 < ratio < 5.0, s  # Monte Carlo and the linearised prediction agree roughly
    assert len(result.limits) == 2 * len(TINY.estimators) * TINY.limit_pose_sets
    assert len(_read(out / "restarts.csv")) == 3 * TINY.restarts * TINY.restart_cases


def test_noise_free_level_is_exact(tiny):
    result, _, _ = tiny
    exact = [r for r in result.rows if r["sigma_pos_mm"] == 0]
    assert exact
    for row in exact:
        assert row["pos_mean_mm"] < 1e-6 and row["rot_mean_deg"] < 1e-6, row
        assert row["pos_mean_mm"] == pytest.approx(row["pos_truth_mean_mm"], abs=1e-12)


def test_tiny_study_writes_findings_json_and_figures(tiny):
    result, out, paths = tiny
    assert {f["finding"] for f in result.findings} == FINDINGS
    text = (out / "findings.md").read_text(encoding="utf-8")
    for name in FINDINGS:
        assert f"`{name}`" in text
    data = json.loads((out / "study.json").read_text(encoding="utf-8"), parse_constant=pytest.fail)
    assert len(data["rows"]) == len(result.rows)
    assert {f["finding"] for f in data["findings"]} == FINDINGS
    assert len(data["noise_limit_table"]) == 2 * TINY.levels * len(TINY.estimators)
    assert [p.name for p in paths["figures"]] == list(FIGURES)
    for path in paths["figures"]:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000


def test_in_process_local_processes_and_dask_give_identical_results():
    in_process = run_study(SMALL, workers=1)
    assert in_process.executor == "in-process"
    reference = _comparable(in_process)
    assert len(reference[0]) == SMALL.levels * SMALL.repeats * ROWS_PER_TRIAL and reference[2]
    assert _comparable(run_study(SMALL, workers=2)) == reference
    with LocalCluster(n_workers=1, processes=False, dashboard_address=None) as cluster, Client(cluster) as client:
        dask = run_study(SMALL, scheduler=client)
    assert "Dask" in dask.executor
    assert _comparable(dask) == reference


def test_seeds_are_pure_functions_of_the_task_key(tiny):
    assert task_seed("large", 3, 7) == task_seed("large", 3, 7) == 3769834354
    seeds = {task_seed(d, level, rep) for d in ("small", "large") for level in range(16) for rep in range(25)}
    assert len(seeds) == 2 * 16 * 25
    # the seed depends on the key only, not on how many levels or repeats the study has
    bigger = {t.key: t.seed for t in study_tasks(StudyConfig(levels=2, repeats=5, restarts=0))}
    for task in study_tasks(TINY):
        if task.key[0] == 0:
            assert bigger[task.key] == task.seed == task_seed(task.deviations, task.level, task.repeat)
    for row in tiny[0].rows:
        assert row["seed"] == task_seed(row["deviations"], row["level"], row["repeat"])
    assert tiny[0].figure2[0]["repeat"] == FIGURE2_REPEAT


def test_random_starts_and_parameter_deviations(kuka_chain):
    start = random_start(np.random.default_rng(1))
    assert np.array_equal(start.alpha, KUKA_LWR4_DH.alpha)
    assert np.degrees(np.abs(start.epsilon - KUKA_LWR4_DH.epsilon)).max() <= RESTART_SPREAD_DEG
    assert 1000 * np.abs(start.d - KUKA_LWR4_DH.d).max() <= RESTART_SPREAD_MM
    truth = TABLE2_LARGE.apply(KUKA_LWR4_DH)
    assert parameter_deviations(truth, truth) == {
        "max_dalpha_deg": 0.0, "max_deps_deg": 0.0, "max_dr_mm": 0.0, "max_dd_mm": 0.0}
    assert parameter_deviations(KUKA_LWR4_DH, truth)["max_dalpha_deg"] == pytest.approx(4.2)


def test_noise_free_test_set_matches_the_noiseless_simulation(kuka_urdf):
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    settings = SimulationSettings(sigma_pos_mm=0.1, sigma_rot_deg=0.1, seed=4, n_calibration=10, n_validation=5)
    noisy = simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE, settings)
    clean = simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE,
                                SimulationSettings(**{**settings.__dict__, "validation_noise": False}))
    placements = chain.placements()
    truth = noise_free_test_set(chain, noisy)
    assert all(np.array_equal(a, b) for a, b in zip(chain.placements(), placements))
    np.testing.assert_allclose(truth.points, clean.validation.points, atol=1e-12)
    np.testing.assert_allclose(truth.rotations, clean.validation.rotations, atol=1e-12)


def test_cli_study(tmp_path, capsys):
    out = tmp_path / "cli"
    code = main(["study", "--out", str(out), "--levels", "2", "--reps", "1", "--restarts", "2",
                 "--limit-pose-sets", "0", "--workers", "1"])
    printed = capsys.readouterr().out
    assert code == 0
    assert "restarts_same_solution" in printed and f"wrote {out / 'findings.md'}" in printed
    assert len(_read(out / "study.csv")) == 2 * 2 * 1 * ROWS_PER_TRIAL
    assert (out / "fig5_methods.png").is_file()


def test_cli_study_rejects_bad_counts(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["study", "--reps", "0"])
    assert exc.value.code == 2
    assert "must be >= 1" in capsys.readouterr().err


def test_progress_bar_draws_one_line():
    stream = io.StringIO()
    bar = ProgressBar(stream, width=10)
    bar(1, 4)
    bar(4, 4)
    text = stream.getvalue()
    assert text.startswith("\rstudy     1/4 [##........]") and "4/4 [##########]" in text
    assert text.endswith("\n") and text.count("\n") == 1
