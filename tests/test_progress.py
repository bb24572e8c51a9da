"""Progress: the library's ``progress(done, total)`` calls (pincal.progress) and how the command line
draws them (pincal.cli.progress): a tqdm bar in a terminal, sparse lines in logs, nothing with --quiet.

Time is a fake clock that tqdm reads (tqdm.std.time), advanced by the test: no test is timed.
"""

from __future__ import annotations

import io
import time
from contextlib import contextmanager
from itertools import pairwise

import numpy as np
import pytest
import tqdm
import tqdm.std

from pincal.cli import progress as progress_module
from pincal.cli.commands import main
from pincal.cli.progress import LOG_INTERVAL_S, TERMINAL_DELAY_S, progress_bar
from pincal.diagnosis.diagnose import MAX_EFFECTS, NO_TORQUE, DiagnoseOptions, candidate_effects, diagnose
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_SMALL, DHDeviations, DHTable
from pincal.model.drift import time_column
from pincal.model.effects import gravity_torques, parse_effect
from pincal.planning.candidates import sample_candidates
from pincal.planning.design import STARTS
from pincal.planning.planner import PlanSettings, plan_measurements
from pincal.progress import Counter, Stages
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.paper import SimulationSettings, simulate_experiment

TOOL = "0.045,-0.043,0.118,0.12,-0.25,0.4"


class FakeClock:
    """What tqdm takes for time.time(); starts at the real time (tqdm's monitor thread is off)."""

    def __init__(self) -> None:
        self.now = time.time()

    def __call__(self) -> float:
        return self.now


@pytest.fixture
def clock(monkeypatch) -> FakeClock:
    fake = FakeClock()
    monkeypatch.setattr(tqdm.std, "time", fake)
    monkeypatch.setattr(tqdm.tqdm, "monitor_interval", 0)
    return fake


def _draw(clock: FakeClock, seconds_per_update: float, n: int = 200, **options) -> str:
    stream = io.StringIO()
    with progress_bar("study tasks", stream=stream, **options) as report:
        for done in range(1, n + 1):
            clock.now += seconds_per_update
            report(done, n)
    return stream.getvalue()


def _counts(line: str) -> tuple[int, int]:
    """(done, total) of one drawn status ``label: ...| done/total [...]``."""
    done, total = line.split("|")[-1].split()[0].split("/")
    return int(done), int(total)


def test_terminal_bar_shows_counts_rate_and_time_left(clock):
    text = _draw(clock, 0.1, interactive=True)  # 20 s of work
    assert "\r" in text  # redrawn in place
    final = text.split("\r")[-1]
    assert "study tasks" in final and "200/200" in final and "task/s" in final and "<" in final  # elapsed<left


def test_quick_work_draws_nothing(clock):
    """Work shorter than TERMINAL_DELAY_S (terminal) or LOG_INTERVAL_S (log) leaves no trace, so a quick
    command's stderr (or its one-line error) is what it was without progress."""
    assert _draw(clock, 0.9 * TERMINAL_DELAY_S / 200, interactive=True) == ""
    assert _draw(clock, 0.9 * LOG_INTERVAL_S / 200, interactive=False) == ""


def test_log_lines_are_whole_lines_at_most_one_per_interval(clock):
    """Not a terminal, 200 updates one second apart: a line of counts at most every LOG_INTERVAL_S
    (10 s), the first after 10 s, and the last at the end — 200 s / 10 s + 1 lines at most."""
    text = _draw(clock, 1.0, interactive=False)
    assert "\r" not in text
    lines = text.splitlines()
    assert 200 / LOG_INTERVAL_S - 1 <= len(lines) <= 200 / LOG_INTERVAL_S + 1, lines
    counts = [_counts(line) for line in lines]
    assert all(line.startswith("study tasks:") for line in lines)
    assert counts[0][0] >= LOG_INTERVAL_S - 1 and counts[-1] == (200, 200)
    assert all(b[0] - a[0] >= LOG_INTERVAL_S for a, b in pairwise(counts[:-1])), counts  # 10 s apart
    assert [c for c, _ in counts] == sorted(c for c, _ in counts)


def test_log_lines_follow_the_interval(clock, monkeypatch):
    """With the interval at zero every update is a line: the interval is what thins them."""
    monkeypatch.setattr(progress_module, "LOG_INTERVAL_S", 0.0)
    assert len(_draw(clock, 0.0, interactive=False).splitlines()) > 200


def test_quiet_draws_nothing(clock):
    assert _draw(clock, 1.0, quiet=True) == "" and _draw(clock, 1.0, quiet=True, interactive=True) == ""


