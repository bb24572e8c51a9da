"""The typed model of a camera's REPORT.json (``calibrate --camera-link``) and of its ``evaluate --json``
(:mod:`pincal.report.model`)."""

from __future__ import annotations

from typing import Literal, TypedDict

from pincal.report.model import (
    ChainJson,
    ChainLevel,
    Finding,
    Identifiability,
    Parameter,
    Quaternion,
    Sha256,
    Vector3,
)
from pincal.report.model_diagnosis import EffectJson
from pincal.report.model_tree import TreeCandidateJson

__all__ = ["CameraSources", "FrameJson", "IntrinsicsJson", "ReprojectionJson", "ReprojectionPair", "ImageErrorJson",
           "PictureJson", "CameraBlock", "CameraReport", "CameraEvaluationJson", "RmsPair", "CameraStepJson",
           "CameraDiagnosisJson", "MotionRmsJson", "MotionPairJson", "RelativePoseJson"]


class _CameraSourcesKeys(TypedDict):
    urdf: str
    data: str
    corrected_urdf: str
    intrinsics: str
    camera_info: str


class CameraSources(_CameraSourcesKeys, total=False):
    """The files of the run: ``intrinsics`` is the file given or ``estimate``; ``camera_info`` the YAML written
    beside the corrected URDF; ``corrected_urdf_withheld`` true when neither was written (a gross misfit);
    ``validation``: ``diagnose --validation``'s held-out images; ``images``: the folder the HTML page looks for the
    image files in (``--images``, else DATA.csv's folder)."""

    corrected_urdf_withheld: bool
    validation: str
    images: str


class FrameJson(TypedDict):
    """A rigid transform ``parent_T_child``: the child's origin [m] and rotation (x, y, z, w) in the parent."""

    parent: str
    child: str
    translation_m: Vector3
    rotation_xyzw: Quaternion


class IntrinsicsJson(TypedDict):
    """OpenCV's pinhole camera [px] with its five distortion coefficients (k1, k2, p1, p2, k3), the image size [px]
    and the intrinsics fitted (names of ``fx fy cx cy k1 k2 p1 p2 k3``; empty: the file's kept)."""

    fx: float
    fy: float
    cx: float
    cy: float
    distortion: list[float]
    width: int
    height: int
    fitted: list[str]


class ReprojectionJson(TypedDict):
    """Reprojection errors of a set of images: RMS per coordinate (u, v) and the largest corner's distance [px]."""

    images: int
    corners: int
    rms_px: float | None
    max_px: float | None


class ReprojectionPair(TypedDict):
    """``before``: the nominal kinematics with their own mount and world frame fitted (OpenCV's hand-eye refined
    by reprojection: what hand-eye tools give); ``after``: the calibrated model."""

    before: ReprojectionJson
    after: ReprojectionJson


class ImageErrorJson(TypedDict):
    """One image's corners reprojected: RMS per coordinate before and after [px]; ``errors_px``: each corner's
    error length after, ‖reprojected − detected‖ [px] to 1e-4 px (the HTML page's box per image)."""

    image: str
    role: str
    session: str
    corners: int
    before_rms_px: float
    after_rms_px: float
    errors_px: list[float]


class PictureJson(TypedDict):
    """The image the HTML page draws: the calibration image with the largest RMS after (where a bad corner or a bad
    model shows first), its size and each corner as detected and as the calibrated model reprojects it, (u, v) [px]."""

    image: str
    role: str
    width: int
    height: int
    detected_px: list[list[float]]
    reprojected_px: list[list[float]]


class CameraBlock(TypedDict):
    """What a camera's calibration found besides the kinematic parameters.

    ``arrangement``: eye_in_hand (the camera on the chain, the board fixed) or eye_to_hand. ``mount``: the
    camera's (or the board's) frame on the chain's last moving link's child, as written to the URDF;
    ``nominal_*``: the same fitted with the nominal kinematics (OpenCV's hand-eye refined: the "before").
    ``worlds``: per session (``sessions``, in the same order), the board in the root frame (eye in hand) or the
    camera in it (eye to hand). ``cannot_see``: what one camera cannot determine,
    in words. ``reprojection``: calibration and validation images, before and after; ``images``: each image;
    ``picture``: one image's corners for the HTML page (null: no image has corners)."""

    arrangement: Literal["eye_in_hand", "eye_to_hand"]
    camera_link: str
    board_link: str | None
    mount: FrameJson
    nominal_mount: FrameJson
    sessions: list[str]
    worlds: list[FrameJson]
    nominal_worlds: list[FrameJson]
    intrinsics: IntrinsicsJson
    nominal_intrinsics: IntrinsicsJson
    cannot_see: list[str]
    reprojection: dict[str, ReprojectionPair]
    images: list[ImageErrorJson]
    picture: PictureJson | None


