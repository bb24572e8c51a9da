"""``pincal plan``: what it prints — the choice, the prediction against random choices, what is
identifiable and the visiting order (the planning itself: :func:`pincal.workflows.preparation.plan_files`)."""

from __future__ import annotations

import argparse
import sys

from pincal.cli.arguments import selection_criterion

__all__ = ["run_plan", "run_camera_plan", "print_plan_summary", "print_candidates", "print_camera_plan"]


#: ``plan``'s flags of a camera, and those of a point sensor a camera's plan refuses (dest: the flag).
_CAMERA_FLAGS = {"board_link": "--board-link", "intrinsics": "--intrinsics", "board": "--board",
                 "board_pose": "--board-pose"}
_SENSOR_FLAGS = {"tip_link": "--tip-link", "report": "--report", "tool": "--tool", "measure": "--measure",
                 "target_points": "--target-points", "workspace": "--workspace", "select": "--select",
                 "sigma_pos": "--sigma-pos", "sigma_rot": "--sigma-rot", "min_distance": "--min-distance",
                 "coupling": "--coupling", "alternate": "--alternate"}


def run_plan(args: argparse.Namespace) -> int:
    """``pincal plan``: choose, write PLAN.csv and PLAN.json, print the summary; the exit code."""
    from pincal.cli.camera import refuse_camera_data
    from pincal.cli.progress import progress_bar
    from pincal.errors import PincalError
    from pincal.model.tree import parse_targets
    from pincal.planning.defaults import DEFAULT_SAMPLE
    from pincal.planning.planner import PlanSettings
    from pincal.workflows.preparation import PlanInputs, plan_files

    if args.camera_link is not None:
        return run_camera_plan(args)
    given = [flag for dest, flag in _CAMERA_FLAGS.items() if getattr(args, dest) is not None]
    if given:
        raise PincalError(f"{given[0]} is a camera's: give --camera-link LINK to plan a camera's images")
    refuse_camera_data(args.existing or [], "--camera-link LINK (the camera's optical frame), --intrinsics FILE and "
                       "--board SPEC")
    if args.report is None:
        raise PincalError("plan: give --report PLAN.json (the prediction to write)")
    args.sample = DEFAULT_SAMPLE if args.sample is None else args.sample

    settings = PlanSettings(count=args.count, level=args.level, sensor=args.measure, criterion=args.criterion,
                            sigma_pos_mm=args.sigma_pos, sigma_rot_deg=args.sigma_rot, target_points=args.target_points,
                            tool_known=args.tool is not None, seed=args.seed, alternate=args.alternate,
                            selection=selection_criterion(args))
    inputs = PlanInputs(tool_pose=args.tool, candidates_path=args.candidates, sample=args.sample,
                        existing_path=args.existing, workspace_path=args.workspace, min_distance_m=args.min_distance,
                        collision_check=not args.no_collision_check, xacro_args=args.xacro_args,
                        package_dirs=dict(args.package_dir), couplings=args.coupling or (), srdf=args.srdf)
    # several --tip-link LINK:POINTS: the tree of their chains (one string: one chain, as ever)
    tip_link = args.tip_link if isinstance(args.tip_link, str) else parse_targets(args.tip_link)
    with progress_bar("plan", quiet=args.quiet, unit="step") as progress:
        run = plan_files(args.urdf, tip_link, settings, args.out, args.report, inputs, progress=progress)
    for note in run.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    print_plan_summary(run)
    print(f"wrote {args.out}\nwrote {args.report}")
    return 0