@pytest.mark.parametrize("total", [1, 7])
def test_total_is_reached(clock, total):
    stream = io.StringIO()
    with progress_bar("x", stream=stream, interactive=False) as report:
        for done in range(1, total + 1):
            clock.now += 2 * LOG_INTERVAL_S
            report(done, total)
    assert f"{total}/{total}" in stream.getvalue().splitlines()[-1]


def test_resumed_work_starts_the_bar(clock):
    """Work done before the first report (study tasks resumed) is where the bar starts."""
    stream = io.StringIO()
    with progress_bar("study tasks", stream=stream, interactive=False) as report:
        clock.now += 2 * LOG_INTERVAL_S
        report(150, 200)
        report(200, 200)
    assert _counts(stream.getvalue().splitlines()[-1]) == (200, 200)


# --- the library's calls -------------------------------------------------------------------------


class Calls(list):
    """A progress callback recording its calls."""

    def __call__(self, done: int, total: int) -> None:
        self.append((done, total))


def assert_promised(calls: Calls) -> None:
    """pincal.progress: done never decreases, never exceeds total, and the last call has done == total."""
    assert calls, "no progress reported"
    assert all(0 <= done <= total for done, total in calls), calls
    assert all(b[0] >= a[0] and b[1] >= a[1] for a, b in pairwise(calls)), calls
    assert calls[-1][0] == calls[-1][1], calls
    assert len(set(calls)) == len(calls), "a call repeats the one before"


def test_counter_and_stages_keep_the_promise():
    calls = Calls()
    counter = Counter(calls)
    counter.expect(3)
    counter.tick()
    counter.tick(5)  # never beyond what was announced
    counter.expect(2)
    counter.settle()
    counter.settle()  # nothing changed: no call
    assert calls == [(1, 3), (3, 3), (5, 5)]
    calls.clear()
    stages = Stages(calls)
    first = stages.next()
    first(1, 4), first(4, 4)
    second = stages.next()
    second(2, 10), second(10, 10)
    assert calls == [(1, 4), (4, 4), (6, 14), (14, 14)]
    assert Stages(None).next() is None


#: The simulation of tests/test_diagnosis.py (Table 1 + Table 2's zero offsets, 6D rows, 0.02 mm / 0.02 deg),
#: on which diagnose finds an undeclared compliance.
OFFSETS_ONLY = DHDeviations("offsets", DHTable(alpha=np.zeros(7), epsilon=TABLE2_SMALL.delta.epsilon,
                                               r=np.zeros(7), d=np.zeros(7)))
SETTINGS = {"sigma_pos_mm": 0.02, "sigma_rot_deg": 0.02, "n_cpa": 8, "n_calibration": 80, "n_validation": 20,
            "validation_noise": False}


@pytest.fixture(scope="module")
def compliance(kuka_urdf):
    chain = KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK)
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, OFFSETS_ONLY, SimulationSettings(seed=3, **SETTINGS),
                                     effects=[parse_effect("compliance:lwr_joint_2:2e-4")])
    return KinematicChain.from_urdf(kuka_urdf, KUKA_FLANGE_LINK, tool=experiment.tool), experiment


def test_calibration_reports_each_fit_once(compliance):
    """One call per fit: the registration, each subset the selection refits (pincal.fit.selection), the fit."""
    chain, experiment = compliance
    calls = Calls()
    result = calibrate_chain(chain, experiment.calibration, "full", ChainFitOptions(tool_known=True), progress=calls)
    assert_promised(calls)
    fits = len(result.selection.refitted) + 2
    assert calls[-1] == (fits, fits)
    assert [done for done, _ in calls] == list(range(1, fits + 1))  # no jump: every fit counted


def test_diagnose_reports_every_step(compliance):
    chain, experiment = compliance
    calibration = calibrate_chain(chain, experiment.calibration, "offsets", ChainFitOptions(tool_known=True))
    calls = Calls()
    result = diagnose(chain, calibration, experiment.calibration,
                      options=DiagnoseOptions(time=time_column(experiment.calibration)), progress=calls)
    assert_promised(calls)
    assert len(result.steps) >= 1
    # each step announces one unit per candidate offered and one for the adoption (the step that adopts
    # nothing too, unless MAX_EFFECTS were adopted); then one for the final fit
    # less the candidates no gravity torque can drive (a vertical J1: pincal.diagnosis.diagnose.NO_TORQUE)
    with chain.placed(calibration.chain_placements):
        gravity = np.abs(gravity_torques(chain, experiment.calibration.q)).max(axis=0)
    weightless = {name for name, g in zip(chain.joint_names, gravity) if g < NO_TORQUE}
    offered = len([e for e in candidate_effects(chain, has_time=True)
                   if not (e.joint in weightless and (e.type == "compliance" or e.source == "gravity"))])
    assert weightless == {"lwr_joint_1"}
    steps = len(result.steps) + (len(result.steps) < MAX_EFFECTS)
    assert calls[-1][1] == sum(offered - step + 1 for step in range(steps)) + 1
    assert len({total for _, total in calls}) == steps + 1  # the total grew step by step


