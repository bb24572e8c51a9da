"""Calibrate the TIAGo arm on real motion-capture data and compare with FIGAROH.

Train on the 2021-11-30 Qualisys session, validate on 2021-11-26 (data and
provenance in data/tiago_mocap/), with tiago.urdf from example-robot-data and
the chain base_footprint → wrist_ft_tool_link (torso lift + 7 arm joints).
pincal fits all four markers as one rigid target; the table reports the RMS
position error of marker 1, as FIGAROH's reference does.

Run:  python examples/tiago_mocap.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from pincal import ChainFitOptions, KinematicChain, calibrate_chain, pose_errors, read_measurements
from pincal.robots import example_robot_data_urdf

# data/ beside examples/: a clone's, or `pincal example NAME` (absolute: a clone's examples/ is a link)
DATA = Path(__file__).absolute().parent.parent / "data" / "tiago_mocap"
TRAIN = DATA / "qualisys_2021-11-30_static_postures.csv"
HELD_OUT = DATA / "qualisys_2021-11-26_static_postures.csv"
TIP = "wrist_ft_tool_link"

#: FIGAROH 1.0.2 on the same split, marker 1 only (data/tiago_mocap/README.md):
#: (parameters, train RMS mm, held-out RMS mm).
FIGAROH = {"registration": (9, 3.36, 4.44), "offsets": (14, 2.88, 4.13), "full": (30, 1.68, 3.22)}


def run_level(level: str, selection: str = "prior") -> dict:
    """Calibrate at ``level`` with ``selection`` (``pincal calibrate``'s default: prior; the API's: aic);
    marker-1 RMS errors on both sessions [mm] and timings."""
    chain = KinematicChain.from_urdf(example_robot_data_urdf("tiago_description/robots/tiago.urdf"), TIP)
    train, _ = read_measurements(TRAIN, chain.joint_specs)
    held_out, _ = read_measurements(HELD_OUT, chain.joint_specs)
    started = time.perf_counter()
    options = ChainFitOptions(selection=selection if level != "registration" else "aic")
    result = calibrate_chain(chain, train, level, options)
    seconds = time.perf_counter() - started
    registration, points = result.target.registration, result.target.points

    def marker1_rms(data) -> float:
        with chain.placed(result.chain_placements):
            errors = pose_errors(chain, data, registration, registration, points=points)
        return errors.point(0).rms

    kinematic = int(sum(s == "calibrated" for s in result.status))
    n_target = 6 + points.size
    return {
        "level": level,
        "parameters": kinematic + n_target,
        "kinematic": kinematic,
        "identifiable": result.rank,
        "train_mm": marker1_rms(train),
        "held_out_mm": marker1_rms(held_out),
        "fit_ms": result.fit_seconds * 1000.0,
        "total_ms": seconds * 1000.0,
        "outliers": [line for line, _ in result.outliers],
    }


def main() -> int:
    rows = [run_level(level) for level in ("registration", "offsets", "full")]
    aic = {level: run_level(level, "aic") for level in ("offsets", "full")}
    print(f"{'level':13s} {'pincal: params':>14s} {'train':>7s} {'held-out':>9s} {'(AIC)':>7s} {'fit':>8s} "
          f"{'| FIGAROH: params':>17s} {'train':>7s} {'held-out':>9s}")
    for row in rows:
        n, train, held = FIGAROH[row["level"]]
        other = f"{aic[row['level']]['held_out_mm']:7.2f}" if row["level"] in aic else f"{'':7s}"
        print(f"{row['level']:13s} {row['parameters']:14d} {row['train_mm']:7.2f} {row['held_out_mm']:9.2f} {other} "
              f"{row['fit_ms']:6.0f}ms | {n:15d} {train:7.2f} {held:9.2f}")
    print("RMS of marker-1 position error in mm; pincal fits all four markers as one rigid target "
          "(params = kinematic + registration 6 + 12 marker coordinates) and keeps every identifiable "
          "parameter under physical priors (pincal calibrate's default, --select prior); (AIC): held-out "
          "with the subset AIC keeps (--select aic).")
    for row in rows:
        if row["outliers"]:
            print(f"{row['level']}: rows reported as outliers at lines {row['outliers']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
