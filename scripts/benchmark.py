"""Timings of pincal: one Method-2 calibration, the default study, and scaling in K.

    python scripts/benchmark.py [--runs 50] [--workers 2] [--skip-study] [--json PATH]

(a) One Method-2 calibration (CPA + zero offsets + r, d; K = 100), in this
    process, always from the nominal table (Table 1): median over ``--runs``.
(b) The full default ``pincal study`` (the paper's protocol) on ``--workers``
    cores: wall time of the whole command.
(c) Calibration with K = 100, 1 000 and 10 000 calibration poses: wall time of
    a whole ``python -c`` process that simulates and then calibrates with
    Method 2 (import and simulation included), the calibration time measured
    inside it, and the ratios K = 10 000 / K = 1 000.
(d) ``pincal plan``: 100 of 10 000 sampled KUKA configurations at the full
    level, whole process and planning time, default and single-threaded BLAS.
(g) ``--auto``: ``pincal calibrate --level auto`` against ``--level full`` on 2 500 6D rows of
    scripts/scenarios.py's raster at constant orientation, whole processes in alternated pairs;
    goal auto <= 3x full (the folds of --level auto are scored by one Gauss-Newton step from
    the fit of all rows from 500 rows on: pincal.fit.fold_update). Writes scripts/benchmark_auto.json.
(h) ``--diagnose``: whole ``pincal diagnose`` processes, on every row and with a held-out split
    (every 5th row in ``--validation``), against one ``pincal calibrate --level full`` of the same
    2 500 6D rows, side by side in rotated triples: on (f)'s UR5 session and on scripts/scenarios.py's
    tracker 4.2 m raster at constant orientation; goal diagnose <= 10x calibrate.
    ``--select CRITERION`` for all three (default: the commands' own). Writes scripts/benchmark_diagnose.json.
(i) ``--tree``: ``pincal calibrate`` of TALOS's upper body (example-robot-data, talos_full_v2.urdf: 2 torso
    joints shared by two 7-joint arms) with a marker on each gripper (``--tip-link LINK:1 --tip-link LINK:2``),
    500 rows simulated by ``pincal.simulation.humanoid.simulate_humanoid`` (the TALOS example's simulation),
    every placement off by 0.5 mm / 0.5 mrad, 0.1 mm noise: whole processes, median of
    ``--runs``-capped 3; goal <= 5 s (the issue's 500 rows x 2 markers); beside it (``diagnose_tree``) whole
    ``pincal diagnose`` processes of the same rows, and of rows whose torso pitch sags under the upper body (an
    effect to find), each in alternated order with calibrate of its rows, and the median of their ratios to
    calibrate's; goal <= 10x. Writes scripts/benchmark_tree.json.
(j) ``--camera``: whole ``pincal detect`` and ``pincal calibrate --camera-link`` processes on 60 rendered
    1280x960 images of a ChArUco board seen by a camera on a UR5 (eye in hand), median of ``--runs``-capped 3;
    goals detect <= 15 s, calibrate <= 10 s. Writes scripts/benchmark_camera.json.
(f) Large, badly conditioned data: ``pincal calibrate --level full`` (AIC
    selection) of a UR5 (example-robot-data) on 2 500 simulated laser-tracker
    6D rows (position + orientation) taken along 6 lines and 4 planes in joint
    space with the wrist held straight (wrist_2 at zero up to encoder jitter of
    5e-8 rad), so that the Jacobian of the identifiable parameters has a
    condition number of ~1e8: whole process and the calibration inside it.

Each benchmark is printed beside a realistic lower bound: the Pinocchio
kinematics its run asked for, at Pinocchio's own cost (one
``computeJointJacobians`` + ``getFrameJacobian``, or one ``forwardKinematics``,
per configuration on the plain chain model, timed here from Python), plus, for
a whole process, starting Python and importing numpy and pinocchio. The
configurations are counted in a separate run of the same work (every process,
study workers included, counts its Pinocchio calls through a ``sitecustomize``).

    python scripts/benchmark.py --against REV [--pairs 5] [--only diagnose_tiago,calibrate_tiago,calibrate_large]

(e) ``--against REV``: builds REV (any git revision) in a temporary worktree and
    virtual environment (its own code, this environment's dependencies) and
    runs each whole-process benchmark of :data:`AGAINST` with both, alternately
    (REV then this tree, then this tree then REV, ...): each ratio REV / this
    is the median over the pairs, next to the absolute times and the load
    average, with the default BLAS threads (``--one-blas-thread`` for one).
    ``calibrate_large`` is (f) (at 6975758 it takes minutes: use ``--pairs 1``); ``study`` is (b)
    (minutes per pair at 6975758).
    Writes ``scripts/benchmark_against.json`` (or ``--json``); nothing else runs.

Prints a table and writes the numbers to ``scripts/benchmark_results.json``.
Goals: (a) median <= 10 ms, (b) <= 60 s on 2 cores, (c) ratio <= 12.
The machine's load average is recorded: other processes slow every number.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import shutil
import site
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

GOALS = {"method2_median_ms": 10.0, "study_wall_s": 60.0, "k_ratio_10000_over_1000": 12.0}

# One process: simulate K calibration poses (large deviations, sigma 0.055), calibrate with Method 2.
_SCALING_PROGRAM = """
import json, sys, time
started = time.perf_counter()
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.paper.methods import calibrate_paper
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.paper import SimulationSettings, simulate_experiment
imported = time.perf_counter()
chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
settings = SimulationSettings(sigma_pos_mm=0.055, sigma_rot_deg=0.055, n_calibration=int(sys.argv[1]), seed=1)
experiment = simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE, settings)
chain.set_tool(experiment.tool)
simulated = time.perf_counter()
calibrate_paper(chain, experiment.calibration, 2, nominal=KUKA_LWR4_DH)
done = time.perf_counter()
print(json.dumps({"import_s": imported - started, "simulate_s": simulated - imported,
                  "calibrate_s": done - simulated}))
