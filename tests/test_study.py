"""The simulation study: a tiny run writes every file, executors agree seed for seed, and a
small but decisive run reproduces the findings that its size can decide."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from distributed import Client, LocalCluster

from pincal.cli.commands import main
from pincal.fit.metrics import pose_errors
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import DEVIATION_SETS, KUKA_LWR4_DH, TABLE2_LARGE
from pincal.robots import KUKA_FLANGE_LINK
from pincal.simulation.paper import SimulationSettings, simulate_experiment
from pincal.study.estimators import ML_ESTIMATOR, ml_without_cpa_orientations
from pincal.study.figures import FIGURES
from pincal.study.run import (
    FIGURE2_REPEAT,
    RESTART_SPREAD_DEG,
    RESTART_SPREAD_MM,
    STUDY_COLUMNS,
    SUMMARY_COLUMNS,
    StudyConfig,
    noise_free_test_set,
    parameter_deviations,
    random_start,
    run_study,
    study_tasks,
    task_seed,
    write_study,
)
from pincal.study.tasks import ABLATION_REPEATS, ABLATION_SUFFIX

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
    # in this process: the executors give the same rows (checked below by
    # test_in_process_local_processes_and_dask_give_identical_results); under pytest-xdist a pool would spawn
    # fresh interpreters, each importing pincal again
    result = run_study(TINY, workers=1)
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
        # The ratio to the limit is computed; with 2 repeats its Monte Carlo relative standard error is
        # up to 0.44 / sqrt(2) = 0.31 (per-draw CV of the default study; 0.53 by the bound in DECISIVE's
        # comment), too large to test it here: test_monte_carlo_errors_agree_with_the_noise_limit does,
        # on 40 repeats.
        ratio = float(s["pos_truth_over_limit"] if s["registration"] == "1" else s["rot_truth_over_limit"])
        assert ratio > 0, s
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


#: A study small enough for seconds, large enough to decide the findings that a study of
#: this size can decide: one deviation set, one noise level (sigma 0.15, the largest of the
#: paper's) with N = 40 repeats, every estimator, the limit on 2 pose sets. The eq 25 means
#: of N draws have a relative standard error CV/sqrt(N): the mean error over the J test poses
#: is a seminorm of Gaussian noise, so its per-draw CV is at most that of a half-normal,
#: sqrt(pi/2 - 1) = 0.755 (Latała & Oleszkiewicz 1999), and is 0.16-0.44 for the truth-
#: referenced errors and ~0.06 for the noisy ones in the default study; with N = 40 that is
#: a relative standard error of 0.01-0.07 (at most 0.12). Each check below uses the standard
#: error the run itself shows (its sd over the repeats / sqrt(N)) and allows K_SE of them,
#: which also covers the +-11 % error of an sd estimated from 40 draws.
DECISIVE = StudyConfig(deviations=("large",), levels=2, repeats=40, restarts=3, restart_cases=3, limit_pose_sets=2)
K_SE = 4.0
#: E||u|| for u ~ N(0, I_3): the mean norm of a test measurement's own noise, per unit sigma.
CHI3_MEAN = 2.0 * np.sqrt(2.0 / np.pi)


@pytest.fixture(scope="module")
def decisive():
    result = run_study(DECISIVE, workers=1)  # in this process, as ``tiny``
    return result, {f["finding"]: f for f in result.findings}


def _noisy(result, method, registration, weight=None):
    """The summary row of (method, weight, registration) at the study's one non-zero level."""
    [row] = [s for s in result.summary if s["sigma_pos_mm"] > 0 and s["method"] == method
             and s["weight"] == weight and s["registration"] == registration]
    return row


def _se(row, column):
    """Relative standard error of the eq 25 mean ``column`` of a summary row: (sd / mean) / sqrt(N)."""
    return row[column + "_sd"] / row[column] / np.sqrt(row["n_repeats"])


def _paired_se(result, a, b, column):
    """Relative standard error of the ratio of two eq 25 means on the same draws, a = (method,
    weight, registration) over b: by the delta method var(x/x̄ - y/ȳ) / N over the paired draws
    (the estimators see the same data, so their errors are correlated)."""
    def values(method, weight, registration):
        return np.array([r[column] for r in sorted(result.rows, key=lambda r: r["repeat"]) if r["sigma_pos_mm"] > 0
                         and (r["method"], r["weight"], r["registration"]) == (method, weight, registration)])
    x, y = values(*a), values(*b)
    return float(np.std(x / x.mean() - y / y.mean(), ddof=1) / np.sqrt(len(x)))


