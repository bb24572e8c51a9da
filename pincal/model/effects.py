"""Effects a kinematic model lacks, as corrections of the measured joint values.

Each joint effect shifts the reading of one joint: actual = q_j + shift, with

* ``compliance``     shift = c · tau_j(q)        c [rad/(N·m)] (m/N for a prismatic joint),
  tau the gravity torque from Pinocchio's ``computeGeneralizedGravity`` on the
  URDF's inertias, plus an optional payload mass at the target; with a ``driver`` i,
  shift = c · tau_i(q): joint j deflects under joint i's load (gravity-torque coupling: a
  parallelogram or a counterbalance links J2's and J3's loads), c [rad or m per N·m or N]
  as j and i are revolute or prismatic (:mod:`pincal.model.effect_units`); with ``moments`` (masses
  unknown) shift = Σ_b θ_b · L_jb(q), L the load of joint j per mass moment b over g₀ and θ_b =
  g₀ · (combination b of mass moments) / k_j [rad, or m for a prismatic joint], eq M1–M2 of
  :mod:`pincal.model.mass_moments`;
* ``encoder_scale``  shift = s · q_j             s relative (gear-ratio error);
* ``cyclic``         shift = a · sin(h q_j) + b · cos(h q_j), harmonic h = 1, 2 [rad];
* ``coupling``       shift = c · q_i             c relative: joint j's reading includes −c × joint
  i's (the ``driver``), as a controller that measures J3 from the horizontal on a parallelogram
  arm reads J3 − J2 (c = 1 corrects it); a mechanical cross-coupling of the transmissions gives a
  small c (rad/m or m/rad between a revolute and a prismatic joint);
* ``backlash``       lost motion between gear flanks [rad or m], two forms:
  ``gravity``: shift = value · sign(tau_j(q)) (a static pose rests on the flank
  gravity pushes it to); ``approach``: shift = value · sign(q_j[k] − q_j[k−1])
  over the rows in time order — a joint that moved less than
  :data:`APPROACH_MIN_STEP` keeps the flank it was on; 0 for the first row.

A ``lateral`` compliance (values c_u, c_v [rad/(N·m)], or per mass moment without masses) does not shift a
reading: it turns the chain at its joint about the two axes orthogonal to the joint's, by its compliances
times the gravity moments about them (eq L1–L3 of :mod:`pincal.model.lateral`).

Two effects act on the sensor side: ``drift`` moves the registration's
translation linearly with time (u [m/s], 3 values; thermal drift) and
``sensor_scale`` scales the sensor's lengths (relative); ``thermal`` (α [1/K]) and
``pause_step`` (3 values) change the points row by row (:mod:`pincal.model.thermal`).

A drift's time handling (spans, never extrapolated) is :mod:`pincal.model.drift`'s.

Each shift is linear in its values: shift = basis(k) · values, so the
calibration's Jacobian for an effect is the joint's Jacobian column times its
basis (see :mod:`pincal.residuals.sensor`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.errors import PincalError, did_you_mean
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.drift import held_times, time_spans
from pincal.model.mass_moments import bending_moments, gravity_loads, moment_names, payload_model
from pincal.model.sensor import Registration

__all__ = [
    "JOINT_EFFECTS", "BEND_EFFECTS", "LATERAL_COMPONENTS",
    "SENSOR_EFFECTS", "EFFECT_TYPES", "BACKLASH_SOURCES", "HARMONICS", "APPROACH_MIN_STEP",
    "FLANK_GAP_S",
    "Effect", "EffectInputs", "RowContext", "gravity_torques", "effect_inputs", "with_loads", "approach_flank",
    "sensed_points", "joint_basis", "joint_shifts", "parse_effect", "effect_to_dict", "effect_from_dict",
]

JOINT_EFFECTS = ("compliance", "encoder_scale", "cyclic", "backlash", "coupling")
#: Effects that turn the chain at a joint about axes other than its own (:mod:`pincal.model.lateral`).
BEND_EFFECTS = ("lateral",)
SENSOR_EFFECTS = ("drift", "sensor_scale", "pause_step")
EFFECT_TYPES = JOINT_EFFECTS + SENSOR_EFFECTS + ("thermal",) + BEND_EFFECTS
#: The axes a lateral compliance bends its joint about (:func:`pincal.model.mass_moments.lateral_axes`), the
#: prefixes of its ``moments`` (``u/PARAMETER:LINK``).
LATERAL_COMPONENTS = ("u", "v")
BACKLASH_SOURCES = ("gravity", "approach")
HARMONICS = (1, 2)

#: A joint that moved less than this between rows stays on its flank [rad or m].
APPROACH_MIN_STEP = 1e-3
#: Rows of another set further than this from the rows' time span say nothing of their flanks [s]: the
#: motion in between is unknown. Half an hour, the default pause of :data:`pincal.model.thermal.PAUSE_S`
#: (the rows of one measuring program are seconds to minutes apart; TIAGo's two days are 100 h apart).
FLANK_GAP_S = 1800.0


@dataclass(frozen=True)
class Effect:
    """One candidate or adopted effect.

    Attributes:
        type: one of :data:`EFFECT_TYPES`.
        joint: URDF joint name for joint effects, None for sensor effects.
        harmonic: h of a ``cyclic`` effect.
        source: ``gravity`` or ``approach`` for ``backlash``.
        driver: for ``coupling``, the joint whose reading drives this joint's shift; for
            ``compliance``, optionally the joint whose gravity torque does (None: its own).
        pause: for ``pause_step``, the pause's number (from 1, :func:`pincal.model.thermal.find_pauses`).
        moments: for a ``compliance`` whose masses are unknown, the mass moments (``PARAMETER:LINK`` of
            :func:`pincal.model.mass_moments.moment_names`) whose loads it follows, one value each; () otherwise.
    """

    type: str
    joint: str | None = None
    harmonic: int | None = None
    source: str | None = None
    driver: str | None = None
    pause: int | None = None
    moments: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.type not in EFFECT_TYPES:
            raise PincalError(f"unknown effect '{self.type}'; effects are: {', '.join(EFFECT_TYPES)}")
        if self.type in JOINT_EFFECTS + BEND_EFFECTS and not self.joint:
            raise PincalError(f"effect '{self.type}' needs a joint")
        if self.type == "cyclic" and self.harmonic not in HARMONICS:
            raise PincalError(f"cyclic effect harmonic must be one of {HARMONICS}, got {self.harmonic}")
        if self.type == "backlash" and self.source not in BACKLASH_SOURCES:
            raise PincalError(f"backlash source must be one of {BACKLASH_SOURCES}, got {self.source}")
        if ((self.type == "coupling") != bool(self.driver) and self.type != "compliance") or (
                self.driver and self.driver == self.joint):
            raise PincalError(f"effect '{self.type}': a coupling names, and a compliance may name, a driving joint "
                              f"other than its own; no other effect does (got joint '{self.joint}', "
                              f"driver '{self.driver}')")
        if self.moments and (self.type not in ("compliance", "lateral") or self.driver):
            raise PincalError(f"effect '{self.type}': only a joint's compliance under its own load follows mass "
                              "moments")
        if self.type == "lateral" and self.moments and not all(
                name.split("/", 1)[0] in LATERAL_COMPONENTS and "/" in name for name in self.moments):
            raise PincalError(f"effect 'lateral:{self.joint}': its mass moments are u/PARAMETER:LINK or "
                              f"v/PARAMETER:LINK (about which lateral axis), got {', '.join(self.moments)}")

    @property
    def n_values(self) -> int:
        if self.moments:
            return len(self.moments)
        return {"cyclic": 2, "drift": 3, "pause_step": 3, "lateral": 2}.get(self.type, 1)

    @property
    def label(self) -> str:
        parts = [self.type]
        if self.joint:
            parts.append(self.joint)
        if self.harmonic:
            parts.append(f"h{self.harmonic}")
        if self.source:
            parts.append(self.source)
        if self.driver:
            parts.append(self.driver)
        if self.pause:
            parts.append(str(self.pause))
        if self.moments:
            parts.append("moments")
        return ":".join(parts)


@dataclass(frozen=True)
class EffectInputs:
    """Per-row quantities effects depend on.

    Attributes:
        q: measured joint values (K, N) [rad or m].
        gravity: gravity torque of each joint at q (K, N) [N·m or N].
        time: row time relative to its mean (K,) [s], or None.
        order: row indices in time order (file order without a time column), (K,).
        context_q / context_time: readings (M, N) and times (M,) [s] of other
            rows of the same session (e.g. held-out rows between calibration
            rows): the approach flank of a row follows the row before it in
            time, whichever set it belongs to. None without them or apart in time.
        flank_time: the rows' own time relative to the mean (K,) [s] when ``time``
            is the drift's, held outside a fitted span (:func:`effect_inputs`
            ``held_sessions``), for the approach flanks; None otherwise.
        joint_names: the names of the columns of ``q`` (a coupling's driver is found by name).
        temperature: T_k − T_ref of each row (K,) [K] (held inside the fitted range), or None.
        pauses: a_kp of each row and pause (K, P) (:mod:`pincal.model.thermal`, eq T2), or None.
        loads: each joint's gravity loads per mass moment over g₀ (K, N, 3, 4N)
            (:func:`pincal.model.mass_moments.gravity_loads`), for compliances of unknown masses; or None.
        load_names: the mass moments of the loads' columns (:func:`pincal.model.mass_moments.moment_names`).
        bending: the gravity moment each joint carries about its lateral axes u, v (K, N, 2) [N·m] (eq M3 of
            the URDF's inertias and the payload, :func:`pincal.model.mass_moments.bending_moments`), or None.
    """

    q: np.ndarray
    gravity: np.ndarray
    time: np.ndarray | None
    order: np.ndarray
    context_q: np.ndarray | None = None
    context_time: np.ndarray | None = None
    flank_time: np.ndarray | None = None
    joint_names: tuple[str, ...] = ()
    temperature: np.ndarray | None = None
    pauses: np.ndarray | None = None
    loads: np.ndarray | None = None
    load_names: tuple[str, ...] = ()
    bending: np.ndarray | None = None


@dataclass(frozen=True)
class RowContext:
    """Other rows of the same session as the rows :func:`effect_inputs` is given (e.g. held-out rows between
    calibration rows, or the calibration rows of held-out ones).

    Attributes:
        q: their joint readings (M, N) [rad or m], for approach flanks.
        time: their times (M,) [s].
        held_sessions: (the session of each row (K,), of each context row (M,)) when the context rows are
            the rows a drift is fitted on and the rows are held out: these take the drift's time as
            ``evaluate`` does (:func:`held_times`); None otherwise.
    """

    q: npt.ArrayLike
    time: npt.ArrayLike
    held_sessions: tuple[npt.ArrayLike, npt.ArrayLike] | None = None


def gravity_torques(
    chain: KinematicChain, q: np.ndarray, payload_kg: float = 0.0, payload_point: np.ndarray | None = None
) -> np.ndarray:
    """Gravity torques (K, N) of the chain's URDF inertias, plus a point mass
    ``payload_kg`` at ``payload_point`` (in the tool frame) [N·m or N]. A joint that others follow
    (URDF ``<mimic>``, eq M1) carries their loads too, by virtual work: tau_driver + multiplier · tau_follower."""
    model = payload_model(chain, payload_kg, payload_point)
    data = model.createData()
    configurations = chain.configurations(q)
    torques = np.stack([pin.computeGeneralizedGravity(model, data, c) for c in configurations])
    return chain.followed_columns(torques[..., None])[..., 0]


def effect_inputs(
    chain: KinematicChain,
    data: MeasurementSet,
    payload_kg: float = 0.0,
    payload_point: np.ndarray | None = None,
    time: np.ndarray | None = None,
    time_reference: float | None = None,
    context: RowContext | None = None,
) -> EffectInputs:
    """Gravity torques, time (minus ``time_reference``, default its mean) and
    time order of the rows of ``data``. ``context`` holds the joint readings and times of other rows of the
    same session, interleaved in time or next to them, for approach flanks (readings only); context further
    than :data:`FLANK_GAP_S` from the rows' time span (another day) is left out: the motion in between is
    unknown, the first flank 0.

    With ``context.held_sessions`` the context rows are the rows a drift is fitted on, and these rows
    (held-out rows) take the drift's time as ``evaluate`` does (:func:`held_times`): outside their
    session's span of context rows, its mean time."""
    context_q = None if context is None else np.asarray(context.q, dtype=float)
    context_time = None if context is None else np.asarray(context.time, dtype=float)
    held_sessions = None if context is None else context.held_sessions
    order = np.arange(data.n_rows) if time is None else np.argsort(time, kind="stable")
    if time is not None and time_reference is None:
        time_reference = float(np.mean(time))
    centred = None if time is None else time - time_reference
    with_context = context_q is not None and context_time is not None and time is not None
    near = context_time is not None and time is not None and with_context and bool(
        max(np.min(context_time) - np.max(time), np.min(time) - np.max(context_time)) <= FLANK_GAP_S)
    drift_time = centred
    if with_context and held_sessions is not None:
        own, fitted = (np.asarray(sessions).astype(str) for sessions in held_sessions)
        assert context_time is not None and time is not None  # with_context
        spans = time_spans(context_time, fitted)
        drift_time = held_times(time, spans, own.tolist(), own)[0] - time_reference
    return EffectInputs(
        q=np.asarray(data.q, dtype=float),
        gravity=gravity_torques(chain, data.q, payload_kg, payload_point),
        bending=bending_moments(chain, data.q, payload_kg, payload_point),
        time=drift_time,
        order=order,
        context_q=np.asarray(context_q, dtype=float) if near else None,
        context_time=np.asarray(context_time, dtype=float) - time_reference if near else None,
        flank_time=centred if drift_time is not centred else None,
        joint_names=tuple(chain.joint_names),
    )


def with_loads(inputs: EffectInputs, chain: KinematicChain) -> EffectInputs:
    """``inputs`` with the chain's gravity loads per mass moment at its rows (:class:`EffectInputs` ``loads``),
    which a compliance of unknown masses follows."""
    return replace(inputs, loads=gravity_loads(chain, inputs.q), load_names=moment_names(chain),
                   joint_names=tuple(chain.joint_names))


def _moment_columns(effect: Effect, inputs: EffectInputs) -> list[int]:
    """The columns of ``inputs.loads`` a compliance of unknown masses follows (:attr:`Effect.moments`)."""
    missing = [name for name in effect.moments if name not in inputs.load_names]
    if inputs.loads is None or missing:
        raise PincalError(f"effect '{effect.label}': no mass moment {', '.join(missing) or 'loads'} on the chain; "
                          f"{did_you_mean(missing[0] if missing else '', inputs.load_names, 'mass moments')}")
    return [inputs.load_names.index(name) for name in effect.moments]


def approach_flank(q: np.ndarray, order: np.ndarray, min_step: float = APPROACH_MIN_STEP) -> np.ndarray:
    """sign(q[k] − q[k−1]) over rows in time order; small moves keep the previous
    flank; 0 for the first row (K,)."""
    flank = np.zeros(len(q))
    current = 0.0
    last = None
    for row in order:
        if last is not None and abs(q[row] - last) >= min_step:
            current = float(np.sign(q[row] - last))
        flank[row] = current
        last = q[row]
    return flank


def sensed_points(
    registration: Registration, world: np.ndarray, scale: float = 0.0, drift: npt.ArrayLike | None = None
) -> np.ndarray:
    """Where the sensor sees points given in the base frame: (1 + s)(Omega y + tau + drift_k).

    Args:
        registration: sensor_T_base (Omega, tau).
        world: points in the base frame [m], (K, P, 3).
        scale: ``sensor_scale`` s (relative).
        drift: ``drift`` offset t_k u of each row [m], (K, 3), or None.
    """
    sensed = registration.apply_points(world)
    if drift is not None:
        sensed = sensed + np.asarray(drift, dtype=float)[:, None, :]
    return (1.0 + scale) * sensed


def joint_basis(effect: Effect, inputs: EffectInputs, joint: int) -> np.ndarray:
    """Basis of a joint effect at every row, (K, n_values): shift = basis @ values."""
    q = inputs.q[:, joint]
    if effect.driver is not None and effect.driver not in inputs.joint_names:
        raise PincalError(f"effect '{effect.label}': no joint '{effect.driver}' on the chain; "
                          f"{did_you_mean(effect.driver, inputs.joint_names, 'joints')}")
    driver = joint if effect.driver is None else inputs.joint_names.index(effect.driver)
    if effect.type == "compliance" and effect.moments:
        return cast(np.ndarray, inputs.loads)[:, joint, 0, _moment_columns(effect, inputs)]  # eq M2
    if effect.type == "compliance":
        return inputs.gravity[:, driver : driver + 1]
    if effect.type == "encoder_scale":
        return q[:, None]
    if effect.type == "coupling":
        return inputs.q[:, driver, None]
    if effect.type == "cyclic":
        h = effect.harmonic
        return np.column_stack([np.sin(h * q), np.cos(h * q)])
    if effect.source == "gravity":
        return np.sign(inputs.gravity[:, joint : joint + 1])
    if inputs.context_q is None:
        return approach_flank(q, inputs.order)[:, None]
    merged = np.concatenate([q, inputs.context_q[:, joint]])
    own = inputs.time if inputs.flank_time is None else inputs.flank_time
    order = np.argsort(np.concatenate([own, inputs.context_time]), kind="stable")
    return approach_flank(merged, order)[: len(q), None]


def joint_shifts(
    effects: Sequence[Effect], values: Sequence[np.ndarray], inputs: EffectInputs, joint_names: Sequence[str]
) -> np.ndarray:
    """Total shift of every joint at every row (K, N) [rad or m]."""
    shifts = np.zeros_like(inputs.q)
    for effect, value in zip(effects, values):
        if effect.type in JOINT_EFFECTS:
            if effect.joint not in joint_names:
                raise PincalError(f"effect '{effect.label}': no joint '{effect.joint}' on the chain; "
                                  f"{did_you_mean(str(effect.joint), joint_names, 'joints')}")
            assert effect.joint is not None  # None is not among the joint names: raised above
            j = list(joint_names).index(effect.joint)
            shifts[:, j] += joint_basis(effect, inputs, j) @ np.atleast_1d(value)
    return shifts


def parse_effect(text: str) -> tuple[Effect, np.ndarray]:
    """``TYPE:JOINT:VALUE`` (``cyclic:JOINT:H:SIN:COS``, ``backlash:JOINT:VALUE[:SOURCE]``,
    ``coupling:JOINT:DRIVER:VALUE``, ``compliance:JOINT[:DRIVER]:VALUE``, ``lateral:JOINT:CU:CV`` [rad/(N·m)],
    ``drift:VX:VY:VZ`` [m/s],
    ``sensor_scale:VALUE``, ``thermal:ALPHA`` [1/K], ``pause_step:DX:DY:DZ`` [m], the first pause's) → effect
    and values."""
    parts = text.split(":")
    try:
        kind = parts[0]
        if kind == "cyclic":
            effect, values = (Effect(kind, parts[1], harmonic=int(parts[2])),
                              np.array([float(parts[3]), float(parts[4])]))
        elif kind == "backlash":
            source = parts[3] if len(parts) > 3 else "gravity"
            effect, values = Effect(kind, parts[1], source=source), np.array([float(parts[2])])
        elif kind == "drift":
            effect, values = Effect(kind), np.array([float(v) for v in parts[1:4]], dtype=float).reshape(3)
        elif kind in ("sensor_scale", "thermal"):
            effect, values = Effect(kind), np.array([float(parts[1])])
        elif kind == "lateral":
            effect, values = Effect(kind, parts[1]), np.array([float(parts[2]), float(parts[3])])
        elif kind == "pause_step":
            effect, values = Effect(kind, pause=1), np.array([float(v) for v in parts[1:4]], dtype=float).reshape(3)
        elif kind == "coupling" or (kind == "compliance" and len(parts) == 4):
            effect, values = Effect(kind, parts[1], driver=parts[2]), np.array([float(parts[3])])
        else:
            effect, values = Effect(kind, parts[1]), np.array([float(parts[2])])
        if not np.all(np.isfinite(values)) or (kind == "sensor_scale" and values[0] <= -1.0):
            raise ValueError("non-finite value or a scale of -1 or less")
        return effect, values
    except (IndexError, ValueError):
        raise PincalError(
            f"bad effect '{text}': use TYPE:JOINT:VALUE, cyclic:JOINT:H:SIN:COS, "
            "backlash:JOINT:VALUE[:gravity|approach], coupling:JOINT:DRIVER:VALUE, compliance:JOINT:DRIVER:VALUE, "
            "lateral:JOINT:CU:CV, "
            "drift:VX:VY:VZ, sensor_scale:VALUE, thermal:ALPHA or pause_step:DX:DY:DZ"
        ) from None


def effect_to_dict(effect: Effect, values: np.ndarray, std: np.ndarray | None = None) -> dict[str, object]:
    """REPORT.json form: {"type", "joint", "value"}; cyclic gives harmonic, sin, cos;
    backlash adds source, coupling (and a compliance driven by another joint's torque) its driver;
    drift's value is [vx, vy, vz] in m/s; a pause step's [dx, dy, dz] in m, with its ``pause``; a compliance of
    unknown masses its ``moments`` and one value (and std) per moment."""
    values = np.atleast_1d(np.asarray(values, dtype=float))
    std = None if std is None else np.atleast_1d(np.asarray(std, dtype=float))
    out: dict[str, object] = {"type": effect.type, "joint": effect.joint}
    if effect.type == "cyclic":
        out.update(harmonic=effect.harmonic, sin=float(values[0]), cos=float(values[1]))
        if std is not None:
            out.update(sin_std=float(std[0]), cos_std=float(std[1]))
        return out
    vector = effect.type in ("drift", "pause_step", "lateral") or bool(effect.moments)
    out["value"] = values.tolist() if vector else float(values[0])
    if std is not None:
        out["std"] = std.tolist() if vector else float(std[0])
    if effect.type == "pause_step":
        out["pause"] = effect.pause
    if effect.type == "backlash":
        out["source"] = effect.source
    if effect.driver:
        out["driver"] = effect.driver
    if effect.moments:
        out["moments"] = list(effect.moments)
    return out


def effect_from_dict(entry: Any) -> tuple[Effect, np.ndarray]:
    """Inverse of :func:`effect_to_dict`."""
    try:
        kind = entry["type"]
        if kind == "cyclic":
            return Effect(kind, entry["joint"], harmonic=int(entry["harmonic"])), np.array(
                [float(entry["sin"]), float(entry["cos"])]
            )
        effect = Effect(kind, entry.get("joint"), source=entry.get("source"), driver=entry.get("driver"),
                        pause=None if entry.get("pause") is None else int(entry["pause"]),
                        moments=tuple(str(m) for m in entry.get("moments") or ()))
        values = np.atleast_1d(np.asarray(entry["value"], dtype=float))
        if values.shape != (effect.n_values,) or not np.isfinite(values).all():
            raise ValueError(f"'value' must be {effect.n_values} finite number(s)")
        return effect, values
    except (KeyError, TypeError, ValueError) as exc:
        raise PincalError(f"bad effect entry {entry} in the report ({exc})") from None