"""


def method2_calibration(runs: int) -> dict:
    """(a): median wall time of one Method-2 calibration [ms], from the nominal every time."""
    from pincal.model.chain import KinematicChain
    from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_LARGE
    from pincal.paper.methods import calibrate_paper
    from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
    from pincal.simulation.paper import SimulationSettings, simulate_experiment

    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    settings = SimulationSettings(sigma_pos_mm=0.055, sigma_rot_deg=0.055, seed=1)
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, TABLE2_LARGE, settings)
    chain.set_tool(experiment.tool)
    for _ in range(3):  # warm-up
        calibrate_paper(chain, experiment.calibration, 2, nominal=KUKA_LWR4_DH)
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        calibrate_paper(chain, experiment.calibration, 2, nominal=KUKA_LWR4_DH)
        times.append((time.perf_counter() - started) * 1000.0)
    with counting_pinocchio() as counts:
        calibrate_paper(chain, experiment.calibration, 2, nominal=KUKA_LWR4_DH)
    return {
        "runs": runs,
        "median_ms": statistics.median(times),
        "min_ms": min(times),
        "max_ms": max(times),
        "k": settings.n_calibration,
        "k_alpha": settings.n_cpa,
        "pinocchio_calls": dict(counts),
    }


def default_study(workers: int) -> dict:
    """(b): wall time of ``pincal study`` with the paper's defaults on ``workers`` processes."""
    with tempfile.TemporaryDirectory() as tmp:
        command = [sys.executable, "-m", "pincal", "study", "--out", tmp, "--workers", str(workers)]
        started = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - started
        inner = json.loads((Path(tmp) / "study.json").read_text(encoding="utf-8"))
    with tempfile.TemporaryDirectory() as tmp:
        counts = counted_run([sys.executable, "-m", "pincal", "study", "--out", tmp, "--workers", str(workers)])
    return {
        "workers": workers,
        "command": "pincal study --workers " + str(workers),
        "wall_s": wall,
        "study_wall_s": inner["wall_s"],
        "rows": len(inner["rows"]),
        "restarts": len(inner["restarts"]),
        "pinocchio_calls": counts,
    }


def scaling(sizes: tuple[int, ...] = (100, 1_000, 10_000)) -> dict:
    """(c): whole-process wall time and in-process calibration time for each K."""
    out = {}
    for k in sizes:
        started = time.perf_counter()
        completed = subprocess.run(
            [sys.executable, "-c", _SCALING_PROGRAM, str(k)], check=True, capture_output=True, text=True
        )
        wall = time.perf_counter() - started
        counts = counted_run([sys.executable, "-c", _SCALING_PROGRAM, str(k)])
        out[str(k)] = {"process_wall_s": wall, **json.loads(completed.stdout), "pinocchio_calls": counts}
    if "1000" in out and "10000" in out:
        out["ratio_10000_over_1000"] = {
            "process_wall": out["10000"]["process_wall_s"] / out["1000"]["process_wall_s"],
            "calibrate": out["10000"]["calibrate_s"] / out["1000"]["calibrate_s"],
        }
    return out


def plan_benchmark(candidates: int = 10_000, count: int = 100) -> dict:
    """(d): ``pincal plan`` choosing ``count`` of ``candidates`` sampled KUKA configurations at the full
    level (one point measured): whole-process wall time and the planning time inside it (PLAN.json),
    with the default BLAS threads and with one BLAS thread."""
    out = {"candidates": candidates, "count": count}
    with tempfile.TemporaryDirectory() as tmp:
        urdf = str(HERE.parent / "pincal" / "robots" / "kuka_lwr4plus.urdf")
        command = [sys.executable, "-m", "pincal", "plan", urdf, "--tip-link", "lwr_flange", "--level", "full",
                   "--sample", str(candidates), "--count", str(count), "--out", f"{tmp}/PLAN.csv",
                   "--report", f"{tmp}/PLAN.json"]
        for name, env in (("default_blas", {}), ("one_blas_thread", {"OPENBLAS_NUM_THREADS": "1",
                                                                     "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"})):
            started = time.perf_counter()
            subprocess.run(command, check=True, stdout=subprocess.DEVNULL, env={**os.environ, **env})
            wall = time.perf_counter() - started
            doc = json.loads(Path(f"{tmp}/PLAN.json").read_text(encoding="utf-8"))
            out[name] = {"process_wall_s": wall, "plan_s": doc["seconds"],
                         "plan_over_random": doc["predicted"]["plan_over_random_mean_position"]}
        Path(f"{tmp}/PLAN.csv").unlink()
        Path(f"{tmp}/PLAN.json").unlink()
        out["pinocchio_calls"] = counted_run(command)
    return out


# --- lower bounds: the Pinocchio work a run asks for, at Pinocchio's own cost -------------------

#: Written as ``sitecustomize.py`` into a folder put first on PYTHONPATH: every Python process of a
#: counted run (study workers included, spawned or forked) counts its Pinocchio kinematics calls and
#: writes them, as JSON named by its pid, into $PINCAL_COUNT_DIR when it exits.
_COUNTING_SITE = """
import atexit, json, os
import pinocchio as _pin
_counts = {"jacobian": 0, "kinematics": 0}
def _counted(name, key):
    original = getattr(_pin, name)
    def counted(*args, **kwargs):
        _counts[key] += 1
        return original(*args, **kwargs)
    setattr(_pin, name, counted)
_counted("computeJointJacobians", "jacobian")
_counted("computeFrameJacobian", "jacobian")
_counted("forwardKinematics", "kinematics")
@atexit.register
def _write():
    name = os.path.join(os.environ["PINCAL_COUNT_DIR"], str(os.getpid()))
    with open(name + ".part", "w") as out:
        json.dump(_counts, out)
    os.replace(name + ".part", name + ".json")
def _forked():  # a forked worker counts from zero and leaves by os._exit, without atexit
    for key in _counts:
        _counts[key] = 0
    leave = os._exit
    def _exit(status):
        _write()
        leave(status)
    os._exit = _exit
os.register_at_fork(after_in_child=_forked)
"""


def counted_run(command: list[str], cwd: str | Path | None = None) -> dict:
    """Run ``command`` (a Python process) with every process counting its Pinocchio calls:
    configurations evaluated with Jacobians (``jacobian``) and forward kinematics only
    (``kinematics``), summed over the processes. Worker processes may outlive the command's
    process (the console script leaves without waiting for them): their counts are awaited until
    no new one has come for a second (at most 30 s)."""
    with (tempfile.TemporaryDirectory() as site,
          tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as counts):
        (Path(site) / "sitecustomize.py").write_text(_COUNTING_SITE, encoding="utf-8")
        path = os.pathsep.join(p for p in (site, os.environ.get("PYTHONPATH", "")) if p)
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=cwd,
                       env={**os.environ, "PYTHONPATH": path, "PINCAL_COUNT_DIR": counts})
        seen, deadline = -1, time.perf_counter() + 30.0
        while time.perf_counter() < deadline:
            written = len(list(Path(counts).glob("*.json")))
            if written == seen:
                break
            seen = written
            time.sleep(1.0)
        total = {"jacobian": 0, "kinematics": 0, "processes": 0}
        for file in Path(counts).glob("*.json"):
            for key, value in json.loads(file.read_text(encoding="utf-8")).items():
                total[key] += value
            total["processes"] += 1
    return total


def pinocchio_row_seconds(urdf: str | Path, tip_link: str, rows: int = 2000) -> dict:
    """Pinocchio's cost per configuration on the plain chain model of ``urdf`` [s], called from
    Python as pincal must: ``computeJointJacobians`` + ``getFrameJacobian`` (a residual with its
    Jacobian) and ``forwardKinematics`` (a residual only); best of 5 passes over ``rows`` random
    configurations."""
    import numpy as np
    import pinocchio as pin

    from pincal.model.chain import KinematicChain

    chain = KinematicChain.from_urdf(urdf, tip_link)
    model, data, frame = chain.model, chain.data, chain.tip_frame_id
    q = np.array([pin.randomConfiguration(model) for _ in range(rows)])
    world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    best = {"jacobian": np.inf, "kinematics": np.inf}
    for _ in range(5):
        started = time.perf_counter()
        for row in q:
            pin.computeJointJacobians(model, data, row)
            pin.getFrameJacobian(model, data, frame, world)
        best["jacobian"] = min(best["jacobian"], (time.perf_counter() - started) / rows)
        started = time.perf_counter()
        for row in q:
            pin.forwardKinematics(model, data, row)
        best["kinematics"] = min(best["kinematics"], (time.perf_counter() - started) / rows)
    return best


