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

    python scripts/benchmark.py --against REV [--pairs 5] [--only diagnose_tiago,calibrate_tiago]

(e) ``--against REV``: builds REV (any git revision) in a temporary worktree and
    virtual environment (its own code, this environment's dependencies) and
    runs each whole-process benchmark of :data:`AGAINST` with both, alternately
    (REV then this tree, then this tree then REV, ...): each ratio REV / this
    is the median over the pairs, next to the absolute times and the load
    average, with the default BLAS threads (``--one-blas-thread`` for one).
    Writes ``scripts/benchmark_against.json`` (or ``--json``); nothing else runs.

Prints a table and writes the numbers to ``scripts/benchmark_results.json``.
Goals: (a) median <= 10 ms, (b) <= 60 s on 2 cores, (c) ratio <= 12.
The machine's load average is recorded: other processes slow every number.
"""

from __future__ import annotations

import argparse
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
from pincal.model.dh import KUKA_LWR4_DH, TABLE2_LARGE
from pincal.fit.paper_methods import calibrate_paper
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
    from pincal.fit.paper_methods import calibrate_paper
    from pincal.model.chain import KinematicChain
    from pincal.model.dh import KUKA_LWR4_DH, TABLE2_LARGE
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
    return {
        "runs": runs,
        "median_ms": statistics.median(times),
        "min_ms": min(times),
        "max_ms": max(times),
        "k": settings.n_calibration,
        "k_alpha": settings.n_cpa,
    }


def default_study(workers: int) -> dict:
    """(b): wall time of ``pincal study`` with the paper's defaults on ``workers`` processes."""
    with tempfile.TemporaryDirectory() as tmp:
        command = [sys.executable, "-m", "pincal", "study", "--out", tmp, "--workers", str(workers)]
        started = time.perf_counter()
        subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - started
        inner = json.loads((Path(tmp) / "study.json").read_text(encoding="utf-8"))
    return {
        "workers": workers,
        "command": "pincal study --workers " + str(workers),
        "wall_s": wall,
        "study_wall_s": inner["wall_s"],
        "rows": len(inner["rows"]),
        "restarts": len(inner["restarts"]),
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
        out[str(k)] = {"process_wall_s": wall, **json.loads(completed.stdout)}
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
    return out


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
}
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


def _timed_run(python: str | Path, arguments: list[str], env: dict) -> float:
    """Wall time of one ``python -m pincal ARGUMENTS`` process [s] in a fresh output folder."""
    from pincal.robots import example_robot_data_urdf

    with tempfile.TemporaryDirectory() as out:
        command = [str(python), "-m", "pincal"] + [
            a.format(out=out, tiago=example_robot_data_urdf(_TIAGO_URDF)) for a in arguments
        ]
        started = time.perf_counter()
        completed = subprocess.run(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                   env={**os.environ, **env}, cwd=out)
        wall = time.perf_counter() - started
    if completed.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed: {completed.stderr.strip()[-500:]}")
    return wall


def compare(python_old: str | Path, python_new: str | Path, arguments: list[str], pairs: int = 5,
            env: dict | None = None) -> dict:
    """Run the same whole-process command with two interpreters, alternately: pair i runs
    old then new for even i, new then old for odd i. Returns the absolute times, the ratio
    old / new of each pair and their median, and the load average before and after."""
    env = env or {}
    load_before = os.getloadavg()
    old_times, new_times = [], []
    for i in range(pairs):
        order = ((python_old, old_times), (python_new, new_times))
        for python, times in order if i % 2 == 0 else order[::-1]:
            times.append(_timed_run(python, arguments, env))
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
        for name in names:
            out[name] = compare(python_old, sys.executable, AGAINST[name], pairs, env)
    finally:
        remove_revision(where)
        shutil.rmtree(where, ignore_errors=True)
    return out


def _print_against(results: dict) -> None:
    print(f"against {results['revision']} ({results['commit'][:10]}), {results['pairs']} alternated pairs, "
          f"BLAS {results['blas']}")
    print(f"{'benchmark':20s} {'old median [s]':>15s} {'new median [s]':>15s} {'ratio (median)':>15s} "
          f"{'ratio (min)':>12s} {'load before/after':>18s}")
    for name, entry in results.items():
        if isinstance(entry, dict):
            print(f"{name:20s} {entry['old_median_s']:15.2f} {entry['new_median_s']:15.2f} "
                  f"{entry['median_ratio']:15.1f} {entry['min_ratio']:12.1f} "
                  f"{entry['load_average_before'][0]:8.2f}/{entry['load_average_after'][0]:.2f}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=50, help="runs of (a) (default 50)")
    parser.add_argument("--workers", type=int, default=2, help="processes of (b) (default 2)")
    parser.add_argument("--skip-study", action="store_true", help="skip (b), the full study")
    parser.add_argument("--json", type=Path, default=None,
                        help="output JSON (default scripts/benchmark_results.json, with --against "
                             "scripts/benchmark_against.json)")
    parser.add_argument("--against", metavar="REV", help="only (e): whole processes against git revision REV")
    parser.add_argument("--pairs", type=int, default=5, help="alternated pairs of (e) (default 5)")
    parser.add_argument("--only", default=",".join(AGAINST), help=f"benchmarks of (e) (default {','.join(AGAINST)})")
    parser.add_argument("--one-blas-thread", action="store_true", help="(e) with OPENBLAS_NUM_THREADS=1 for both")
    args = parser.parse_args(argv)
    if args.against:
        names = [n for n in args.only.split(",") if n]
        unknown = [n for n in names if n not in AGAINST]
        if unknown:
            parser.error(f"unknown benchmark(s) {unknown}; choose from {list(AGAINST)}")
        results = against(args.against, args.pairs, names, args.one_blas_thread)
        _print_against(results)
        path = args.json or HERE / "benchmark_against.json"
        path.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
        print(f"wrote {path}")
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
    results["method2_calibration"] = method2_calibration(args.runs)
    results["scaling"] = scaling()
    if not args.skip_study:
        results["default_study"] = default_study(args.workers)
    results["plan"] = plan_benchmark()
    results["machine"]["load_average_after"] = os.getloadavg()

    a = results["method2_calibration"]
    print(f"{'benchmark':58s} {'value':>10s} {'goal':>8s}")
    print(f"{'(a) Method 2 calibration, K = 100, median of %d [ms]' % a['runs']:58s} "
          f"{a['median_ms']:10.2f} {GOALS['method2_median_ms']:8.0f}")
    if "default_study" in results:
        b = results["default_study"]
        print(f"{'(b) pincal study (defaults), %d workers, wall [s]' % b['workers']:58s} "
              f"{b['wall_s']:10.1f} {GOALS['study_wall_s']:8.0f}")
    for k, entry in results["scaling"].items():
        if k.isdigit():
            print(f"{'(c) K = %s: process wall [s] / calibration [s]' % k:58s} "
                  f"{entry['process_wall_s']:10.2f} / {entry['calibrate_s']:.3f}")
    ratio = results["scaling"].get("ratio_10000_over_1000")
    if ratio:
        print(f"{'(c) K = 10000 / K = 1000, whole process':58s} {ratio['process_wall']:10.2f} "
              f"{GOALS['k_ratio_10000_over_1000']:8.0f}")
        print(f"{'(c) K = 10000 / K = 1000, calibration only':58s} {ratio['calibrate']:10.2f}")
    for name, entry in results["plan"].items():
        if isinstance(entry, dict):
            print(f"{'(d) pincal plan KUKA full 100 of 10000, %s: wall / plan [s]' % name:58s} "
                  f"{entry['process_wall_s']:10.2f} / {entry['plan_s']:.2f}")
    load = results["machine"]
    print(f"load average before {load['load_average_before'][0]:.2f}, after {load['load_average_after'][0]:.2f} "
          f"({load['cpus']} CPUs)")
    args.json.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
