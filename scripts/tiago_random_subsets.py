"""The reference against which ``pincal plan`` is judged on real data: 1 000 random TIAGo subsets.

    python scripts/tiago_random_subsets.py [--count 1000] [--out tests/data/tiago_random_subsets.csv]

TIAGo's 37 static postures of 2021-11-30 (``data/tiago_mocap``, four Qualisys markers): for each of
``--count`` random 20-row subsets (``numpy.random.default_rng(1)``, ``rng.choice(37, 20)``), calibrate
at level full estimating every identifiable parameter (``selection="all"``: the estimator whose error
the plan predicts) and hold out 2021-11-26: the RMS of marker 1's position error [mm], the README's
TIAGo metric. About 85 ms a subset on one core (85 s for 1 000).

``tests/test_plan.py::test_tiago_planned_subset_is_in_the_best_quarter_of_random_subsets`` ranks
the planned subset against the file and recomputes 20 of its rows (the 10 nearest the planned value
and 10 others) to 1e-6 mm, so a calibrator that changes its answers fails that test with a pointer
here instead of ranking against a stale reference. Rerun this script when it says so.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.metrics import pose_errors
from pincal.measurements.csv_v1 import read_measurements
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.robots import example_robot_data_urdf

ROOT = Path(__file__).resolve().parent.parent
TIAGO_DATA = ROOT / "data" / "tiago_mocap"
TRAIN = TIAGO_DATA / "qualisys_2021-11-30_static_postures.csv"
HELD_OUT = TIAGO_DATA / "qualisys_2021-11-26_static_postures.csv"
REFERENCE = ROOT / "tests" / "data" / "tiago_random_subsets.csv"
ROWS, CHOSEN, SEED = 37, 20, 1


def tiago() -> tuple[KinematicChain, MeasurementSet, MeasurementSet]:
    """TIAGo's arm to its wrist tool link, the training day and the held-out day."""
    chain = KinematicChain.from_urdf(example_robot_data_urdf("tiago_description/robots/tiago.urdf"),
                                     "wrist_ft_tool_link")
    train, _ = read_measurements(TRAIN, chain.joint_specs)
    held_out, _ = read_measurements(HELD_OUT, chain.joint_specs)
    return chain, train, held_out


def heldout_rms(chain: KinematicChain, train: MeasurementSet, held_out: MeasurementSet, rows) -> float:
    """Calibrate on the training rows ``rows`` (level full, every identifiable parameter) and return
    marker 1's position RMS on the held-out day [mm]."""
    result = calibrate_chain(chain, train.select(np.sort(np.asarray(rows))), "full", ChainFitOptions(selection="all"))
    with chain.placed(result.chain_placements):
        errors = pose_errors(chain, held_out, result.target.registration, result.target.registration,
                             points=result.target.points)
    return errors.point(0).rms


def random_subsets(count: int) -> list[np.ndarray]:
    """The seeded random subsets, each sorted (row indices of the training file, 0-based)."""
    rng = np.random.default_rng(SEED)
    return [np.sort(rng.choice(ROWS, CHOSEN, replace=False)) for _ in range(count)]


def read_reference(path: Path = REFERENCE) -> tuple[list[np.ndarray], np.ndarray]:
    """The subsets and their held-out RMS [mm] as this script wrote them."""
    with open(path, newline="") as handle:
        records = list(csv.DictReader(handle))
    return ([np.array([int(i) for i in r["rows"].split()]) for r in records],
            np.array([float(r["heldout_marker1_rms_mm"]) for r in records]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--count", type=int, default=1000, help="random subsets (default 1000)")
    parser.add_argument("--out", type=Path, default=REFERENCE, help="the CSV written (default: the test's file)")
    args = parser.parse_args(argv)
    chain, train, held_out = tiago()
    subsets = random_subsets(args.count)
    temporary = args.out.with_name(args.out.name + ".part")
    with open(temporary, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["rows", "heldout_marker1_rms_mm"])
        for rows in subsets:
            writer.writerow([" ".join(map(str, rows)), repr(heldout_rms(chain, train, held_out, rows))])
    temporary.replace(args.out)
    print(f"{args.count} subsets -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