def import_floor(runs: int = 5) -> float:
    """Median wall time of ``python -c "import numpy, pinocchio"`` [s]: any Pinocchio-based
    Python process pays it."""
    times = []
    for _ in range(runs):
        started = time.perf_counter()
        subprocess.run([sys.executable, "-c", "import numpy, pinocchio"], check=True)
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def lower_bound(counts: dict, per_row: dict, floor: float = 0.0, workers: int = 1) -> float:
    """Seconds the counted Pinocchio work takes at ``per_row`` cost, shared by ``workers``
    processes, plus ``floor`` (process start and imports) [s]."""
    work = counts["jacobian"] * per_row["jacobian"] + counts["kinematics"] * per_row["kinematics"]
    return floor + work / workers


@contextlib.contextmanager
def counting_pinocchio():
    """In this process: count Pinocchio's kinematics calls inside the block (same keys as
    :func:`counted_run`)."""
    import pinocchio as pin

    counts = {"jacobian": 0, "kinematics": 0}
    saved = {name: getattr(pin, name) for name in ("computeJointJacobians", "computeFrameJacobian",
                                                   "forwardKinematics")}

    def counted(name: str, key: str):
        def call(*args, **kwargs):
            counts[key] += 1
            return saved[name](*args, **kwargs)
        return call

    pin.computeJointJacobians = counted("computeJointJacobians", "jacobian")
    pin.computeFrameJacobian = counted("computeFrameJacobian", "jacobian")
    pin.forwardKinematics = counted("forwardKinematics", "kinematics")
    try:
        yield counts
    finally:
        for name, function in saved.items():
            setattr(pin, name, function)


# --- (f) large, badly conditioned data ------------------------------------------------------------

_UR5_URDF = "ur_description/urdf/ur5_robot.urdf"
_UR5_TIP = "tool0"
#: Encoder jitter of the straight wrist [rad]: a 20-bit encoder behind a 1:100 gear reads 6e-8 rad.
_WRIST_JITTER_RAD = 5e-8


def large_session(path: Path, rows: int = 2500, seed: int = 11) -> dict:
    """Write (f)'s measurements to ``path``; returns the condition number of the scaled Jacobian of
    the identifiable parameters (with registration and target) at the nominal model, and its rank.

    The UR5's 42 placement errors are N(0, 1 mm or 1 mrad); a laser tracker with a 6D probe
    measures one point (σ 20 µm per axis) and its orientation (σ 0.002°). The rows lie on 6 lines
    and 4 planes through random configurations (joint-space steps of up to ±0.5 along random
    directions), wrist_2 at zero plus encoder jitter.
    """
    import numpy as np

    from pincal.fit.chain_calibration import FitProblem, row_weights
    from pincal.fit.identifiability import condition_number, order_parameters
    from pincal.fit.sessions import initial_target
    from pincal.measurements.csv_v1 import write_measurements
    from pincal.model.chain import KinematicChain
    from pincal.model.parameter_sets import PlacementErrors
    from pincal.robots import example_robot_data_urdf
    from pincal.simulation.sensor import DEFAULT_REGISTRATION, SimulatedSensor, measure

    chain = KinematicChain.from_urdf(example_robot_data_urdf(_UR5_URDF), _UR5_TIP)
    params = PlacementErrors(chain)
    rng = np.random.default_rng(seed)
    truth = rng.normal(0.0, 1e-3, params.size)
    pieces, per = [], -(-rows // 10)
    for piece in range(10):
        q0, d1, d2 = rng.uniform(-1.5, 1.5, 6), rng.normal(size=6), rng.normal(size=6)
        q0[4] = d1[4] = d2[4] = 0.0  # the wrist stays straight
        if piece < 6:  # a line
            pieces.append(q0 + np.linspace(-0.5, 0.5, per)[:, None] * d1)
        else:  # a plane
            pieces.append(q0 + rng.uniform(-0.5, 0.5, (per, 1)) * d1 + rng.uniform(-0.5, 0.5, (per, 1)) * d2)
    q = np.vstack(pieces)[:rows]
    q[:, 4] += rng.normal(0.0, _WRIST_JITTER_RAD, rows)
    nominal = chain.placements()
    params.apply(truth)
    data = measure(chain, q, DEFAULT_REGISTRATION, rng,
                   SimulatedSensor(20e-6, np.radians(0.002), points=np.array([[0.03, -0.02, 0.12]]),
                                   with_rotation=True), "calibration")
    chain.set_placements(nominal)
    write_measurements(path, data)
    # the condition number the user's data has: every identifiable parameter, at the nominal model
    problem = FitProblem(chain, params, data, initial_target(chain, data, fit_points=True), True,
                         row_weights(data, None))
    objective = problem.objective(np.arange(params.size), np.zeros(params.size))
    jac = objective.jacobian(objective.start_vector())
    others = np.arange(params.size, objective.n_params)
    ordering = order_parameters(jac, np.arange(params.size), others)
    identifiable = np.concatenate([ordering.order[: ordering.rank], others])
    return {"rows": rows, "rank": ordering.rank, "condition": condition_number(jac[:, identifiable])}


def large_calibration(per_row: dict | None = None, floor: float = 0.0) -> dict:
    """(f): the whole ``pincal calibrate`` process on :func:`large_session`'s data, the
    calibration time inside it (REPORT.json), what was kept, and the lower bound."""
    from pincal.robots import example_robot_data_urdf

    urdf = example_robot_data_urdf(_UR5_URDF)
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "tracker.csv"
        session = large_session(data)
        command = [sys.executable, "-m", "pincal", "calibrate", str(urdf), str(data), "--tip-link", _UR5_TIP,
                   "--level", "full", "--select", "aic", "--out", f"{tmp}/ur5_calibrated.urdf",
                   "--report", f"{tmp}/REPORT.json"]
        started = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - started
        report = json.loads(Path(f"{tmp}/REPORT.json").read_text(encoding="utf-8"))
        Path(f"{tmp}/ur5_calibrated.urdf").unlink()
        counts = counted_run(command)
    per_row = per_row or pinocchio_row_seconds(urdf, _UR5_TIP)
    return {
        **session,
        "process_wall_s": wall,
        "calibrate_s": report["fit"]["total_seconds"],
        "final_fit_s": report["fit"]["fit_seconds"],
        "kept": report["identifiability"]["selection"]["kept"],
        "final_condition": report["identifiability"]["jacobian_condition"],
        "pinocchio_calls": counts,
        "lower_bound_calibrate_s": lower_bound(counts, per_row),
        "lower_bound_process_s": lower_bound(counts, per_row, floor),
    }


# --- (e) side by side against another revision ----------------------------------------------

_TIAGO_URDF = "tiago_description/robots/tiago.urdf"
_TIAGO_DATA = HERE.parent / "data" / "tiago_mocap"

#: Whole-process benchmarks run against another revision: name → arguments of ``python -m pincal``
#: ({out} is a fresh output folder per run, {tiago} the TIAGo URDF of example-robot-data).
AGAINST = {
    "diagnose_tiago": [
        "diagnose", "{tiago}", str(_TIAGO_DATA / "qualisys_2021-11-30_static_postures.csv"),
        "--validation", str(_TIAGO_DATA / "qualisys_2021-11-26_static_postures.csv"),
        "--tip-link", "wrist_ft_tool_link", "--out", "{out}/tiago_diagnosed.urdf", "--report", "{out}/REPORT.json",
    ],
    "calibrate_tiago": [
        "calibrate", "{tiago}", str(_TIAGO_DATA / "qualisys_2021-11-30_static_postures.csv"),
        "--tip-link", "wrist_ft_tool_link", "--level", "full",
        "--out", "{out}/tiago_calibrated.urdf", "--report", "{out}/REPORT.json",
    ],
    "calibrate_large": [  # (f): {large} is the measurement file of :func:`large_session`
        "calibrate", "{ur5}", "{large}", "--tip-link", _UR5_TIP, "--level", "full",
        "--out", "{out}/ur5_calibrated.urdf", "--report", "{out}/REPORT.json",
    ],
    # (b): the paper's protocol (both deviation sets, 16 levels, 25 repeats, every estimator, 2 700
    # restarts) on 2 worker processes; minutes at 6975758 (use --pairs 3 or fewer)
    "study": ["study", "--out", "{out}/study", "--workers", "2"],
}
#: Arguments this tree needs to do the work an older revision does by default: ``--select aic`` since
#: ``--select prior`` became the default (the revisions these ratios are quoted against know no --select).
SAME_WORK = {name: ["--select", "aic"] for name in ("diagnose_tiago", "calibrate_tiago", "calibrate_large")}
#: The robot (URDF in example-robot-data, tip link) of each benchmark of :data:`AGAINST`, for its lower bound.
AGAINST_ROBOT = {"diagnose_tiago": (_TIAGO_URDF, "wrist_ft_tool_link"),
                 "calibrate_tiago": (_TIAGO_URDF, "wrist_ft_tool_link"),
                 "calibrate_large": (_UR5_URDF, _UR5_TIP),
                 "study": ("kuka", "lwr_flange")}  # "kuka": the packaged KUKA LWR 4+ URDF
#: Worker processes of a benchmark of :data:`AGAINST` (its Pinocchio work is shared by them).
AGAINST_WORKERS = {"study": 2}
_ONE_BLAS_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def build_revision(revision: str, where: Path) -> Path:
    """Check ``revision`` out in a git worktree under ``where`` and make a virtual environment
    that runs its pincal with this environment's packages; returns its python."""
    repository = HERE.parent
    tree = where / "tree"
    subprocess.run(["git", "-C", str(repository), "worktree", "add", "--detach", str(tree), revision],
                   check=True, capture_output=True, text=True)
    venv = where / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             check=True, capture_output=True, text=True).stdout.strip()
    package_root = tree / "src" if (tree / "src" / "pincal").is_dir() else tree
    # REV's pincal first on the path; then this environment's packages with their .pth files
    # (this tree's editable install only adds a finder consulted after the path)
    lines = [str(package_root)] + [f"import site; site.addsitedir({p!r})" for p in site.getsitepackages()
                                   if Path(p).is_dir()]
    (Path(purelib) / "pincal_benchmark_against.pth").write_text("\n".join(lines) + "\n", encoding="utf-8")
    return python


