"""What ``calibrate``, ``diagnose`` and ``evaluate`` are asked to do, as frozen values checked once.

The command line builds one of these from its flags (:mod:`pincal.cli.commands`); a script may
build one directly. Every check of the flags' meaning together — a level and a method, a prior
at a level without kinematic parameters, a stated noise — is made here, when the object is
made, with the one-line message the command prints; the workflows of
:mod:`pincal.workflows` take the object and the paths and check nothing of it again.
``plan`` has its own (:class:`pincal.planning.planner.PlanSettings`).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, cast, get_args

import numpy as np
import numpy.typing as npt

from pincal.errors import PincalError, expect_value
from pincal.fit.prior import Prior
from pincal.measurements.couplings import ReadingCoupling, decide_followers
from pincal.measurements.csv_v1 import read_table
from pincal.model.masses import DEFAULT_MASSES, MASSES, Masses
from pincal.model.thermal import PAUSE_S

if TYPE_CHECKING:  # the fit's selection module is imported only when a selection is checked
    from pincal.fit.selection import SelectionCriterion
    from pincal.model.chain import KinematicChain
    from pincal.model.tree import KinematicTree

__all__ = [
    "CALIBRATE_LEVELS", "DIAGNOSE_LEVELS", "CalibrateLevel", "DiagnoseLevel", "METHODS", "expect", "no_prior",
    "default_selection", "CalibrateSettings", "DiagnoseSettings", "EvaluateSettings", "follow_couplings",
]

#: ``calibrate --level``: the any-chain levels, ``auto`` (chosen by cross-validation) and ``dh``
#: (the paper's Methods 1–3 on a DH-described chain).
CalibrateLevel = Literal["registration", "offsets", "full", "auto", "dh"]
#: ``diagnose --level``: the geometry under the effects.
DiagnoseLevel = Literal["registration", "offsets", "full", "auto"]
#: The values of :data:`CalibrateLevel` and :data:`DiagnoseLevel`, in order.
CALIBRATE_LEVELS: tuple[CalibrateLevel, ...] = get_args(CalibrateLevel)
DIAGNOSE_LEVELS: tuple[DiagnoseLevel, ...] = get_args(DiagnoseLevel)
#: The paper's methods (``--method``); 2 when ``--level dh`` names none.
METHODS = (1, 2, 3)


def expect(settings: object, kind: type, function: str) -> None:
    """Refuse, with a TypeError naming the class, a workflow call whose ``settings`` is not a ``kind``
    (a script written for the former signature, which took each setting as its own argument)."""
    expect_value(settings, kind, function)


def no_prior(flag: str, level: str) -> PincalError:
    """The error for a prior (``flag``: ``--select prior`` or ``--prior-scale``) at ``level``
    ``registration`` or ``dh``, which fit no kinematic parameter a prior could hold."""
    what = ("fits no kinematic parameter" if level == "registration"
            else "estimates the paper's DH parameters, which take no prior")
    return PincalError(f"{flag} does not apply to --level {level} (it {what}): use --level offsets, full or "
                       f"auto, or drop {flag}")


def _selection(selection: str, level: str) -> None:
    from pincal.fit.selection import SELECTION_CRITERIA  # here: evaluate's settings need no fit module

    if selection not in SELECTION_CRITERIA:
        raise PincalError(f"--select must be one of {', '.join(SELECTION_CRITERIA)}, got '{selection}'")
    if selection == "prior" and level in ("registration", "dh"):
        raise no_prior("--select prior", level)


def _tool(tool_pose: npt.ArrayLike | None) -> np.ndarray | None:
    """A read-only copy of the pose (the caller's array may change; these settings may not)."""
    if tool_pose is None:
        return None
    pose = np.array(tool_pose, dtype=float)
    if pose.shape != (4, 4) or not np.all(np.isfinite(pose)):
        raise PincalError(f"--tool must be a finite 4x4 pose of the target in the tip link, got shape {pose.shape}")
    pose.setflags(write=False)
    return pose


def default_selection(level: str | None) -> SelectionCriterion | Prior:
    """The commands' default ``--select``: the prior wherever kinematic parameters are fitted
    (offsets, full, auto; docs/defaults.md), AIC at registration and dh."""
    return "aic" if level in ("registration", "dh") else Prior()


def _xacro(args: Iterable[tuple[object, object]]) -> tuple[tuple[str, str], ...]:
    return tuple((str(k), str(v)) for k, v in args)


class _FitSettings:
    """What calibrate's and diagnose's settings share: the selection, the stated noise, the tool
    and the xacro arguments, resolved and checked the same way (attributes of the dataclasses)."""

    level: CalibrateLevel
    selection: SelectionCriterion | Prior | None
    sigma_pos_mm: float | None
    tool_pose: np.ndarray | None
    xacro_args: tuple[tuple[str, str], ...]
    couplings: tuple[ReadingCoupling, ...]
    force: bool

    def _resolve(self) -> None:
        """From ``__post_init__``, after the level is checked: the default selection, then the checks."""
        if self.selection is None:
            object.__setattr__(self, "selection", default_selection(self.level))
        _selection(self.criterion, self.level)
        _positive("--sigma-pos", self.sigma_pos_mm)
        object.__setattr__(self, "tool_pose", _tool(self.tool_pose))
        object.__setattr__(self, "xacro_args", _xacro(self.xacro_args))
        object.__setattr__(self, "couplings", tuple(self.couplings))

    @property
    def criterion(self) -> SelectionCriterion | Prior:
        """``selection`` as the fits take it: resolved and checked when the settings are made, never None."""
        return cast("SelectionCriterion | Prior", self.selection)

    @property
    def sigma_pos_m(self) -> float | None:
        return None if self.sigma_pos_mm is None else self.sigma_pos_mm / 1000.0


def _positive(flag: str, value: float | None) -> None:
    if value is not None and not (np.isfinite(value) and value > 0):
        raise PincalError(f"{flag} must be a positive number, got {value}")


@dataclass(frozen=True)
class CalibrateSettings(_FitSettings):
    """``pincal calibrate`` without its paths.

    Attributes:
        tip_link: the end of the chain (``--tip-link``, ``--tool-parent``).
        level: one of :data:`CALIBRATE_LEVELS`.
        method: the paper's method at level ``dh`` (None: Method 2); None at any other level.
        weight: w of Method 3 [mm²/deg²].
        tool_pose: the known target pose in the tip link (4, 4), or None: estimated.
        sigma_column: extra column of per-row noise scales [mm] (row weights).
        reject_outliers: refit without the rows flagged as outliers.
        selection: the parameter selection (:data:`pincal.fit.selection.SELECTION_CRITERIA`; a
            :class:`pincal.fit.prior.Prior` for ``prior``); None: the command's default
            (:func:`default_selection`).
        sigma_pos_mm: the sensor's stated position noise per axis [mm] (plausibility checks), or None.
        xacro_args: ``NAME:=VALUE`` pairs for a ``.xacro`` description.
        couplings: joint readings taken against another joint (``--coupling``), corrected in every
            row read (:mod:`pincal.measurements.couplings`, eq C1).
        force: write the corrected URDF (and effects.yaml) even of a model that misses its rows grossly
            (``--force``; :func:`pincal.fit.plausibility.gross_misfit`); without it they are withheld.

    Raises:
        PincalError: an unknown level, method or selection; a method outside level ``dh``, or
            level ``dh`` without the tool; a prior where no kinematic parameter is fitted; the
            stated noise with the paper's methods; a weight or noise that is not positive; a tool
            that is not a 4×4 pose.
    """

    tip_link: str
    level: CalibrateLevel = "full"
    method: int | None = None
    weight: float = 1.0
    tool_pose: np.ndarray | None = field(default=None, compare=False)
    sigma_column: str | None = None
    reject_outliers: bool = False
    selection: SelectionCriterion | Prior | None = None
    sigma_pos_mm: float | None = None
    xacro_args: tuple[tuple[str, str], ...] = ()
    couplings: tuple[ReadingCoupling, ...] = ()
    force: bool = False

    def __post_init__(self) -> None:
        if self.level not in CALIBRATE_LEVELS:
            raise PincalError(f"--level must be one of {', '.join(CALIBRATE_LEVELS)}, got '{self.level}'")
        if self.level != "dh" and self.method is not None:
            raise PincalError(f"--method applies to --level dh only (got --level {self.level})")
        if self.method is not None and self.method not in METHODS:
            raise PincalError(f"--method must be 1, 2 or 3, got {self.method}")
        if self.level == "dh" and self.tool_pose is None:
            raise PincalError("the paper's methods (--level dh) need the tool: --tool X,Y,Z,ROLL,PITCH,YAW; "
                              "or use --level registration|offsets|full to estimate the target")
        if self.level == "dh" and self.couplings:
            raise PincalError("--coupling applies to --level registration, offsets, full or auto, not to the paper's "
                              "methods; correct the readings in the data for those")
        if self.level == "dh" and self.sigma_pos_mm is not None:
            raise PincalError("--sigma-pos applies to --level registration, offsets, full or auto (the plausibility "
                              "checks of pincal.fit.plausibility), not to the paper's methods; drop it")
        if self.level == "dh" and self.force:
            raise PincalError("--force applies to --level registration, offsets, full or auto (the plausibility "
                              "checks of pincal.fit.plausibility), not to the paper's methods; drop it")
        _positive("--weight", self.weight)
        self._resolve()

    @property
    def paper_method(self) -> int:
        """The paper's method run at level ``dh``: ``method``, or 2."""
        return self.method if self.method is not None else 2


@dataclass(frozen=True)
class DiagnoseSettings(_FitSettings):
    """``pincal diagnose`` without its paths.

    Attributes:
        tip_link, tool_pose, sigma_column, selection, sigma_pos_mm, xacro_args, couplings, force: as for
            :class:`CalibrateSettings` (``selection`` None: :func:`default_selection`; ``force``: of the
            final model, with its effects).
        level: the geometry under the effects, one of :data:`DIAGNOSE_LEVELS`.
        payload_kg: a point mass at the target for the gravity torques [kg].
        time_column: the column of row times [s] (None: the first of
            :data:`pincal.model.drift.TIME_COLUMNS` present).
        temperature_column: the column of row temperatures [°C] (None: the first of
            :data:`pincal.model.thermal.TEMPERATURE_COLUMNS` present).
        pause_s: a gap longer than this between rows of a session is a pause [s] (:mod:`pincal.model.thermal`).
        masses: where the gravity loads come from, one of :data:`pincal.model.masses.MASSES` (``unknown``:
            compliances follow the carried links' mass moments, as on a URDF without inertias).
        lateral: also try each revolute joint's lateral (bending) compliance (:mod:`pincal.model.lateral`).

    Raises:
        PincalError: an unknown level, selection or masses, a prior at level registration, a negative
            payload, a noise that is not positive, a tool that is not a 4×4 pose.
    """

    tip_link: str
    level: DiagnoseLevel = "full"
    tool_pose: np.ndarray | None = field(default=None, compare=False)
    sigma_column: str | None = None
    selection: SelectionCriterion | Prior | None = None
    payload_kg: float = 0.0
    time_column: str | None = None
    sigma_pos_mm: float | None = None
    xacro_args: tuple[tuple[str, str], ...] = ()
    couplings: tuple[ReadingCoupling, ...] = ()
    temperature_column: str | None = None
    pause_s: float = PAUSE_S
    force: bool = False
    masses: Masses = DEFAULT_MASSES
    lateral: bool = False

    def __post_init__(self) -> None:
        if self.level not in DIAGNOSE_LEVELS:
            raise PincalError(f"--level must be one of {', '.join(DIAGNOSE_LEVELS)}, got '{self.level}'")
        if self.masses not in MASSES:
            raise PincalError(f"--masses must be one of {', '.join(MASSES)}, got '{self.masses}'")
        if not (np.isfinite(self.payload_kg) and self.payload_kg >= 0):
            raise PincalError(f"--payload-kg must be a non-negative number, got {self.payload_kg}")
        if not (np.isfinite(self.pause_s) and self.pause_s > 0):
            raise PincalError(f"--pause-s must be a positive number of seconds, got {self.pause_s}")
        self._resolve()


@dataclass(frozen=True)
class EvaluateSettings:
    """``pincal evaluate`` (sensor data) without its paths.

    Attributes:
        allow_other_urdf: accept a URDF other than the one written with the report.
        xacro_args: ``NAME:=VALUE`` pairs for a ``.xacro`` description.
        fixed_registration: a reported session's name, or ``""`` for the only/first one, whose
            registration every row uses (``--fixed-registration``); None: the module's rule.
        new_session: re-estimate the registration of every session of the data.
        temperature_column: the column of row temperatures [°C] (None: the report's, else the first of
            :data:`pincal.model.thermal.TEMPERATURE_COLUMNS` present).
        max_pos_mm: the largest position error the robot may show [mm] (``--max-pos-mm``), or None: not judged.
        max_rot_deg: the largest orientation error [deg] (``--max-rot-deg``), or None. Both are judged by
            :func:`pincal.workflows.evaluation_outputs.evaluate_and_write`; :func:`evaluate_files` measures only.

    Raises:
        PincalError: ``fixed_registration`` and ``new_session`` together; a threshold that is negative or
            not finite.
    """

    allow_other_urdf: bool = False
    xacro_args: tuple[tuple[str, str], ...] = ()
    fixed_registration: str | None = None
    new_session: bool = False
    temperature_column: str | None = None
    max_pos_mm: float | None = None
    max_rot_deg: float | None = None

    def __post_init__(self) -> None:
        if self.fixed_registration is not None and self.new_session:
            raise PincalError("--fixed-registration and --new-session exclude each other; give one")
        for flag, value in (("--max-pos-mm", self.max_pos_mm), ("--max-rot-deg", self.max_rot_deg)):
            if value is not None and not (np.isfinite(value) and value >= 0):
                raise PincalError(f"{flag} must be a non-negative number, got {value}")
        object.__setattr__(self, "xacro_args", _xacro(self.xacro_args))


def follow_couplings(chain: KinematicChain | KinematicTree, couplings: Sequence[ReadingCoupling],
                     paths: Sequence[str | os.PathLike[str]]) -> tuple[ReadingCoupling, ...]:
    """The run's ``--coupling`` decided once, from the columns of its calibration files ``paths``: a coupling
    on a chain joint one of them has no column for ``follows`` its driver
    (:func:`pincal.measurements.couplings.decide_followers`), and ``chain`` (or a tree of several targets) is made
    to follow it for the whole run (:meth:`pincal.model.chain.KinematicChain.follow`,
    :meth:`pincal.model.tree.KinematicTree.follow`); REPORT.json records what was decided.

    Raises:
        MeasurementError: an unreadable file, a coupling on a joint the URDF's ``<mimic>`` already ties.
    """
    if not couplings:
        return ()
    decided = decide_followers(couplings, chain.joint_names, [read_table(p).names for p in paths])
    chain.follow(decided)
    return decided
