"""What ``--level auto`` chooses, and the held-out error of every level beside it.

For each robot the level is chosen by cross-validation on the calibration data
only (:func:`pincal.choose_level`, :func:`pincal.choose_fixture_level`); every
level and the chosen one are then fitted on all calibration data and evaluated
on data the choice never saw:

* **TIAGo** (data/tiago_mocap): calibrate on 2021-11-30, evaluate on 2021-11-26
  (RMS of marker 1 [mm], as examples/tiago_mocap.py; the training session's
  registration, as there). 37 of the 62 held-out rows repeat a training posture
  (same joint readings to 0.02 rad): the error on the other 25 is given too.
* **MUKCa iiwa 14 and Panda** (data/mukca): calibrate on two placements, evaluate
  on the third, each in turn, as examples/mukca.py; auto chooses by
  leave-one-placement-out on the two; consistency / distortion on the third [mm].
* **Simulated UR5 and Panda** (example-robot-data): joint zeros off by
  N(0, 1 mrad), every other placement coordinate by N(0, 0.1 mm) / N(0, 0.1 mrad),
  unmodelled joint compliance (5e-6 rad/N·m on the shoulder and elbow joints), a
  laser tracker of 0.05 mm per axis on one point of the flange; a sparse (12
  rows) and a rich (100 rows) set of random configurations; evaluated against
  the truth on 200 other configurations (RMS [mm]); 10 seeds each.

Nothing is tuned to the evaluation data.

``--select`` is the selection within each level (default aic; ``prior``: the
MAP fit with physical priors of pincal.fit.prior), used by auto's cross-validation
fits and by the fixed levels alike.

Run:  python examples/level_auto.py [--case tiago|iiwa14|panda|sim] [--seeds N] [--first-seed S]
                                   [--select aic|bic|press|all|prior]
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from pincal import (
    ChainFitOptions,
    JointOffsets,
    KinematicChain,
    PlacementErrors,
    calibrate_chain,
    calibrate_fixture,
    choose_fixture_level,
    choose_level,
    fixture_metrics,
    pose_errors,
    read_fixture,
    read_fixture_data,
    read_measurements,
)
from pincal.model.effects import parse_effect
from pincal.robots import example_robot_data_urdf
from pincal.simulation.sensor import (
    DEFAULT_REGISTRATION,
    SimulatedEffects,
    SimulatedSensor,
    measure,
    random_configurations,
)

# the folder above examples/: a clone, or where `pincal example NAME --out data` put data/ (absolute, not
# resolved: a clone's examples/ is a link into pincal/datasets/)
ROOT = Path(__file__).absolute().parent.parent
LEVELS = ("registration", "offsets", "full")
#: Auto may be worse than the best fixed level by this factor (the bound --level auto is held to).
MARGIN = 1.10
#: The selection within each level (--select).
SELECT = {"selection": "aic"}


def _fixed_and_auto(held: dict[str, float], chosen: str) -> str:
    best = min(held.values())
    cells = " | ".join(f"{held[level]:.3f}" for level in LEVELS)
    return f"{cells} | {chosen} | {held[chosen]:.3f} | {held[chosen] / best:.2f}"


# --- TIAGo ---------------------------------------------------------------------------------------


def tiago() -> str:
    data = ROOT / "data" / "tiago_mocap"
    urdf = example_robot_data_urdf("tiago_description/robots/tiago.urdf")
    chain = KinematicChain.from_urdf(urdf, "wrist_ft_tool_link")
    train, _ = read_measurements(data / "qualisys_2021-11-30_static_postures.csv", chain.joint_specs)
    test, _ = read_measurements(data / "qualisys_2021-11-26_static_postures.csv", chain.joint_specs)
    novel = np.abs(test.q[:, None, :] - train.q[None, :, :]).max(axis=2).min(axis=1) > 0.02
    started = time.perf_counter()
    choice = choose_level(chain, train, ChainFitOptions(**SELECT))
    seconds = time.perf_counter() - started
    # other deals of the folds
    others = [choose_level(chain, train, ChainFitOptions(**SELECT), seed=seed) for seed in range(1, 6)]
    held, held_novel, kept = {}, {}, {}
    for level in LEVELS:
        result = calibrate_chain(chain, train, level, ChainFitOptions(**SELECT))
        registration = result.target.registration
        with chain.placed(result.chain_placements):
            errors = pose_errors(chain, test, registration, registration, points=result.target.points)
        marker1 = errors.position_m[:, 0] * 1000.0
        held[level] = float(np.sqrt(np.mean(marker1**2)))
        held_novel[level] = float(np.sqrt(np.mean(marker1[novel] ** 2)))
        kept[level] = len(result.kept)
    lines = [_cv_table(choice), "",
             f"chosen: {choice.chosen} ({seconds:.1f} s); with fold seeds 1-5: chosen "
             + ", ".join(c.chosen for c in others) + "; lowest CV " + ", ".join(c.lowest for c in others), "",
             "marker-1 RMS on 2021-11-26 [mm]; auto = one-SE rule (seed 0), lowest = lowest CV error:", "",
             "| rows | registration | offsets | full | auto chose | auto | auto / best | lowest | lowest / best |",
             "|---|---|---|---|---|---|---|---|---|",
             f"| all 62 | {_fixed_and_auto(held, choice.chosen)} | {_ratio(held, choice.lowest)} |",
             f"| 25 novel postures | {_fixed_and_auto(held_novel, choice.chosen)} | "
             f"{_ratio(held_novel, choice.lowest)} |"]
    return "\n".join(lines)


def _ratio(held: dict[str, float], level: str) -> str:
    return f"{held[level]:.3f} | {held[level] / min(held.values()):.2f}"


def _cv_table(choice) -> str:
    rule = "richest" if choice.selection == "prior" else "simplest"
    head = (f"{choice.scheme}; rule: {rule} level within one standard error; lowest {choice.lowest}, "
            f"chosen {choice.chosen}")
    rows = [f"| {s.level} | {s.cv_error_mm:.3f} ± {s.standard_error_mm:.3f} | "
            + " ".join(f"{e:.2f}" for e in s.fold_errors_mm) + " |" for s in choice.scores]
    return "\n".join([head, "", "| level | CV error ± SE [mm] | folds [mm] |", "|---|---|---|", *rows])


# --- MUKCa ---------------------------------------------------------------------------------------

MUKCA = {
    "iiwa14": ("urdf/iiwa14.urdf", "kuka_14", ("front", "left_back", "raised_left"), "tool0"),
    "panda": ("urdf/panda.urdf", "panda_1", ("back-high", "front", "right"), "panda_link8"),
}


def mukca(robot: str) -> str:
    data = ROOT / "data" / "mukca"
    relative, folder, placements, tip = MUKCA[robot]
    urdf = data / relative  # the data's own URDFs
    fixture = read_fixture(data / "fixture.csv")
    lines = [("| held-out placement | inner CV [mm]: registration / offsets / full | auto chose | "
             "registration | offsets | full | auto |"), "|---|---|---|---|---|---|---|"]
    sums = {level: [] for level in (*LEVELS, "auto")}
    for held in placements:
        chain = KinematicChain.from_urdf(urdf, tip)
        train = read_fixture_data([data / folder / f"{p}.csv" for p in placements if p != held],
                                  chain.joint_specs, fixture)
        test = read_fixture_data([data / folder / f"{held}.csv"], chain.joint_specs, fixture)
        choice = choose_fixture_level(chain, train, **SELECT)
        metrics = {}
        for level in LEVELS:
            result = calibrate_fixture(chain, train, level, **SELECT)
            with chain.placed(result.chain_placements):
                after = fixture_metrics(chain, test, result.ball)
            metrics[level] = (after.consistency_mm, after.distortion_mm)
        metrics["auto"] = metrics[choice.chosen]
        for key, value in metrics.items():
            sums[key].append(value)
        cv = " / ".join(f"{s.cv_error_mm:.3f}" for s in choice.scores)
        cells = " | ".join(f"{metrics[k][0]:.3f} / {metrics[k][1]:.3f}" for k in (*LEVELS, "auto"))
        lines.append(f"| {held} | {cv} | {choice.chosen} (lowest CV: {choice.lowest}) | {cells} |")
    means = {k: np.mean(v, axis=0) for k, v in sums.items()}
    lines.append("| **mean** | | | " + " | ".join(f"**{means[k][0]:.3f} / {means[k][1]:.3f}**"
                                                for k in (*LEVELS, "auto")) + " |")
    for i, what in enumerate(("consistency", "distortion")):
        best = min(means[level][i] for level in LEVELS)
        lines.append(f"\nauto / best fixed level, mean {what}: {means['auto'][i] / best:.2f}")
    return "\n".join(lines)


# --- simulated arms ------------------------------------------------------------------------------

SIMULATED = {
    "ur5": ("ur_description/urdf/ur5_robot.urdf", "tool0", ("shoulder_lift_joint", "elbow_joint")),
    "panda": ("panda_description/urdf/panda.urdf", "panda_link8", ("panda_joint2", "panda_joint4")),
}
FLANGE_POINT = np.array([[0.02, 0.01, 0.05]])  # the tracker's reflector on the flange [m]
SIGMA_M = 0.05e-3


def simulated_case(robot: str, rows: int, seed: int) -> tuple[dict[str, float], str, str]:
    """Held-out RMS of each level and the level auto chose, for one seed."""
    relative, tip, stiff = SIMULATED[robot]
    chain = KinematicChain.from_urdf(example_robot_data_urdf(relative), tip)
    nominal = chain.placements()
    rng = np.random.default_rng(1000 + seed)
    offsets = JointOffsets(chain)
    offsets.apply(rng.normal(0.0, 1e-3, offsets.size))
    placements = PlacementErrors(chain)
    placements.apply(rng.normal(0.0, 1e-4, placements.size))
    effects = [parse_effect(f"compliance:{joint}:5e-6") for joint in stiff]
    q_train = random_configurations(chain, rng, rows)
    q_test = random_configurations(chain, rng, 200)
    sensor, compliance = SimulatedSensor(SIGMA_M, 0.0, FLANGE_POINT, with_rotation=False), SimulatedEffects(effects)
    train = measure(chain, q_train, DEFAULT_REGISTRATION, rng, sensor, "calibration", compliance)
    test = measure(chain, q_test, DEFAULT_REGISTRATION, rng, replace(sensor, sigma_pos_m=0.0), "calibration",
                   compliance)
    chain.set_placements(nominal)  # the nominal robot is what is calibrated
    choice = choose_level(chain, train, ChainFitOptions(**SELECT))
    held = {}
    for level in LEVELS:
        result = calibrate_chain(chain, train, level, ChainFitOptions(**SELECT))
        registration = result.target.registration
        with chain.placed(result.chain_placements):
            errors = pose_errors(chain, test, registration, registration, points=result.target.points)
        held[level] = float(np.sqrt(np.mean(errors.position_m**2)) * 1000.0)
    return held, choice.chosen, choice.lowest


def simulated(seeds: int, first: int = 0) -> str:
    lines = [("| arm, rows | registration | offsets | full | auto chose (seeds) | auto | auto / best (mean) | "
             "seeds auto > 1.1 × best | lowest CV: mean, / best, seeds > 1.1 × best |"),
             "|---|---|---|---|---|---|---|---|---|"]
    for robot in SIMULATED:
        for rows in (12, 100):
            runs = [simulated_case(robot, rows, seed) for seed in range(first, first + seeds)]
            held = {level: np.mean([r[0][level] for r in runs]) for level in LEVELS}
            auto = np.mean([r[0][r[1]] for r in runs])
            best = min(held.values())
            worse = sum(r[0][r[1]] > MARGIN * min(r[0].values()) for r in runs)
            chosen = ", ".join(f"{level} {sum(r[1] == level for r in runs)}" for level in LEVELS
                               if any(r[1] == level for r in runs))
            lowest = np.mean([r[0][r[2]] for r in runs])
            lowest_worse = sum(r[0][r[2]] > MARGIN * min(r[0].values()) for r in runs)
            lines.append(f"| {robot}, {rows} | " + " | ".join(f"{held[level]:.3f}" for level in LEVELS)
                         + f" | {chosen} | {auto:.3f} | {auto / best:.2f} | {worse} of {seeds} | "
                         f"{lowest:.3f}, {lowest / best:.2f}, {lowest_worse} of {seeds} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", choices=("tiago", "iiwa14", "panda", "sim"), action="append",
                        help="default: all")
    parser.add_argument("--seeds", type=int, default=10, help="seeds per simulated case (default 10)")
    parser.add_argument("--first-seed", type=int, default=0, help="first simulated seed (default 0)")
    parser.add_argument("--select", choices=("aic", "bic", "press", "all", "prior"), default="aic",
                        help="selection within each level (default aic; prior: pincal.fit.prior's MAP fit)")
    args = parser.parse_args(argv)
    SELECT["selection"] = args.select
    for case in args.case or ("tiago", "iiwa14", "panda", "sim"):
        started = time.perf_counter()
        if case == "tiago":
            text = tiago()
        elif case == "sim":
            text = simulated(args.seeds, args.first_seed)
        else:
            text = mukca(case)
        print(f"\n## {case} ({time.perf_counter() - started:.0f} s)\n\n{text}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