def remove_revision(where: Path) -> None:
    """Undo :func:`build_revision` (the worktree is unregistered from the repository)."""
    subprocess.run(["git", "-C", str(HERE.parent), "worktree", "remove", "--force", str(where / "tree")],
                   check=False, capture_output=True)


def _command(python: str | Path, arguments: list[str], out: str, files: dict) -> list[str]:
    """``python -m pincal ARGUMENTS`` with {out} the output folder and the other placeholders
    ({tiago}, {ur5}, {large}) from ``files``."""
    from pincal.robots import example_robot_data_urdf

    paths = {"tiago": example_robot_data_urdf(_TIAGO_URDF), "ur5": example_robot_data_urdf(_UR5_URDF), **files}
    return [str(python), "-m", "pincal"] + [a.format(out=out, **paths) for a in arguments]


def _timed_run(python: str | Path, arguments: list[str], env: dict, files: dict | None = None) -> float:
    """Wall time of one ``python -m pincal ARGUMENTS`` process [s] in a fresh output folder."""
    with tempfile.TemporaryDirectory() as out:
        command = _command(python, arguments, out, files or {})
        started = time.perf_counter()
        completed = subprocess.run(command, check=False, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                   text=True, env={**os.environ, **env}, cwd=out)
        wall = time.perf_counter() - started
    if completed.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {completed.stderr.strip()[-500:]}")
    return wall


def compare(python_old: str | Path, python_new: str | Path, arguments: list[str], pairs: int = 5,
            env: dict | None = None, files: dict | None = None, new_extra: list[str] | None = None) -> dict:
    """Run the same whole-process command with two interpreters, alternately: pair i runs
    old then new for even i, new then old for odd i (the new one with ``new_extra`` arguments
    appended: what keeps the two runs the same work). Returns the absolute times, the ratio
    old / new of each pair and their median, and the load average before and after."""
    env = env or {}
    new_arguments = arguments + list(new_extra or [])
    load_before = os.getloadavg()
    old_times, new_times = [], []
    for i in range(pairs):
        order = ((python_old, old_times, arguments), (python_new, new_times, new_arguments))
        for python, times, command in order if i % 2 == 0 else order[::-1]:
            times.append(_timed_run(python, command, env, files))
    ratios = [o / n for o, n in zip(old_times, new_times)]
    return {
        "pairs": pairs,
        "old_s": old_times,
        "new_s": new_times,
        "ratios": ratios,
        "median_ratio": statistics.median(ratios),
        "min_ratio": min(ratios),
        "old_median_s": statistics.median(old_times),
        "new_median_s": statistics.median(new_times),
        "load_average_before": load_before,
        "load_average_after": os.getloadavg(),
    }