def test_plan_reports_the_search_the_draws_and_the_predictions():
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    settings = PlanSettings(count=12, level="full", seed=1)
    calls = Calls()
    plan = plan_measurements(chain, sample_candidates(chain, 300, 1), settings, progress=calls)
    assert_promised(calls)
    total = calls[-1][1]
    # greedy, each exchange start's passes (STARTS starts, a pass at least each), the priority order and
    # the additions, 12 units each, and the 20 random draws
    assert (total - settings.random_draws) % settings.count == 0
    assert total >= (3 + STARTS) * settings.count + settings.random_draws
    assert [done for done, _ in calls] == list(range(1, total + 1))  # every unit counted as it is done
    assert len(plan.q) == settings.count


# --- the commands ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sim")
    assert main(["simulate", "--out", str(folder), "--deviations", "small", "--sigma-pos", "0.02",
                 "--sigma-rot", "0.02", "--seed", "2", "--effect", "encoder_scale:lwr_joint_4:0.003"]) == 0
    return folder


def _commands(sim, out):
    kuka = str(kuka_lwr4plus_urdf())
    data = str(sim / "calibration.csv")
    return {
        "calibrate": ["calibrate", kuka, data, "--tip-link", KUKA_FLANGE_LINK, "--level", "full",
                      "--out", str(out / "c.urdf"), "--report", str(out / "c.json")],
        "diagnose": ["diagnose", kuka, data, "--tip-link", KUKA_FLANGE_LINK, "--level", "offsets", "--tool", TOOL,
                     "--plots", str(out / "plots"), "--out", str(out / "d.urdf"), "--report", str(out / "d.json")],
        "plan": ["plan", kuka, "--tip-link", KUKA_FLANGE_LINK, "--count", "12", "--sample", "300",
                 "--out", str(out / "p.csv"), "--report", str(out / "p.json")],
        "study tasks": ["study", "--reps", "1", "--levels", "2", "--restarts", "0", "--limit-pose-sets", "0",
                        "--workers", "1", "--out", str(out / "study")],
    }


@pytest.mark.parametrize("label", ["calibrate", "diagnose", "plan", "study tasks"])
def test_commands_report_progress_on_stderr_and_quiet_silences_it(simulated, tmp_path, capsys, monkeypatch, label):
    """Each long command draws its counts on stderr, never stdout (every update a line here: the log
    interval is set to zero, since these runs are quicker than one interval); --quiet draws nothing."""
    monkeypatch.setattr(progress_module, "LOG_INTERVAL_S", 0.0)
    monkeypatch.setattr("pincal.study.figures.start_figures", lambda *args: lambda: [])  # seconds of drawing
    monkeypatch.setattr("pincal.diagnosis.plots.plot_diagnosis", lambda *args: [])  # uncounted, as are those
    argv = _commands(simulated, tmp_path)[label]
    assert main(argv) == 0
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.startswith(label + ":") and "|" in line]  # counted
    assert lines and not any(line.startswith(label + ":") for line in captured.out.splitlines()), captured.err
    counts = [_counts(line) for line in lines]
    assert counts[-1][0] == counts[-1][1] > 0 and [c for c, _ in counts] == sorted(c for c, _ in counts)
    _stopping_at_the_first_report(monkeypatch)
    # --quiet: the same command, stopped at its first report (every line above drew one by then)
    with pytest.raises(_FirstReport):
        main(argv + ["--quiet"])
    assert label + ":" not in capsys.readouterr().err


class _FirstReport(BaseException):
    """Raised by :func:`_stopping_at_the_first_report`'s callback (no ``except Exception`` of a command holds it)."""


def _stopping_at_the_first_report(monkeypatch):
    """Make every command's progress bar raise :class:`_FirstReport` once it has drawn its first report."""
    real = progress_module.progress_bar

    @contextmanager
    def stopping(*args, **kwargs):
        with real(*args, **kwargs) as report:
            def first(done, total):
                report(done, total)
                raise _FirstReport
            yield first

    monkeypatch.setattr(progress_module, "progress_bar", stopping)


def test_a_quick_command_in_a_log_prints_no_progress(simulated, tmp_path, capsys, clock):
    """In a log the first line comes after the interval (10 s): a calibration within it adds nothing to
    stderr. The clock is held (no machine is too slow for this test); the log-line tests above
    advance it."""
    assert main(_commands(simulated, tmp_path)["calibrate"]) == 0
    assert "calibrate:" not in capsys.readouterr().err

