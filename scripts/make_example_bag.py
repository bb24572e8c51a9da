#!/usr/bin/env python3
"""Make the shipped example bag ``pincal/datasets/lwr_bag/`` (seeded: the same files every run).

    python scripts/make_example_bag.py                    # rewrites pincal/datasets/lwr_bag/session/ and validation.csv
    python scripts/make_example_bag.py --out /tmp/lwr_bag  # elsewhere (the folder must not exist)

A KUKA LWR 4+ whose geometry is the paper's Table 1 plus its small deviations (Table 2, as
``pincal simulate --deviations small`` makes it) visits 12 random postures, holding each 2.4 s,
moving between them in 0.9 s (:mod:`pincal.simulation.recording`); one stop lasts only 1 s, and
during another the motion-capture body is shaken (a 2 Hz, 2.5 mm wobble) while the joints hold.
The streams are those of a real cell, thinned to 50 Hz to keep the file under 200 kB:
``/joint_states`` from 20-bit encoders (readings rounded to 2π/2^20 rad, noise 3e-6 rad),
``/mocap/tool/pose`` (PoseStamped) with 0.05 mm and 0.006° of noise, float32 values as
motion-capture systems send them, stamped on the tracker's own clock 0.180 s ahead of the robot's,
and received 2 ms (joints) and 12 ms (tracker) later with jitter. Written as a rosbag2 folder with
MCAP storage and zstd chunks. ``validation.csv`` holds 20 other postures
as static rows (CSV v1, the same tracker noise averaged over 150 samples) for ``pincal evaluate``.
"""

from __future__ import annotations

import argparse
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np

from pincal.measurements.bags import write_bag
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.model.dh.table import KUKA_LWR4_DH, TABLE2_SMALL
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.paper import DEFAULT_TOOL_RPY, DEFAULT_TOOL_XYZ
from pincal.simulation.recording import RecordingSettings, RecordingTopics, SessionEvents, simulate_recording
from pincal.simulation.sensor import DEFAULT_REGISTRATION, SimulatedSensor, measure, random_configurations

ROOT = Path(__file__).resolve().parents[1]
SEED = 2024
POSTURES = 12
VALIDATION = 20
SHORT, SHAKEN = 5, 10  # the stop held 1 s, the stop whose target is shaken
SETTINGS = RecordingSettings(hold_s=2.4, move_s=0.9, joint_rate_hz=50.0, tracker_rate_hz=50.0, joint_noise=3e-6,
                             tracker_noise_m=5e-5, tracker_noise_rad=1e-4,
                             clock_offset_s=0.180, seed=SEED)
ENCODER_STEP = 2 * np.pi / 2**20  # rad


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "pincal" / "datasets" / "lwr_bag")
    args = parser.parse_args()
    tool = pose_from_xyz_rpy(DEFAULT_TOOL_XYZ, DEFAULT_TOOL_RPY)  # where the mocap body sits on the flange
    chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK, tool=tool)
    rng = np.random.default_rng(SEED)
    postures = random_configurations(chain, rng, POSTURES)
    held_out = random_configurations(chain, rng, VALIDATION)
    with chain.placed(TABLE2_SMALL.apply(KUKA_LWR4_DH).joint_origins()):
        recording = simulate_recording(chain, postures, DEFAULT_REGISTRATION, SETTINGS, pose=True,
                                       events=SessionEvents(holds={SHORT: 1.0}, shaken={SHAKEN: 0.0025}),
                                       topics=RecordingTopics(["/mocap/tool/pose"]))
        sigma = SETTINGS.tracker_noise_m / np.sqrt(150), SETTINGS.tracker_noise_rad / np.sqrt(150)
        validation = measure(chain, held_out, DEFAULT_REGISTRATION, rng, SimulatedSensor(*sigma), "validation")
    joints = recording.joints
    joints = replace(joints, positions=np.round(joints.positions / ENCODER_STEP) * ENCODER_STEP)
    pose = recording.measurements[0]
    assert pose.quaternions is not None
    pose = replace(pose, positions=pose.positions.astype(np.float32).astype(float),
                   quaternions=pose.quaternions.astype(np.float32).astype(float), frame="mocap")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.out == parser.get_default("out"):  # the shipped set is rewritten, byte for byte
        shutil.rmtree(args.out / "session", ignore_errors=True)
    elif (args.out / "session").exists():
        parser.error(f"{args.out / 'session'} exists; give a new --out")
    write_bag(args.out / "session", joints, [pose], "mcap", compress=True)
    write_measurements(args.out / "validation.csv", validation)
    size = sum(p.stat().st_size for p in (args.out / "session").iterdir())
    print(f"wrote {args.out / 'session'} ({size / 1024:.0f} kB, {len(joints.stamps)} joint readings, "
          f"{len(pose.stamps)} poses) and {args.out / 'validation.csv'} ({VALIDATION} rows)")


if __name__ == "__main__":
    main()