def against(revision: str, pairs: int, names: list[str], one_blas_thread: bool) -> dict:
    """(e): every benchmark of ``names`` against ``revision``, alternately; the worktree is removed after."""
    out: dict = {"revision": revision, "pairs": pairs,
                 "blas": "one thread" if one_blas_thread else "default threads"}
    commit = subprocess.run(["git", "-C", str(HERE.parent), "rev-parse", revision],
                            check=True, capture_output=True, text=True).stdout.strip()
    out["commit"] = commit
    where = Path(tempfile.mkdtemp(prefix="pincal-against-"))
    try:
        python_old = build_revision(commit, where)
        env = _ONE_BLAS_THREAD if one_blas_thread else {}
        files = {}
        if "calibrate_large" in names:
            files["large"] = str(where / "tracker.csv")
            out["large_session"] = large_session(Path(files["large"]))
        floor = import_floor()
        out["import_floor_s"] = floor
        for name in names:
            extra = SAME_WORK.get(name, [])
            out[name] = compare(python_old, sys.executable, AGAINST[name], pairs, env, files, extra)
            with tempfile.TemporaryDirectory() as tmp:
                counts = counted_run(_command(sys.executable, AGAINST[name] + extra, tmp, files), cwd=tmp)
            from pincal.robots import example_robot_data_urdf, kuka_lwr4plus_urdf

            urdf, tip = AGAINST_ROBOT[name]
            path = kuka_lwr4plus_urdf() if urdf == "kuka" else example_robot_data_urdf(urdf)
            per_row = pinocchio_row_seconds(path, tip)
            out[name].update(pinocchio_calls=counts,
                             lower_bound_s=lower_bound(counts, per_row, floor, AGAINST_WORKERS.get(name, 1)))
    finally:
        remove_revision(where)
        shutil.rmtree(where, ignore_errors=True)
    return out


def _print_against(results: dict) -> None:
    print(f"against {results['revision']} ({results['commit'][:10]}), {results['pairs']} alternated pairs, "
          f"BLAS {results['blas']}")
    print(f"{'benchmark':20s} {'old median [s]':>15s} {'new median [s]':>15s} {'ratio (median)':>15s} "
          f"{'ratio (min)':>12s} {'load before/after':>18s} {'lower bound [s]':>16s} {'new / bound':>12s}")
    for name, entry in results.items():
        if name in AGAINST:
            print(f"{name:20s} {entry['old_median_s']:15.2f} {entry['new_median_s']:15.2f} "
                  f"{entry['median_ratio']:15.1f} {entry['min_ratio']:12.1f} "
                  f"{entry['load_average_before'][0]:8.2f}/{entry['load_average_after'][0]:<9.2f} "
                  f"{entry['lower_bound_s']:16.2f} {entry['new_median_s'] / entry['lower_bound_s']:12.1f}")
    if "large_session" in results:
        session = results["large_session"]
        print(f"calibrate_large: {session['rows']} 6D rows, {session['rank']} identifiable parameters, "
              f"condition number {session['condition']:.2g}")
    print(f"lower bound = Python + import numpy, pinocchio ({results['import_floor_s']:.2f} s) + the Pinocchio "
          "calls the run made, at Pinocchio's cost per call")


def _raster_session(folder: Path, rows: int) -> tuple[Path, str, Path]:
    """scripts/scenarios.py's tracker 4.2 m, 6D raster at constant orientation with ``rows`` rows, written
    into ``folder``: the robot's URDF, its tip link and the measurement file."""
    import importlib.util
    from dataclasses import replace

    from pincal.measurements.csv_v1 import write_measurements

    spec = importlib.util.spec_from_file_location("scenarios", HERE / "scenarios.py")
    scenarios = importlib.util.module_from_spec(spec)
    sys.modules["scenarios"] = scenarios
    spec.loader.exec_module(scenarios)
    case = replace(next(c for c in scenarios.SCENARIOS if "6D, raster" in c.name), rows=rows)
    urdf, tip = scenarios.build_robots(folder)[case.robot]
    _, calibration, _ = scenarios.simulate(case, urdf, tip)
    write_measurements(folder / "raster.csv", calibration)
    return urdf, tip, folder / "raster.csv"