class RmsPair(TypedDict):
    """A set of images' reprojection RMS per coordinate (u and v) [px] before and after a step."""

    before_px: float
    after_px: float


class CameraStepJson(TypedDict):
    """An effect ``diagnose --camera-link`` adopted: the effect (its values and standard deviations), its ΔBIC, the
    calibration images' reprojection RMS before and after it, the held-out images' (None without any), the step's
    candidates, best first."""

    effect: EffectJson
    delta_bic: float
    calibration: RmsPair
    heldout: RmsPair | None
    candidates: list[TreeCandidateJson]


class CameraDiagnosisJson(TypedDict):
    """``diagnose --camera-link``'s search: the adoption rule in words, where the loads come from (``masses``:
    ``urdf`` or ``unknown``), the adopted steps, the candidates of the step that adopted nothing, those the images
    cannot test, and the held-out images' reprojection RMS [px] of the camera calibration and of the final model
    (None without held-out images)."""

    criterion: str
    masses: str
    steps: list[CameraStepJson]
    last_candidates: list[TreeCandidateJson]
    untestable: list[str]
    heldout: RmsPair | None


class _CameraDiagnosisKeys(TypedDict, total=False):
    effects: list[EffectJson]
    diagnosis: CameraDiagnosisJson


class CameraReport(_CameraDiagnosisKeys):
    """REPORT.json of ``calibrate --camera-link``: a chain calibrated from a camera's images of a board.
    ``diagnose --camera-link``'s adds the joint effects of the final model (``effects``, as in effects.yaml;
    ``parameters``, ``camera`` and its reprojection errors are the final model's, with its effects) and its search
    (``diagnosis``)."""

    pincal_version: str
    report_version: int
    method: None
    level: ChainLevel
    model: Literal["joint placements"]
    measurement: Literal["camera"]
    sources: CameraSources
    chain: ChainJson
    parameters: list[Parameter]
    identifiability: Identifiability
    camera: CameraBlock
    fit_seconds: float
    notes: list[str]
    warnings: list[Finding]
    urdf_sha256: Sha256
    xacro_args: dict[str, str]


class MotionRmsJson(TypedDict):
    """RMS over the pairs of a relative pose's error: its translation [mm] and its rotation [deg]."""

    mm: float
    deg: float


class MotionPairJson(TypedDict):
    """Two consecutive evaluated images of one session: the error of the mounted frame's relative pose between them
    as each model predicts it against as the images measure it (PnP of each image's corners), [mm, deg], and its
    floor, what the corners' noise alone leaves in the measured one (a perfect model's RMS error)."""

    first: str
    second: str
    session: str
    before_mm: float
    before_deg: float
    after_mm: float
    after_deg: float
    floor_mm: float
    floor_deg: float


class RelativePoseJson(TypedDict):
    """The relative pose of the camera (eye in hand) or of the board (eye to hand) between consecutive evaluated
    images of each session (:mod:`pincal.fit.camera_motion`, eqs R1-R6): per pair and its RMS over the pairs,
    before, after and the floor (null without pairs); ``noise_px``: the corners' noise per coordinate the PnP
    residuals show, the floor's source [px]; ``*_within_floor``: a model's errors no larger than a perfect
    model's would be (95 %); ``verdict`` in words (``no pairs`` ... when no session has 2 images PnP places);
    ``no_pairs``: the sessions with fewer than 2 such images; ``unplaced``: images PnP cannot place (fewer than 4
    corners, or on one line)."""

    frame: Literal["camera", "board"]
    noise_px: float | None
    pairs: list[MotionPairJson]
    before: MotionRmsJson | None
    after: MotionRmsJson | None
    floor: MotionRmsJson | None
    before_within_floor: bool
    after_within_floor: bool
    verdict: str
    no_pairs: list[str]
    unplaced: list[str]


class _CameraEvaluationKeys(TypedDict, total=False):
    relative_pose: RelativePoseJson


class CameraEvaluationJson(_CameraEvaluationKeys):
    """``pincal evaluate --json`` of a camera's report: the evaluated images' reprojection errors before (the nominal
    URDF with the report's nominal mount, world frame and the start's intrinsics) and after (the corrected URDF and
    its camera_info), overall and per image; ``picture``: the evaluated image with the largest RMS after, for
    ``evaluate --html``; ``relative_pose``: the camera's (or the board's) relative pose between consecutive images,
    before and after, against what the images measure, with the floor of that comparison (absent from files
    written before pincal measured it)."""

    urdf: str
    report: str
    data: str
    camera_info: str
    world: Literal["reported", "re-estimated"]
    reprojection: ReprojectionPair
    images: list[ImageErrorJson]
    picture: PictureJson | None