def _limit_spread(row, limit):
    """Relative spread of the noise limit over the pose sets it was computed on (0 for one set)."""
    return row[limit + "_sd"] / row[limit]


def test_monte_carlo_errors_agree_with_the_noise_limit(decisive):
    """Every estimator's truth-referenced Monte Carlo mean against its linearised noise limit.

    The MC mean has the relative standard error of the run (0.03-0.06 here, see DECISIVE);
    the limit is computed on 2 of the 40 pose sets, and its relative spread over them
    (0.000-0.11) adds in quadrature. |MC / limit - 1| must stay within K_SE of these: a
    band of +-0.12 (ML) to +-0.25 (Methods 1-3), +-0.5 for Method 1's orientation, whose
    limit differs most between pose sets; 0.2-5 was accepted before.
    """
    result, _ = decisive
    checked = 0
    for row in result.summary:
        if row["sigma_pos_mm"] == 0:
            continue
        for measured, limit, ratio in (("pos_truth_mean_mm", "limit_pos_mm", "pos_truth_over_limit"),
                                       ("rot_truth_mean_deg", "limit_rot_deg", "rot_truth_over_limit")):
            if np.isnan(row[limit]):
                continue
            tolerance = K_SE * np.hypot(_se(row, measured), _limit_spread(row, limit))
            assert abs(row[ratio] - 1) < tolerance, (row["method"], row["weight"], row["registration"], ratio,
                                                     row[ratio], tolerance)
            checked += 1
    assert checked == 2 * len(DECISIVE.estimators)  # position and orientation of each estimator


def test_findings_the_paper_states_hold(decisive):
    """Findings this study size decides and the paper (or the README) states."""
    result, found = decisive
    m1, m2_orientation = _noisy(result, "1", 1), _noisy(result, "2", 2)  # Method 1: Registration 1 only
    # Fig 5b and the abstract ("much smaller robot orientation errors"): Method 2 (Registration 2) below
    # Method 1 on the paper's metric. Per draw the ratio is 0.95 +- 0.08 (default study), so 40 repeats
    # put 1 four standard errors away. Against the truth the noise limits say the same: 0.08 vs 0.15 deg.
    finding = found["method2_orientation_below_method1"]
    assert finding["holds"]
    ratio = finding["values"]["ratio"]["large"]["mean"]
    assert ratio == pytest.approx(m2_orientation["rot_mean_deg"] / m1["rot_mean_deg"], rel=1e-12)
    assert ratio < 1 - K_SE * _paired_se(result, ("2", None, 2), ("1", None, 1), "rot_mean_deg")
    assert m2_orientation["limit_rot_deg"] < m1["limit_rot_deg"]
    assert finding["values"]["ratio_truth"]["large"]["mean"] < 1
    # Fig 5a and the abstract ("position errors are comparable"): the ratio within the finding's
    # 0.67-1.5 (1.11 +- 0.19 per draw: 40 repeats put both ends more than ten standard errors away).
    assert found["position_errors_comparable"]["holds"]
    # Section 8: every restart of Methods 1-3 (3 starts x 3 cases, two of them noisy) reaches the
    # solution from Table 1: the fits are not trapped in local minima.
    restarts = found["restarts_same_solution"]
    assert restarts["holds"] and restarts["values"]["total"] == 3 * 3 * DECISIVE.restarts
    # Fig 3a,c / 4a: Registration 1 gives the smaller position errors (0.87 +- 0.10 per draw).
    # The orientation half (Registration 2 better) is not decided: on the paper's metric the two
    # registrations differ by 0.5 % +- 1 % per draw, the test measurements' own noise dominating.
    for name in ("registrations_method2", "registrations_method3"):
        assert found[name]["values"]["pos_reg1_over_reg2"]["large"]["max"] < 1, name
    # Fig 6: w changes Method 3's position errors more than its orientation errors. Whether the
    # position change exceeds the finding's 10 % cannot be decided here (13 % +- 2.5 % at this size;
    # 11.6 % over the 800 trials of the default study).
    sensitive = found["method3_sensitive_to_w"]["values"]
    assert sensitive["rot_change"] < sensitive["pos_change"]


