"""What ``pincal simulate``, ``demo`` and ``study`` print: the commands of the paper's experiment
(Franaszek & Marvel 2022) and its simulation study, over :mod:`pincal.workflows.simulation`,
:mod:`pincal.workflows.demo` and :mod:`pincal.study.run`."""

from __future__ import annotations

import argparse

from pincal.cli.error_table import HEADER, error_columns

__all__ = ["simulate_command", "demo_command", "study_command"]


def simulate_command(args: argparse.Namespace) -> int:
    import numpy as np

    from pincal.simulation.paper import SimulationSettings
    from pincal.workflows.simulation import simulate_to_directory

    settings = SimulationSettings(sigma_pos_mm=args.sigma_pos, sigma_rot_deg=args.sigma_rot, seed=args.seed)
    experiment, truth = simulate_to_directory(args.out, args.deviations, settings, effects=args.effect)
    print(f"wrote {args.out / 'calibration.csv'} ({experiment.calibration.n_rows} rows: "
          f"{int(np.sum(experiment.calibration.roles == 'cpa'))} cpa, "
          f"{int(np.sum(experiment.calibration.roles == 'calibration'))} calibration)")
    print(f"wrote {args.out / 'validation.csv'} ({experiment.validation.n_rows} rows)")
    print(f"wrote {args.out / 'truth.json'}")
    print(f"next: {truth['calibrate_command']}")
    return 0


def demo_command(args: argparse.Namespace) -> int:
    from pincal.simulation.paper import SimulationSettings
    from pincal.workflows.demo import run_demo

    settings = SimulationSettings(sigma_pos_mm=0.055, sigma_rot_deg=0.055, seed=args.seed)
    print("KUKA LWR 4+ (Table 1), ground truth = Table 1 + large deviations (Table 2),")
    print(f"sensor noise sigma_p = {settings.sigma_pos_mm} mm, sigma_a = {settings.sigma_rot_deg} deg, "
          f"K = {settings.n_calibration} calibration + {settings.n_cpa} CPA rows per joint, "
          f"J = {settings.n_validation} held-out rows, seed {settings.seed}")
    rows = run_demo(args.out, settings)
    print()
    print("errors on held-out rows (eq 24; positions through Registration 1, orientations through Registration 2)")
    print(HEADER + f" {'fit [ms]':>9s}")
    for row in rows:
        timing = f" {row.seconds * 1000:9.1f}" if row.seconds else f" {'-':>9s}"
        print(f"{row.label:24s} {error_columns(row.validation)}{timing}")
    print()
    print(f"corrected URDFs, reports and data in {args.out}/ "
          f"(kuka_lwr4plus_method2.urdf is the paper's recommended calibration)")
    return 0


def study_command(args: argparse.Namespace) -> int:
    from pincal.cli.progress import progress_bar
    from pincal.study.checkpoints import CHECKPOINT_FOLDER, TaskStore
    from pincal.study.run import StudyConfig, run_study, write_study
    from pincal.workflows.paths import ensure_directory

    ensure_directory(args.out)  # before the run, not after it
    config = StudyConfig(levels=args.levels, repeats=args.reps, restarts=args.restarts,
                         limit_pose_sets=args.limit_pose_sets)
    checkpoints = args.out / CHECKPOINT_FOLDER  # finished tasks: a rerun after a crash resumes from them
    with progress_bar("study tasks", quiet=args.quiet) as progress:
        result = run_study(config, workers=args.workers, scheduler=args.scheduler, progress=progress,
                           checkpoints=checkpoints)
    paths = write_study(result, args.out, workers=args.workers)  # figures drawn by as many processes
    TaskStore(checkpoints).clear()
    print(f"{len(result.rows)} rows from {config.levels} noise levels x {config.repeats} repeats x "
          f"{len(config.deviations)} deviation sets, {sum(r['starts'] for r in result.restart_summary)} restarts; "
          f"{result.wall_s:.1f} s on {result.executor}")
    print()
    for finding in result.findings:
        print(f"{'holds' if finding['holds'] else 'FAILS':5s}  {finding['finding']}: {finding['evidence']}")
    print()
    for name in ("study", "summary", "restarts", "findings", "json"):
        print(f"wrote {paths[name]}")
    print(f"wrote {len(paths['figures'])} figures in {args.out}/")
    return 0
