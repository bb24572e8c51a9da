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

Prints a table and writes the numbers to ``scripts/benchmark_results.json``.
Goals: (a) median <= 10 ms, (b) <= 60 s on 2 cores, (c) ratio <= 12.
The machine's load average is recorded: other processes slow every number.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=50, help="runs of (a) (default 50)")
    parser.add_argument("--workers", type=int, default=2, help="processes of (b) (default 2)")
    parser.add_argument("--skip-study", action="store_true", help="skip (b), the full study")
    parser.add_argument("--json", type=Path, default=HERE / "benchmark_results.json", help="output JSON")
    args = parser.parse_args(argv)

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
    load = results["machine"]
    print(f"load average before {load['load_average_before'][0]:.2f}, after {load['load_average_after'][0]:.2f} "
          f"({load['cpus']} CPUs)")
    args.json.write_text(json.dumps(results, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