def test_findings_the_noise_limit_predicts_to_fail(decisive):
    """Findings of the paper that cannot hold here, for a reason the noise limit states."""
    result, found = decisive
    sigma = DECISIVE.max_sigma
    # Section 9, v ~ 4 sigma_p and rho ~ 4 sigma_a for Method 2. On the paper's metric each test
    # pose's error is the estimator's error a (mean norm L, the noise limit) minus the test
    # measurement's own noise n (mean norm 2 sqrt(2/pi) sigma), independent: by Jensen's inequality
    # E|a - n| >= max(L, E|n|), by the triangle inequality E|a - n| <= L + E|n|. Method 2's
    # orientation limit, 0.56 sigma_a, bounds rho / sigma_a by 2.15: below the finding's 3 whatever
    # the draw, so the finding cannot hold.
    slopes = found["method2_four_sigma"]["values"]["slopes"]["large"]
    for slope, column, limit, registration in ((slopes["pos_mm_per_mm"], "pos_mean_mm", "limit_pos_mm", 1),
                                               (slopes["rot_deg_per_deg"], "rot_mean_deg", "limit_rot_deg", 2)):
        row = _noisy(result, "2", registration)
        slack = K_SE * np.hypot(_se(row, column), _limit_spread(row, limit))
        low, high = max(row[limit] / sigma, CHI3_MEAN), row[limit] / sigma + CHI3_MEAN
        assert low * (1 - slack) < slope < high * (1 + slack), (column, low, slope, high)
        if column == "rot_mean_deg":
            assert high * (1 + slack) < 3.0
    assert not found["method2_four_sigma"]["holds"]
    # Fig 5c,d: Method 3 (w = 1) worse than Method 2. The noise limits say the opposite in position,
    # 0.37 vs 0.43 mm at sigma 0.15, and the Monte Carlo agrees (0.88 +- 0.12 per draw on the paper's
    # metric: 40 repeats decide it): the finding fails on its position half.
    m2, m3 = _noisy(result, "2", 1), _noisy(result, "3", 1, 1.0)
    assert m3["limit_pos_mm"] < m2["limit_pos_mm"]
    ratio = found["method3_worse_than_method2"]["values"]["pos_ratio"]["large"]["mean"]
    assert ratio == pytest.approx(m3["pos_mean_mm"] / m2["pos_mean_mm"], rel=1e-12)
    assert ratio < 1 - K_SE * _paired_se(result, ("3", 1.0, 1), ("2", None, 1), "pos_mean_mm")
    assert not found["method3_worse_than_method2"]["holds"]


def test_ml_estimator_gains_over_method2_on_both_metrics(decisive):
    """The ML estimator against Method 2 (ml_vs_method2).

    Method 2 uses part of the data the ML estimator uses, so (to first order) its covariance is
    at least the Cramer-Rao bound the ML estimator reaches; every test pose's error covariance
    then is too, and since a larger Gaussian error can only raise the mean norm, with or without
    the test measurement's own noise added (Jensen), the ML errors are the smaller on both metrics.
    Against the truth the gain is what the noise limits predict, L_ML / L_M2 - 1, within the
    Monte Carlo error of both means.
    """
    result, found = decisive
    finding = found["ml_vs_method2"]
    assert finding["holds"]
    change = finding["values"]["percent_change"]
    for column, registration in (("pos_mean_mm", 1), ("rot_mean_deg", 2)):
        se = _paired_se(result, ("ml", None, registration), ("2", None, registration), column)
        assert change[column] < -100 * K_SE * se, (column, change[column], se)
    for column, limit, registration in (("pos_truth_mean_mm", "limit_pos_mm", 1),
                                        ("rot_truth_mean_deg", "limit_rot_deg", 2)):
        ml, m2 = _noisy(result, "ml", registration), _noisy(result, "2", registration)
        assert change[column] == pytest.approx(100 * (ml[column] / m2[column] - 1), rel=1e-12)
        predicted = ml[limit] / m2[limit]
        se = _paired_se(result, ("ml", None, registration), ("2", None, registration), column)
        tolerance = K_SE * np.sqrt(se**2 + _limit_spread(ml, limit) ** 2 + _limit_spread(m2, limit) ** 2)
        assert abs((1 + change[column] / 100) / predicted - 1) < tolerance, (column, change[column], predicted)
    # The CPA-orientation ablation ran on its trials (the first ABLATION_REPEATS repeats of the one
    # non-zero level) and gives finite numbers; its share is not decided by 5 trials (the default
    # study's 20 trials: 6 +- 3 % of the orientation gain against the truth).
    ablation = finding["values"]["cpa_orientation_ablation"]
    assert ablation["trials"] == ABLATION_REPEATS and ablation["sigmas"] == [DECISIVE.max_sigma]
    for name in ("ratio", "ratio_without", "share", "share_se"):
        assert all(np.isfinite(v) for v in ablation[name].values()), name
    assert "withholding them from the ML estimator (5 trials" in finding["evidence"]


