"""Calibrate the KUKA LBR iiwa 14 and the Franka Panda without a sensor (MUKCa socket data).

For each robot, calibrate on two of the three fixture placements and evaluate
on the third (each placement held out in turn): the consistency (RMS spread
of the computed ball centre within a socket) and the distortion (error of the
computed socket distance against the fixture's 50 mm) on the held-out
placement, before (nominal URDF, ball centre fitted to it on the same two
placements) and after, at the levels offsets and full. Nothing is tuned to the
held-out placement: it is read only to be evaluated. Data, URDF and
provenance in data/mukca/ (README there). The iiwa is calibrated twice: from
the data's own URDF and from a URDF built from its DH table
(data/mukca/iiwa14_dh.csv) by ``pincal urdf-from-dh``.

Run:  python examples/mukca.py [--robot iiwa14|iiwa14_dh|panda] [--level offsets|full]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from pincal import (
    KinematicChain,
    calibrate_fixture,
    fixture_metrics,
    read_fixture,
    read_fixture_data,
)
from pincal.model.dh.conversion import urdf_from_dh_table

# data/ beside examples/: a clone's, or `pincal example NAME` (absolute: a clone's examples/ is a link)
DATA = Path(__file__).absolute().parent.parent / "data" / "mukca"
LEVELS = ("offsets", "full")
#: robot → (folder of placement files, placements, tip link)
ROBOTS = {
    "iiwa14": ("kuka_14", ("front", "left_back", "raised_left"), "tool0"),
    "iiwa14_dh": ("kuka_14", ("front", "left_back", "raised_left"), "flange"),
    "panda": ("panda_1", ("back-high", "front", "right"), "panda_link8"),
}


def urdf_of(robot: str, folder: Path) -> Path:
    """The nominal URDF of ``robot``; the DH one is written into ``folder``."""
    if robot in ("iiwa14", "panda"):  # the data's own URDFs
        return DATA / "urdf" / f"{robot}.urdf"
    out = folder / "iiwa14_dh.urdf"
    urdf_from_dh_table(DATA / "iiwa14_dh.csv", "standard", out)  # what pincal urdf-from-dh runs
    return out


def held_out(robot: str, urdf: Path, level: str, held: str, selection: str = "aic") -> dict:
    """Calibrate on the placements other than ``held`` (``selection``: ``--select``); metrics on ``held`` [mm]."""
    folder, placements, tip = ROBOTS[robot]
    fixture = read_fixture(DATA / "fixture.csv")
    chain = KinematicChain.from_urdf(urdf, tip)
    train = read_fixture_data([DATA / folder / f"{p}.csv" for p in placements if p != held],
                              chain.joint_specs, fixture)
    test = read_fixture_data([DATA / folder / f"{held}.csv"], chain.joint_specs, fixture)
    started = time.perf_counter()
    result = calibrate_fixture(chain, train, level, selection=selection)
    seconds = time.perf_counter() - started
    with chain.placed(result.chain_placements):
        after = fixture_metrics(chain, test, result.ball)
    before = fixture_metrics(KinematicChain.from_urdf(urdf, tip), test, result.nominal_ball)
    return {
        "held": held,
        "before": (before.consistency_mm, before.distortion_mm),
        "after": (after.consistency_mm, after.distortion_mm),
        "train_after": (result.training.consistency_mm, result.training.distortion_mm),
        "kept": len(result.kept),
        "identifiable": result.rank,
        "seconds": seconds,
    }


def robot_rows(robot: str, urdf: Path, levels=LEVELS) -> dict[str, list[dict]]:
    """Every held-out choice at every level."""
    return {level: [held_out(robot, urdf, level, held) for held in ROBOTS[robot][1]] for level in levels}


def table(robot: str, rows: dict[str, list[dict]]) -> str:
    """Markdown: held-out placement, before, then after per level (consistency / distortion, mm)."""
    levels = list(rows)
    head = "| held-out placement | nominal: consistency / distortion | " + " | ".join(
        f"{level} ({rows[level][0]['identifiable']} identifiable): consistency / distortion" for level in levels) + " |"
    lines = [head, "|" + "---|" * (2 + len(levels))]
    first = rows[levels[0]]
    for i, entry in enumerate(first):
        cells = [f"{entry['before'][0]:.3f} / {entry['before'][1]:.3f}"]
        cells += [f"{rows[level][i]['after'][0]:.3f} / {rows[level][i]['after'][1]:.3f} "
                  f"({rows[level][i]['kept']} kept)" for level in levels]
        lines.append(f"| {entry['held']} | " + " | ".join(cells) + " |")
    mean = [np.mean([e["before"] for e in first], axis=0)] + [np.mean([e["after"] for e in rows[level]], axis=0)
                                                              for level in levels]
    lines.append("| **mean** | " + " | ".join(f"**{m[0]:.3f} / {m[1]:.3f}**" for m in mean) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", choices=tuple(ROBOTS), action="append", help="default: all")
    parser.add_argument("--level", choices=LEVELS, action="append", help="default: both")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as folder:
        for robot in args.robot or ROBOTS:
            started = time.perf_counter()
            rows = robot_rows(robot, urdf_of(robot, Path(folder)), tuple(args.level or LEVELS))
            print(f"\n{robot} (consistency / distortion on the held-out placement [mm]; "
                  f"{time.perf_counter() - started:.1f} s)\n")
            print(table(robot, rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
