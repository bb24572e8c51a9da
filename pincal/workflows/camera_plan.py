"""``pincal plan --camera-link``: the configurations to image a ChArUco board from, written as PLAN.csv.

Where the camera and the board are, roughly, is all a plan needs beside the URDF, the intrinsics and the
board:

* **eye in hand** (the camera's link on the chain): the board is fixed in the world; its pose in the root
  link's frame comes from ``board_pose`` (``--board-pose X,Y,Z,ROLL,PITCH,YAW``, OpenCV's board frame: the
  origin at the board's outer corner before corner 0, x along its columns, z out of its back), or from the
  images of a first run (``existing_path``, a DATA.csv of ``pincal detect``);
* **eye to hand** (the camera's link hangs from the root): the camera is where the URDF puts its link and
  the board where the URDF puts the board's link on the chain, or again where a first run's images put them.

With a first run its images are fitted at level ``registration`` (the start of
:func:`pincal.fit.camera_calibration.calibrate_camera`: solvePnP, OpenCV's hand-eye, then the mount and the
world frame refined by reprojection), their information counts, their reprojection RMS is the pixel noise
assumed, and the candidates are aimed from their configurations. The candidates — configurations aimed at
the board by inverse kinematics (:func:`pincal.planning.camera_views.aimed_configurations`) and as many drawn
within the joint limits, or those of a candidate file — are checked for self-collision as ``plan``'s are, and
the plan is chosen among the usable ones (:func:`pincal.planning.camera_plan.plan_camera_views`). PLAN.csv
has ``plan``'s columns: the joint columns, ``priority`` and ``candidate``; image the board at each row and
add an ``image`` column naming each file, and it is the JOINTS.csv of ``pincal detect --joints``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pincal.errors import ModelError, PincalError, expect_value
from pincal.fit.camera_calibration import calibrate_camera, image_sessions
from pincal.fit.camera_start import hand_eye_start
from pincal.fit.plausibility import GROSS_REACH_FRACTION, gross_misfit, reach_m
from pincal.measurements.camera_csv import CornerSet, read_corners
from pincal.measurements.charuco import parse_board
from pincal.model.camera_chain import camera_chain
from pincal.model.camera_info import check_image_size, read_intrinsics
from pincal.model.description import read_description
from pincal.planning.camera_plan import CameraPlan, CameraPlanSettings, plan_camera_views
from pincal.planning.camera_views import aimed_configurations
from pincal.planning.candidates import read_candidates, sample_candidates
from pincal.planning.collisions import check_clearance, has_collision_geometry
from pincal.planning.defaults import DEFAULT_AIMED
from pincal.planning.files import write_plan_csv
from pincal.progress import Progress, Stages
from pincal.residuals.camera import CameraEstimate
from pincal.workflows.camera_calibration import arrangement_words, misfit_m
from pincal.workflows.paths import description_inputs, refuse_overwrite
from pincal.workflows.preparation import refuse_srdf_unchecked

__all__ = ["CameraPlanInputs", "CameraPlanRun", "camera_plan_files"]

#: Seeds of the inverse kinematics drawn within the joint limits when no first run gives configurations.
_SEEDS = 20


@dataclass(frozen=True)
class CameraPlanInputs:
    """What ``pincal plan --camera-link`` reads beside the URDF (its flags).

    Attributes:
        camera_link: the link of the camera's optical frame (``--camera-link``).
        intrinsics_path: ROS camera_info or OpenCV YAML with the image size (``--intrinsics``).
        board: the ChArUco board as ``--board`` names it (``charuco:COLSxROWS:SQUARE_M:MARKER_M:DICT``).
        board_link: the board's link on the chain, eye to hand (``--board-link``).
        board_pose: ``base_T_board`` (4, 4) [m], eye in hand (``--board-pose``; the module docstring).
        existing_path: a first run's DATA.csv (``--existing``).
        candidates_path: choose among these configurations (``--candidates``) instead of aimed and drawn ones.
        sample: configurations aimed, and as many drawn (``--sample``).
        collision_check: False: no self-collision check (``--no-collision-check``).
        xacro_args: ``NAME:=VALUE`` pairs a ``.xacro`` URDF is expanded with (``--xacro-arg``).
        package_dirs: NAME → the folder of ROS package NAME, for ``package://`` collision meshes.
        srdf: the robot's SRDF (``--srdf``): its ``disable_collisions`` pairs (except those disabled as "Never" in
            collision) are the ones not checked.
    """

    camera_link: str
    intrinsics_path: str | Path
    board: str
    board_link: str | None = None
    board_pose: np.ndarray | None = None
    existing_path: str | Path | None = None
    candidates_path: str | Path | None = None
    sample: int = DEFAULT_AIMED
    collision_check: bool = True
    xacro_args: Sequence[tuple[str, str]] = ()
    package_dirs: Mapping[str, Path] | None = None
    srdf: str | Path | None = None

    def __post_init__(self) -> None:
        refuse_srdf_unchecked(self.srdf, self.collision_check)


@dataclass(frozen=True)
class CameraPlanRun:
    """Outcome of :func:`camera_plan_files`: the plan, the arrangement, the camera planned for, how many
    candidates there were and what the user should know."""

    plan: CameraPlan
    arrangement: str
    camera: CameraEstimate
    n_candidates: int
    notes: list[str]


def _camera(inputs: CameraPlanInputs, description_source: str, chain_model_pose: np.ndarray | None,
            arrangement: str) -> np.ndarray:
    """The world frame W (4, 4) [m] without a first run: ``--board-pose`` eye in hand, the URDF's camera
    placement (``chain_model_pose``: root_T_camera) eye to hand."""
    if arrangement == "eye_in_hand":
        if inputs.board_pose is None:
            raise PincalError(f"{description_source}: the camera's link '{inputs.camera_link}' rides on the chain "
                              "(eye in hand): say where the board is, --board-pose X,Y,Z,ROLL,PITCH,YAW in the root "
                              "link's frame (roughly), or --existing DATA.csv of a first run")
        return np.asarray(inputs.board_pose, dtype=float)
    if inputs.board_pose is not None:
        raise PincalError(f"--board-pose: the board rides on the chain at '{inputs.board_link}' (eye to hand), "
                          "where the URDF puts it; leave out --board-pose")
    assert chain_model_pose is not None  # eye to hand: the camera's link is fixed to the root
    return np.linalg.inv(chain_model_pose)  # camera_T_base


def camera_plan_files(urdf: str | Path, inputs: CameraPlanInputs, settings: CameraPlanSettings,
                      out_csv: str | Path, progress: Progress | None = None) -> CameraPlanRun:
    """Plan ``settings.count`` images of the board for the camera of ``inputs``; write PLAN.csv.

    ``progress(done, total)`` counts the collision checks, then the search's steps.

    Raises:
        PincalError: one line naming the file or flag: the output is an input; a camera or board link that is
            not in the URDF or not attached by a fixed joint; intrinsics without an image size or of another
            size than the first run's images; eye in hand without ``board_pose`` or a first run; too few usable
            candidates; any problem of the inputs.
    """
    expect_value(inputs, CameraPlanInputs, "camera_plan_files")
    expect_value(settings, CameraPlanSettings, "camera_plan_files")
    urdf = Path(urdf)
    refuse_overwrite(out_csv, *description_inputs(urdf, inputs.xacro_args),
                     *(Path(p) for p in (inputs.intrinsics_path, inputs.existing_path, inputs.candidates_path)
                       if p is not None))
    description = read_description(urdf, inputs.xacro_args)
    chain, arrangement = camera_chain(description, inputs.camera_link, inputs.board_link)
    intrinsics = read_intrinsics(inputs.intrinsics_path)
    if intrinsics.width <= 0 or intrinsics.height <= 0:
        raise ModelError(f"{inputs.intrinsics_path}: no image size; a plan needs it to tell what is in view "
                         "(give image_width and image_height)")
    board = parse_board(inputs.board)
    notes: list[str] = []
    existing: CornerSet | None = None
    session_names: tuple[str, ...] = ()
    if inputs.existing_path is not None:
        if inputs.board_pose is not None:
            raise PincalError("--board-pose with --existing: the first run's images say where the board is; "
                              "give one of them")
        existing, read_notes = read_corners(inputs.existing_path, chain.joint_specs)
        notes += read_notes
        check_image_size(intrinsics, existing.sizes, existing.images, str(inputs.existing_path),
                         str(inputs.intrinsics_path))
        start, session_names = hand_eye_start(chain, existing, arrangement, intrinsics)
        first = calibrate_camera(chain, existing, start, "registration", session_names=session_names)
        seen = misfit_m(chain, existing, first.estimate, image_sessions(existing, session_names, len(start.worlds)),
                        first.rms_px)
        # a miss calibrate would withhold a model for is no pixel noise to plan with
        if gross_misfit(seen, reach_m(chain, existing.q)) is not None:
            raise PincalError(f"{inputs.existing_path}: the nominal kinematics with the mount and world frame fitted "
                              f"miss these images' corners by {first.rms_px:.4g} px RMS ({seen * 1e3:.3g} mm at the "
                              f"board, beyond {GROSS_REACH_FRACTION * 100:g} % of the reach): not images of this "
                              f"arrangement ({arrangement_words(inputs.camera_link, inputs.board_link)}) or not of "
                              "this robot; give the first run of this camera and board")
        camera = first.estimate
        settings = replace(settings, sigma_px=first.rms_px)
        notes.append(f"{inputs.existing_path}: {len(existing.images)} image(s) recorded, reprojection RMS "
                     f"{first.rms_px:.3g} px with the nominal kinematics (the pixel noise assumed)")
    else:
        root_T_camera = None
        if arrangement == "eye_to_hand":
            model = chain.model
            root_T_camera = model.frames[model.getFrameId(inputs.camera_link)].placement.homogeneous
        world = _camera(inputs, description.source, root_T_camera, arrangement)
        camera = CameraEstimate(arrangement, world[None], np.eye(4), intrinsics)  # the URDF's mount
    rng = np.random.default_rng(settings.seed)
    if inputs.candidates_path is not None:
        candidates, labels = read_candidates(inputs.candidates_path, chain)
    else:
        current = 0 if existing is None else session_names.index(str(existing.sessions[-1]))
        seeds = existing.q if existing is not None else sample_candidates(chain, _SEEDS, settings.seed)
        aimed = aimed_configurations(chain, replace(camera, worlds=camera.worlds[[current]]), board, seeds,
                                     inputs.sample, rng, settings.limits)
        candidates = np.concatenate([aimed, sample_candidates(chain, inputs.sample, settings.seed + 1)])
        labels = np.arange(len(candidates))
    stages = Stages(progress)
    allowed = np.ones(len(candidates), dtype=bool)
    if inputs.collision_check and has_collision_geometry(urdf, inputs.xacro_args):
        try:
            clearance = check_clearance(urdf, chain, candidates, 0.0, xacro_args=inputs.xacro_args,
                                        progress=stages.next(), package_dirs=inputs.package_dirs, srdf=inputs.srdf)
        except ModelError as exc:  # checked by default, not asked for: say how to plan without it
            if inputs.srdf is not None:
                raise
            raise ModelError(f"{exc}; or plan --no-collision-check without the self-collision check") from None
        allowed = clearance.allowed
        if not allowed.all():
            notes.append(f"{int((~allowed).sum())} of {len(candidates)} candidates refused: in self-collision")
        if clearance.unrelated_ignored:  # separate limbs, yet touching at zero
            notes.append(f"{urdf.name}: {clearance.unrelated_note()}")
        if clearance.srdf is not None:
            notes.append(f"{clearance.pairs_checked} link pairs checked, {clearance.srdf_words()}")
    elif inputs.collision_check:
        notes.append(f"{urdf.name} has no <collision> geometry: the candidates are not checked for self-collision "
                     "(check the plan's postures before the robot moves)"
                     + (f"; --srdf {inputs.srdf} is not used" if inputs.srdf is not None else ""))
    kept = np.flatnonzero(allowed)
    plan = plan_camera_views(chain, camera, board, candidates[kept], settings, existing, session_names,
                             progress=stages.next())
    plan = replace(plan, candidates=kept[plan.candidates])
    write_plan_csv(out_csv, plan, chain, labels)
    return CameraPlanRun(plan, arrangement, camera, len(candidates), notes + list(plan.notes))