def test_findings_a_small_study_cannot_decide_are_still_computed(decisive):
    """largest_parameter_deviations compares maxima over the paper's many conditions with ours (their
    size grows with the number of trials, so a small study cannot decide it): check that ours are the
    maxima over the rows of Methods 1-3. deviation_size_irrelevant needs both deviation sets and
    ~100 repeats each to decide 10 % (per-draw scatter 0.25); the tiny study checks it is reported."""
    result, found = decisive
    ours = found["largest_parameter_deviations"]["values"]["ours"]
    for column, value in ours.items():
        assert value == max(r[column] for r in result.rows if r["method"] in ("1", "2", "3")) > 0
    assert "deviation_size_irrelevant" not in found  # one deviation set


def test_ablation_withholding_nothing_is_the_ml_estimator(kuka_urdf):
    """The ablation's fit, with no orientations withheld, reproduces calibrate_ml exactly: it differs
    from the ML estimator only by what it withholds."""
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    settings = SimulationSettings(sigma_pos_mm=0.1, sigma_rot_deg=0.1, seed=2, n_cpa=10, n_calibration=40)
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE, settings)
    chain.set_tool(experiment.tool)
    reference = ML_ESTIMATOR.calibrate(chain, experiment.calibration, 0.1)
    table, registration = ml_without_cpa_orientations(chain, experiment.calibration, 0.1, 0.1, withhold=())
    assert np.array_equal(table.to_vector(), reference.table.to_vector())
    assert np.array_equal(registration.rotation, reference.registration_position.rotation)
    assert np.array_equal(registration.translation, reference.registration_position.translation)
    withheld, _ = ml_without_cpa_orientations(chain, experiment.calibration, 0.1, 0.1)
    assert not np.array_equal(withheld.to_vector(), reference.table.to_vector())


def test_ablation_columns_are_the_ablation_on_the_trials_own_data(tiny, kuka_urdf):
    """The ablation numbers on the ML rows are the ablated estimator on that trial's own simulated data,
    written to study.json and findings.md, never to study.csv."""
    result, out, _ = tiny
    ablated = [r for r in result.rows if "rot_truth_mean_deg" + ABLATION_SUFFIX in r]
    assert {r["method"] for r in ablated} == {"ml"}
    assert len(ablated) == 2 * len(TINY.deviations) * min(ABLATION_REPEATS, TINY.repeats)  # two registrations
    row = ablated[-1]
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, DEVIATION_SETS[row["deviations"]],
                                     TINY.settings(row["sigma_pos_mm"], row["seed"]))
    chain.set_tool(experiment.tool)
    table, registration = ml_without_cpa_orientations(
        chain, experiment.calibration, row["sigma_pos_mm"], row["sigma_rot_deg"])
    chain.set_placements(table.joint_origins())
    for suffix, data in (("", experiment.validation), ("_truth", noise_free_test_set(chain, experiment))):
        errors = pose_errors(chain, data, registration, registration)
        # whatever executor ran the study (a worker process may thread BLAS otherwise): equal to rounding
        assert row[f"pos{suffix}_mean_mm{ABLATION_SUFFIX}"] == pytest.approx(errors.position.mean, rel=1e-9)
        assert row[f"rot{suffix}_mean_deg{ABLATION_SUFFIX}"] == pytest.approx(errors.rotation.mean, rel=1e-9)
    assert not any(ABLATION_SUFFIX in column for column in _read(out / "study.csv")[0])
    data = json.loads((out / "study.json").read_text(encoding="utf-8"))
    assert sum("rot_truth_mean_deg" + ABLATION_SUFFIX in r for r in data["rows"]) == len(ablated)
    text = (out / "findings.md").read_text(encoding="utf-8")
    assert "## ML estimator vs Method 2" in text and "share of the gain due to the CPA orientations" in text


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


def test_cli_study(tmp_path, capsys, monkeypatch):
    """The command's wiring: its tables, findings and every figure's file. The figures are stubs here (drawing them
    is two thirds of this run; the tiny study's fixture above and tests/test_study_processes.py draw them through
    the same FIGURES table)."""
    from pincal.study import figures

    def stub(result, path):
        path.write_bytes(b"stub")
        return path

    monkeypatch.setattr(figures, "FIGURES", {name: stub for name in figures.FIGURES})
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