def auto_against_full(pairs: int = 3, rows: int = 2500) -> dict:
    """(g) ``calibrate --level auto`` against ``--level full``, whole processes side by side (alternated
    pairs, the same machine and load), on the raster scenario of scripts/scenarios.py with ``rows`` 6D rows.
    The goal (the unseen-setups issue): auto ≤ 3× full."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        urdf, tip, raster = _raster_session(folder, rows)
        times: dict[str, list[float]] = {"full": [], "auto": []}
        for _ in range(pairs):
            for level in ("full", "auto"):
                started = time.perf_counter()
                subprocess.run([sys.executable, "-c", "import sys; from pincal.cli import console; sys.exit(console())",
                                "calibrate", str(urdf), str(raster), "--tip-link", tip, "--level", level,
                                "--quiet", "--out", str(folder / f"{level}.urdf"), "--report",
                                str(folder / f"{level}.json")], check=True, capture_output=True)
                times[level].append(time.perf_counter() - started)
    ratios = [a / f for a, f in zip(times["auto"], times["full"])]
    return {"rows": rows, "pairs": pairs, "full_s": times["full"], "auto_s": times["auto"],
            "ratio_median": statistics.median(ratios), "goal": 3.0, "load_average": os.getloadavg()}


#: (h)'s goal: a whole ``pincal diagnose`` at most this many times one
#: ``pincal calibrate --level full`` of the same rows.
DIAGNOSE_GOAL = 10.0
#: (h): every HELD_OUT_EVERY-th row of a session goes to the --validation file.
HELD_OUT_EVERY = 5


def _held_out_split(path: Path) -> tuple[Path, Path]:
    """``path``'s rows split as a user holding out every :data:`HELD_OUT_EVERY`-th one would: the
    calibration file and the held-out file beside it (the header in both)."""
    header, *rows = path.read_text(encoding="utf-8").splitlines()
    files = path.with_name(path.stem + "_calibration.csv"), path.with_name(path.stem + "_heldout.csv")
    for file, held in zip(files, (False, True)):
        kept = [row for i, row in enumerate(rows) if (i % HELD_OUT_EVERY == HELD_OUT_EVERY - 1) == held]
        file.write_text("\n".join([header, *kept]) + "\n", encoding="utf-8")
    return files


def diagnose_against_calibrate(pairs: int = 3, rows: int = 2500, select: str | None = None) -> dict:
    """(h) whole ``pincal diagnose`` processes against one ``pincal calibrate --level full`` of the same
    rows, side by side: on (f)'s UR5 session and on scripts/scenarios.py's tracker 4.2 m 6D raster at
    constant orientation, ``rows`` 6D rows each. Per session and pair, three processes in an order
    rotated from pair to pair: calibrate on every row, diagnose on every row, and diagnose with a
    held-out split (:func:`_held_out_split`: 4/5 calibrated, 1/5 in ``--validation``). Each ratio
    diagnose / calibrate is taken within its pair (the same load), its median over the pairs reported;
    the goal is :data:`DIAGNOSE_GOAL`. ``select``: a ``--select`` criterion for all three (default:
    the commands' own)."""
    from pincal.robots import example_robot_data_urdf

    extra = [] if select is None else ["--select", select]
    out: dict = {"rows": rows, "pairs": pairs, "select": select or "default", "goal": DIAGNOSE_GOAL,
                 "held_out_every": HELD_OUT_EVERY, "load_average_before": os.getloadavg(), "sessions": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        ur5 = folder / "ur5_tracker.csv"
        large_session(ur5, rows)
        raster_urdf, raster_tip, raster = _raster_session(folder, rows)
        sessions = {"ur5_lines_planes": (example_robot_data_urdf(_UR5_URDF), _UR5_TIP, ur5),
                    "raster_constant_orientation": (raster_urdf, raster_tip, raster)}
        for name, (urdf, tip, data) in sessions.items():
            calibration, heldout = _held_out_split(data)
            common = ["--tip-link", tip, *extra, "--quiet"]
            commands = {
                "calibrate": ["calibrate", str(urdf), str(data), "--level", "full", *common,
                              "--out", "{out}/calibrated.urdf", "--report", "{out}/REPORT.json"],
                "diagnose": ["diagnose", str(urdf), str(data), *common,
                             "--out", "{out}/diagnosed.urdf", "--report", "{out}/REPORT.json"],
                "diagnose_validation": ["diagnose", str(urdf), str(calibration), "--validation", str(heldout),
                                        *common, "--out", "{out}/diagnosed.urdf", "--report", "{out}/REPORT.json"],
            }
            times: dict[str, list[float]] = {command: [] for command in commands}
            order = list(commands)
            for i in range(pairs):
                for command in order[i % 3:] + order[: i % 3]:
                    times[command].append(_timed_run(sys.executable, commands[command], {}))
            entry: dict = {"times_s": times}
            for command in ("diagnose", "diagnose_validation"):
                ratios = [d / c for d, c in zip(times[command], times["calibrate"])]
                entry[f"{command}_over_calibrate"] = {"ratios": ratios, "median": statistics.median(ratios)}
            out["sessions"][name] = entry
    out["load_average_after"] = os.getloadavg()
    return out


def _print_diagnose(result: dict) -> None:
    """(h)'s lines: per session, the median times and the median ratios against the goal."""
    print(f"(h) whole pincal diagnose / one pincal calibrate --level full, {result['rows']} 6D rows, "
          f"--select {result['select']}, median of {result['pairs']} rotated triples (goal <= {result['goal']:g}x)")
    for name, entry in result["sessions"].items():
        times = {command: statistics.median(values) for command, values in entry["times_s"].items()}
        plain, held = entry["diagnose_over_calibrate"]["median"], entry["diagnose_validation_over_calibrate"]["median"]
        print(f"    {name:28s} calibrate {times['calibrate']:6.2f} s, diagnose {times['diagnose']:6.2f} s "
              f"({plain:.1f}x), with --validation {times['diagnose_validation']:6.2f} s ({held:.1f}x)")
    print(f"    load average before {result['load_average_before'][0]:.2f}, after "
          f"{result['load_average_after'][0]:.2f} ({os.cpu_count()} CPUs)")


#: (i): TALOS's gripper links, each carrying one marker, and the rows of the issue's scale.
TREE_TARGETS = ("gripper_left_base_link:1", "gripper_right_base_link:2")
TREE_ROWS = 500
TREE_GOAL_S = 5.0


#: (i): the compliance of TALOS's torso pitch joint in the rows diagnose adopts an effect on [rad/(N·m)]: a
#: sag of 2-3 mrad under the upper body's ~25 N·m, a few mm at the grippers: the size of what joint and lateral
#: compliances corrected in a published elastic humanoid calibration (10.5 -> 3.1 mm mean position error).
TREE_COMPLIANCE = ("torso_2_joint", -1e-4)


def _tree_rows(rows: int, seed: int, compliance: float):
    """(i)'s rows: TALOS as :func:`pincal.simulation.humanoid.simulate_humanoid` simulates it, with a marker
    10 cm beyond each gripper's base seen by its mocap (0.1 mm per axis), every placement off by 0.5 mm / 0.5
    mrad, no payload, and the torso pitch at its reading + ``compliance`` x its gravity torque under the URDF's
    masses (none: rigid)."""
    from pincal.simulation.humanoid import HumanoidSettings, simulate_humanoid

    settings = HumanoidSettings(targets=TREE_TARGETS, rows=rows, held_out_rows=0, sigma_pos_mm=0.1,
                                deviation_mm=0.5, deviation_mrad=0.5,
                                compliance=((TREE_COMPLIANCE[0], compliance),) if compliance else (),
                                payload_kg=0.0, marker_m=(0.0, 0.0, -0.1), seed=seed)
    return simulate_humanoid(settings)


def tree_calibration(runs: int = 3, rows: int = TREE_ROWS, seed: int = 3) -> dict:
    """(i): whole ``pincal calibrate`` processes of TALOS's upper body with a marker on each gripper [s], and
    whole ``pincal diagnose`` processes beside them (``diagnose_tree``): on the same rigid rows, and on rows
    whose torso pitch sags (:data:`TREE_COMPLIANCE`), each against calibrate of its rows in alternated order."""
    from pincal.measurements.csv_v1 import write_measurements
    from pincal.robots import example_robot_data_urdf
    from pincal.simulation.humanoid import TALOS_URDF

    urdf = example_robot_data_urdf(TALOS_URDF)
    targets = [flag for target in TREE_TARGETS for flag in ("--tip-link", target)]
    out: dict = {}
    with tempfile.TemporaryDirectory() as folder:
        for name, compliance in (("rigid", 0.0), ("torso_compliance", TREE_COMPLIANCE[1])):
            simulated = _tree_rows(rows, seed, compliance)
            data = Path(folder) / f"talos_{name}.csv"
            write_measurements(data, simulated.calibration)
            times: dict[str, list[float]] = {"calibrate": [], "diagnose": []}
            for i in range(runs):  # calibrate and diagnose side by side, their order alternated (the same load)
                for command in ("calibrate", "diagnose")[:: 1 if i % 2 == 0 else -1]:
                    start = time.perf_counter()
                    subprocess.run([sys.executable, "-m", "pincal", command, str(urdf), str(data), *targets,
                                    "--out", f"{folder}/talos_{command}.urdf", "--report",
                                    f"{folder}/REPORT_{command}.json", "--quiet"], check=True, capture_output=True)
                    times[command].append(time.perf_counter() - start)
            report = json.loads(Path(folder, "REPORT_calibrate.json").read_text(encoding="utf-8"))
            diagnosis = json.loads(Path(folder, "REPORT_diagnose.json").read_text(encoding="utf-8"))
            ratios = [d / c for d, c in zip(times["diagnose"], times["calibrate"])]
            out[name] = {"calibrate_s": times["calibrate"], "diagnose_s": times["diagnose"],
                         "over_calibrate": {"ratios": ratios, "median": statistics.median(ratios)},
                         "rms_after_mm": [t["calibration_errors"]["position"]["rms_mm"] for t in report["targets"]],
                         "diagnosed_rms_mm": [t["calibration_errors"]["position"]["rms_mm"]
                                              for t in diagnosis["targets"]],
                         "effects": [f"{e['type']}:{e.get('joint')}" for e in diagnosis.get("effects", [])]}
    rigid = out["rigid"]
    return {"rows": rows, "joints": simulated.tree.n_joints, "targets": list(TREE_TARGETS),
            "times_s": rigid["calibrate_s"],
            "median_s": statistics.median(rigid["calibrate_s"]), "goal_s": TREE_GOAL_S,
            "rms_after_mm": rigid["rms_after_mm"],
            "diagnose_tree": {**out, "goal": DIAGNOSE_GOAL, "compliance": list(TREE_COMPLIANCE)},
            "load_average": os.getloadavg()}


#: (j)'s goals: 60 images of 1280x960 px, whole processes [s].
CAMERA_GOALS = {"detect_s": 15.0, "calibrate_s": 10.0}


def camera_benchmark(runs: int = 3, images: int = 60, seed: int = 1) -> dict:
    """(j): whole ``pincal detect`` and ``pincal calibrate --camera-link`` processes on ``images`` rendered
    1280x960 images of a ChArUco board seen by a camera on a UR5's tool0 (pincal.workflows.camera_simulation's
    scene, rendered by pincal.simulation.board_images, 2 grey levels of noise), median of ``runs`` [s]."""
    import csv

    import cv2
    import numpy as np

    from pincal.model.camera_info import write_camera_info
    from pincal.model.camera_view import pose
    from pincal.simulation.board_images import BoardView, render_board
    from pincal.workflows.camera_simulation import BOARD_SPEC, INTRINSICS, CameraSimulationSettings, simulate_camera

    simulated = simulate_camera(CameraSimulationSettings("eye_in_hand", images=images, held_out=0, seed=seed))
    chain, scene, rng = simulated.chain, simulated.scene, np.random.default_rng(seed)
    detect, calibrate = [], []
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        (root / "images").mkdir()
        started = time.perf_counter()
        with chain.placed(list(simulated.placements)):
            rotations, positions = chain.tool_poses(simulated.q)
        names = [f"image_{k:03d}.png" for k in range(images)]
        for name, r, t in zip(names, rotations, positions):
            camera_T_board = np.linalg.inv(pose(r, t) @ scene.mount) @ scene.worlds[0]
            view = BoardView(INTRINSICS.matrix, np.array(INTRINSICS.distortion), (INTRINSICS.width, INTRINSICS.height),
                             cv2.Rodrigues(camera_T_board[:3, :3])[0].ravel(), camera_T_board[:3, 3])
            cv2.imwrite(str(root / "images" / name), render_board(scene.board, view, 2.0, rng))
        render_s = time.perf_counter() - started
        with open(root / "joints.csv", "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["image", *chain.joint_names])
            writer.writerows([name, *(repr(float(v)) for v in row)] for name, row in zip(names, simulated.q))
        (root / "ur5_camera.urdf").write_text(simulated.urdf_text, encoding="utf-8")
        write_camera_info(root / "camera_info.yaml", INTRINSICS)
        for _ in range(runs):
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "pincal", "detect", str(root / "images"), "--board", BOARD_SPEC,
                            "--joints", str(root / "joints.csv"), "--out", str(root / "DATA.csv")],
                           check=True, capture_output=True)
            detect.append(time.perf_counter() - start)
            start = time.perf_counter()
            subprocess.run([sys.executable, "-m", "pincal", "calibrate", str(root / "ur5_camera.urdf"),
                            str(root / "DATA.csv"), "--camera-link", "camera_link", "--intrinsics",
                            str(root / "camera_info.yaml"), "--out", str(root / "calibrated.urdf"), "--report",
                            str(root / "REPORT.json")], check=True, capture_output=True)
            calibrate.append(time.perf_counter() - start)
        report = json.loads((root / "REPORT.json").read_text(encoding="utf-8"))
    reprojection = report["camera"]["reprojection"]["calibration"]
    return {"images": images, "size": [INTRINSICS.width, INTRINSICS.height], "render_s": render_s,
            "detect_s": detect, "detect_median_s": statistics.median(detect),
            "calibrate_s": calibrate, "calibrate_median_s": statistics.median(calibrate),
            "fit_s": report["fit_seconds"], "corners": reprojection["after"]["corners"],
            "rms_px": [reprojection["before"]["rms_px"], reprojection["after"]["rms_px"]], "goals": CAMERA_GOALS,
            "load_average": os.getloadavg()}


def _write_json(path: Path, result: dict | list) -> None:
    """Write one benchmark's numbers and say where."""
    path.write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--auto", action="store_true", help="only (g): --level auto against --level full, "
                        "2 500 raster rows, whole processes side by side")
    parser.add_argument("--runs", type=int, default=50, help="runs of (a) (default 50)")
    parser.add_argument("--workers", type=int, default=2, help="processes of (b) (default 2)")
    parser.add_argument("--skip-study", action="store_true", help="skip (b), the full study")
    parser.add_argument("--json", type=Path, default=None,
                        help="output JSON (default scripts/benchmark_results.json, with --against "
                             "scripts/benchmark_against.json)")
    parser.add_argument("--against", metavar="REV", help="only (e): whole processes against git revision REV")
    parser.add_argument("--pairs", type=int, default=None, help="alternated pairs of (e) (default 5) and "
                        "rotated triples of (h) (default 3)")
    default_against = "diagnose_tiago,calibrate_tiago"
    parser.add_argument("--only", default=default_against,
                        help=f"benchmarks of (e) among {','.join(AGAINST)} (default {default_against})")
    parser.add_argument("--one-blas-thread", action="store_true", help="(e) with OPENBLAS_NUM_THREADS=1 for both")
    parser.add_argument("--diagnose", action="store_true", help="only (h): whole diagnose (with and without "
                        "--validation) against calibrate --level full, 2 500 6D rows of (f)'s UR5 and of a raster, "
                        "side by side")
    parser.add_argument("--select", default=None, help="(h): a --select criterion for every command "
                        "(default: the commands' own)")
    parser.add_argument("--tree", action="store_true", help="only (i): calibrate TALOS's upper body, a marker on "
                        "each gripper, 500 rows, whole processes")
    parser.add_argument("--camera", action="store_true", help="only (j): pincal detect and calibrate --camera-link "
                        "on 60 rendered 1280x960 images, whole processes")
    args = parser.parse_args(argv)
    if args.camera:
        result = camera_benchmark(runs=min(args.runs, 3))
        print(f"(j) {result['images']} images {result['size'][0]}x{result['size'][1]}, whole processes, median of "
              f"{len(result['detect_s'])}: detect {result['detect_median_s']:.2f} s (goal <= "
              f"{CAMERA_GOALS['detect_s']:g} s), calibrate --camera-link {result['calibrate_median_s']:.2f} s (goal <= "
              f"{CAMERA_GOALS['calibrate_s']:g} s; the fit {result['fit_s']:.2f} s); {result['corners']} corners, RMS "
              f"{result['rms_px'][0]:.3f} -> {result['rms_px'][1]:.3f} px; load {result['load_average'][0]:.1f}")
        _write_json(args.json or HERE / "benchmark_camera.json", result)
        return 0
    if args.tree:
        result = tree_calibration(runs=min(args.runs, 3))
        print(f"(i) calibrate, {result['joints']} joints, {len(result['targets'])} targets, {result['rows']} rows, "
              f"whole process: {result['median_s']:.2f} s median of {len(result['times_s'])} (goal <= "
              f"{result['goal_s']:g} s); RMS after {', '.join(f'{v:.3f}' for v in result['rms_after_mm'])} mm; "
              f"load {result['load_average'][0]:.1f}")
        diagnose = result["diagnose_tree"]
        for name in ("rigid", "torso_compliance"):
            entry = diagnose[name]
            print(f"    diagnose_tree, {name} rows, whole process: {statistics.median(entry['diagnose_s']):.2f} s "
                  f"median, {entry['over_calibrate']['median']:.1f}x calibrate (median of the runs' ratios; goal "
                  f"<= {diagnose['goal']:g}x); effects {', '.join(entry['effects']) or 'none'}; RMS "
                  f"{', '.join(f'{v:.3f}' for v in entry['rms_after_mm'])} -> "
                  f"{', '.join(f'{v:.3f}' for v in entry['diagnosed_rms_mm'])} mm")
        _write_json(args.json or HERE / "benchmark_tree.json", result)
        return 0
    if args.diagnose:
        result = diagnose_against_calibrate(pairs=args.pairs or 3, select=args.select)
        _print_diagnose(result)
        _write_json(args.json or HERE / "benchmark_diagnose.json", result)
        return 0
    if args.auto:
        result = auto_against_full()
        print(f"(g) calibrate --level auto / --level full, {result['rows']} raster rows, whole process: "
              f"{result['ratio_median']:.2f}x (median of {result['pairs']} pairs; goal <= {result['goal']:g}x); "
              f"full {statistics.median(result['full_s']):.2f} s, auto {statistics.median(result['auto_s']):.2f} s, "
              f"load {result['load_average'][0]:.1f}")
        _write_json(args.json or HERE / "benchmark_auto.json", result)
        return 0
    if args.against:
        names = [n for n in args.only.split(",") if n]
        unknown = [n for n in names if n not in AGAINST]
        if unknown:
            parser.error(f"unknown benchmark(s) {unknown}; choose from {list(AGAINST)}")
        results = against(args.against, args.pairs or 5, names, args.one_blas_thread)
        _print_against(results)
        _write_json(args.json or HERE / "benchmark_against.json", results)
        return 0
    args.json = args.json or HERE / "benchmark_results.json"

    results: dict = {
        "machine": {
            "python": platform.python_version(),
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
            "load_average_before": os.getloadavg(),
        },
        "goals": GOALS,
    }
    from pincal.robots import (
        KUKA_FLANGE_LINK,
        example_robot_data_urdf,
        kuka_lwr4plus_urdf,
    )

    kuka = pinocchio_row_seconds(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    floor = import_floor()
    results["lower_bounds"] = {"import_floor_s": floor, "kuka_per_row_s": kuka}
    results["method2_calibration"] = method2_calibration(args.runs)
    results["scaling"] = scaling()
    if not args.skip_study:
        results["default_study"] = default_study(args.workers)
    results["plan"] = plan_benchmark()
    ur5 = pinocchio_row_seconds(example_robot_data_urdf(_UR5_URDF), _UR5_TIP)
    results["lower_bounds"]["ur5_per_row_s"] = ur5
    results["large_calibration"] = large_calibration(ur5, floor)
    results["machine"]["load_average_after"] = os.getloadavg()

    def row(label: str, value: float, goal: str = "", limit: float | None = None, note: str = "") -> None:
        """One line: the benchmark, its value, its goal, the lower bound and how far pincal is from it."""
        far = f"{limit:11.3g} {value / limit:8.1f}x" if limit else f"{'':11s} {'':9s}"
        print(f"{label:62s} {value:10.3f} {goal:>6s} {far}  {note}")

    print(f"{'benchmark':62s} {'value':>10s} {'goal':>6s} {'lower bound':>11s} {'how far':>9s}")
    a = results["method2_calibration"]
    row(f"(a) Method 2 calibration, K = 100, median of {a['runs']} [s]", a["median_ms"] / 1e3,
        f"{GOALS['method2_median_ms'] / 1e3:g}", lower_bound(a["pinocchio_calls"], kuka))
    if "default_study" in results:
        b = results["default_study"]
        row(f"(b) pincal study (defaults), {b['workers']} workers, wall [s]", b["wall_s"],
            f"{GOALS['study_wall_s']:g}", lower_bound(b["pinocchio_calls"], kuka, floor, b["workers"]))
    for k, entry in results["scaling"].items():
        if k.isdigit():
            row(f"(c) K = {k}: process wall [s]", entry["process_wall_s"], "",
                lower_bound(entry["pinocchio_calls"], kuka, floor), f"(calibration {entry['calibrate_s']:.3f} s)")
    ratio = results["scaling"].get("ratio_10000_over_1000")
    if ratio:
        row("(c) K = 10000 / K = 1000, whole process", ratio["process_wall"], f"{GOALS['k_ratio_10000_over_1000']:g}")
        row("(c) K = 10000 / K = 1000, calibration only", ratio["calibrate"])
    plan = results["plan"]
    for name in ("default_blas", "one_blas_thread"):
        entry = plan[name]
        row(f"(d) pincal plan KUKA full 100 of 10000, {name}: wall [s]", entry["process_wall_s"], "",
            lower_bound(plan["pinocchio_calls"], kuka, floor), f"(planning {entry['plan_s']:.2f} s)")
    f = results["large_calibration"]
    row(f"(f) UR5, 2500 6D rows, cond {f['condition']:.1e}, full level: wall [s]", f["process_wall_s"], "",
        f["lower_bound_process_s"])
    row("(f) the calibration inside it, selection included [s]", f["calibrate_s"], "", f["lower_bound_calibrate_s"],
        f"({f['kept']} of {f['rank']} identifiable kept)")
    print(f"lower bound: the Pinocchio calls each run made, at Pinocchio's cost per call from Python (KUKA "
          f"{kuka['jacobian'] * 1e6:.1f} us with Jacobians, {kuka['kinematics'] * 1e6:.1f} us without; UR5 "
          f"{ur5['jacobian'] * 1e6:.1f} / {ur5['kinematics'] * 1e6:.1f} us), plus for a whole process "
          f"Python + import numpy, pinocchio ({floor:.2f} s)")
    load = results["machine"]
    print(f"load average before {load['load_average_before'][0]:.2f}, after {load['load_average_after'][0]:.2f} "
          f"({load['cpus']} CPUs)")
    _write_json(args.json, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