def print_plan_summary(run) -> None:
    """The choice, the prediction against random, identifiability and the visiting order."""
    plan, doc = run.plan, run.document
    settings = doc["settings"]
    print(f"chose {len(plan.q)} of {run.n_candidates} candidates for criterion {plan.criterion} "
          f"(level {settings['level']}, measure {settings['measure']}, noise {plan.sigma_pos_mm:.4g} mm"
          + ("" if plan.sigma_rot_deg is None else f", {plan.sigma_rot_deg:.4g} deg")
          + f", {plan.sigma_source}); {plan.swaps} exchange swaps, {plan.seconds:.2f} s")
    print_candidates(run)
    others = len(plan.estimated) - len(plan.identifiable)
    shown = ", ".join(plan.not_identifiable[:6]) + (", ..." if len(plan.not_identifiable) > 6 else "")
    print(f"identifiable: {len(plan.identifiable)} kinematic parameters (+ {others} registration/target); "
          f"not identifiable: {len(plan.not_identifiable)}" + (f" ({shown})" if shown else ""))

    def errors(p) -> str:
        if p is None:
            return "not determined"
        text = f"mean {p.mean_position_mm:.4g} mm, max {p.max_position_mm:.4g} mm"
        if p.mean_rotation_deg is not None:
            text += f"; orientation mean {p.mean_rotation_deg:.4g} deg, max {p.max_rotation_deg:.4g} deg"
        return text + f" (condition {p.condition:.3g})"

    print(f"predicted error, plan:   {errors(plan.prediction)}")
    print(f"predicted error, random: {errors(plan.random)} [median of {plan.settings.random_draws} draws, "
          f"{plan.random_singular} not determining the parameters]")
    ratio = doc["predicted"]["plan_over_random_mean_position"]
    if ratio is not None:
        print(f"plan / random mean position error: {ratio:.2f}")
    for target in plan.targets:  # several --tip-link: each target's share

        def mean(values) -> str:
            return "not determined" if values is None else f"mean {values[0]:.4g} mm, max {values[1]:.4g} mm"

        name = f"{target.link} ({','.join(map(str, target.points))})"
        print(f"  {name}: plan {mean(target.plan)}; random {mean(target.random)}")
    if plan.recorded is not None:
        print(f"recorded rows alone: {errors(plan.recorded)}")
        for entry in doc["additions"][:10]:
            if entry["predicted_mean_mm"] is not None:
                gain = "" if entry["gain_mm"] is None else f" (gain {entry['gain_mm']:.4g} mm)"
                print(f"  add #{entry['priority']}: candidate {entry['candidate']} -> "
                      f"{entry['predicted_mean_mm']:.4g} mm{gain}")
    order = doc["order"]
    print(f"order: {order['method']}, {plan.travel_s:.1f} s of moves at the velocity limits")
    for balance in plan.balance:
        if balance.joint in order["alternate"]:
            corr = "n/a" if balance.correlation is None else f"{balance.correlation:+.2f}"
            print(f"  {balance.joint}: {balance.from_below} from below, {balance.from_above} from above, "
                  f"flank-position correlation {corr}")


def print_candidates(run) -> None:
    """Each joint's range of the candidates and where it comes from, and what the collision check refused."""
    sample = run.document["settings"]["sample"]
    print(f"candidates: {run.n_candidates} " + (f"drawn uniformly (seed {run.plan.settings.seed}) within:"
                                                 if sample is not None else "read from the file, spanning:"))
    width = max((len(r.joint) for r in run.ranges), default=0)
    for r in run.ranges:
        print(f"  {r.joint:<{width}}  {r.lower:9.2f} .. {r.upper:8.2f} {r.unit}  ({r.source})")
    if run.clearance is not None:
        c = run.clearance
        closer = "" if c.min_distance_m == 0.0 else f", {c.too_close} closer than {c.min_distance_m:g} m"
        ignored = "in contact" if c.min_distance_m == 0.0 else "closer"
        skipped = c.srdf_words() or f"{len(c.pairs_ignored)} ignored as {ignored} at the zero configuration"
        print(f"refused {c.in_collision + c.too_close} of {run.n_candidates} candidates: {c.in_collision} in "
              f"self-collision{closer} ({c.pairs_checked} link pairs checked, {skipped})")
    elif run.collision_check == "off":
        print("not checked for self-collision (--no-collision-check)")


def run_camera_plan(args: argparse.Namespace) -> int:
    """``pincal plan --camera-link``: choose the images, write PLAN.csv, print the summary; the exit code."""
    from pincal.cli.progress import progress_bar
    from pincal.errors import PincalError
    from pincal.planning.camera_plan import CameraPlanSettings
    from pincal.planning.defaults import DEFAULT_AIMED
    from pincal.workflows.camera_plan import CameraPlanInputs, camera_plan_files

    given = [flag for dest, flag in _SENSOR_FLAGS.items()
             if getattr(args, dest) is not None and not (isinstance(getattr(args, dest), (list, tuple))
                                                         and not getattr(args, dest))]
    if given:
        raise PincalError(f"{given[0]} is a point sensor's: a camera's plan (--camera-link) writes PLAN.csv of "
                          "the images to take; leave it out")
    missing = [flag for flag, value in (("--intrinsics", args.intrinsics), ("--board", args.board)) if value is None]
    if missing:
        raise PincalError(f"plan --camera-link: give {' and '.join(missing)} (the camera's intrinsics file with its "
                          "image size; the board, as detect takes it)")
    existing = args.existing or []
    if len(existing) > 1:
        raise PincalError("--existing: a camera's plan continues one first run; give its one DATA.csv")
    settings = CameraPlanSettings(count=args.count, level=args.level, criterion=args.criterion, seed=args.seed)
    inputs = CameraPlanInputs(camera_link=args.camera_link, intrinsics_path=args.intrinsics, board=args.board,
                              board_link=args.board_link, board_pose=args.board_pose,
                              existing_path=existing[0] if existing else None, candidates_path=args.candidates,
                              sample=DEFAULT_AIMED if args.sample is None else args.sample,
                              collision_check=not args.no_collision_check, xacro_args=args.xacro_args,
                              package_dirs=dict(args.package_dir), srdf=args.srdf)
    with progress_bar("plan", quiet=args.quiet, unit="step") as progress:
        run = camera_plan_files(args.urdf, inputs, settings, args.out, progress=progress)
    for note in run.notes:
        print(f"pincal: note: {note}", file=sys.stderr)
    print_camera_plan(run)
    print(f"wrote {args.out}")
    return 0


def print_camera_plan(run) -> None:
    """The choice, the usable views, identifiability and the information and prediction against random."""
    plan, settings = run.plan, run.plan.settings
    limits = settings.limits
    print(f"chose {len(plan.q)} of {int(plan.usable.sum())} usable candidates ({run.n_candidates} in all; usable: "
          f"the whole board in the image, at most {limits.max_angle_deg:g} deg from facing the camera"
          f", corners at least {plan.min_spacing_px:.3g} px apart) for criterion "
          f"{settings.criterion} (level {settings.level}, {run.arrangement.replace('_', ' ')}, pixel noise "
          f"{settings.sigma_px:.3g} px); {plan.seconds:.2f} s")
    views = plan.views
    print(f"views: {views.angle_deg.min():.0f}-{views.angle_deg.max():.0f} deg from facing, board "
          f"{views.distance_m.min():.2f}-{views.distance_m.max():.2f} m away, corners at least "
          f"{views.spacing_px.min():.3g} px apart")
    others = len(plan.estimated) - len(plan.identifiable)
    shown = ", ".join(plan.not_identifiable[:6]) + (", ..." if len(plan.not_identifiable) > 6 else "")
    print(f"identifiable: {len(plan.identifiable)} kinematic parameters (+ {others} of the world frame, the mount"
          + (" and the intrinsics" if settings.intrinsics else "") + "); "
          f"not identifiable: {len(plan.not_identifiable)}" + (f" ({shown})" if shown else ""))
    print(f"ln det of the information: plan {plan.log_det:.4g}, random {plan.random_log_det:.4g} [median of "
          f"{settings.random_draws} draws of usable candidates]")
    what = "camera's optical centre" if run.arrangement == "eye_in_hand" else "board's origin"

    def errors(p) -> str:
        return "not determined" if p is None else f"mean {p.mean_position_mm:.4g} mm, max {p.max_position_mm:.4g} mm"

    print(f"predicted error of the {what}, plan:   {errors(plan.prediction)}")
    print(f"predicted error of the {what}, random: {errors(plan.random)} [{plan.random_singular} draws not "
          "determining the parameters]")
    print(f"order: short travel, {plan.travel_s:.1f} s of moves at the velocity limits")
