"""Effects a kinematic model lacks, as corrections of the measured joint values.

Each joint effect shifts the reading of one joint: actual = q_j + shift, with

* ``compliance``     shift = c · tau_j(q)        c [rad/(N·m)] (m/N for a prismatic joint),
  tau the gravity torque from Pinocchio's ``computeGeneralizedGravity`` on the
  URDF's inertias, plus an optional payload mass at the target;
* ``encoder_scale``  shift = s · q_j             s relative (gear-ratio error);
* ``cyclic``         shift = a · sin(h q_j) + b · cos(h q_j), harmonic h = 1, 2 [rad];
* ``backlash``       lost motion between gear flanks [rad or m], two forms:
  ``gravity``: shift = value · sign(tau_j(q)) (a static pose rests on the flank
  gravity pushes it to); ``approach``: shift = value · sign(q_j[k] − q_j[k−1])
  over the rows in time order — a joint that moved less than
  :data:`APPROACH_MIN_STEP` keeps the flank it was on; 0 for the first row.

Two effects act on the sensor side: ``drift`` moves the registration's
translation linearly with time (u [m/s], 3 values; thermal drift) and
``sensor_scale`` scales the sensor's lengths (relative).

Each shift is linear in its values: shift = basis(k) · values, so the
calibration's Jacobian for an effect is the joint's Jacobian column times its
basis (see :mod:`pincal.residuals.sensor`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pinocchio as pin

from pincal.errors import PincalError
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.sensor import Registration

JOINT_EFFECTS = ("compliance", "encoder_scale", "cyclic", "backlash")
SENSOR_EFFECTS = ("drift", "sensor_scale")
EFFECT_TYPES = JOINT_EFFECTS + SENSOR_EFFECTS
BACKLASH_SOURCES = ("gravity", "approach")
HARMONICS = (1, 2)

#: A joint that moved less than this between rows stays on its flank [rad or m].
APPROACH_MIN_STEP = 1e-3
#: Extra columns taken as the row time [s], first found wins.
TIME_COLUMNS = ("time", "t", "timestamp", "t_start_robot")


@dataclass(frozen=True)
class Effect:
    """One candidate or adopted effect.

    Attributes:
        type: one of :data:`EFFECT_TYPES`.
        joint: URDF joint name for joint effects, None for sensor effects.
        harmonic: h of a ``cyclic`` effect.
        source: ``gravity`` or ``approach`` for ``backlash``.
    """

    type: str
    joint: str | None = None
    harmonic: int | None = None
    source: str | None = None

    def __post_init__(self) -> None:
        if self.type not in EFFECT_TYPES:
            raise PincalError(f"unknown effect '{self.type}'; effects are: {', '.join(EFFECT_TYPES)}")
        if self.type in JOINT_EFFECTS and not self.joint:
            raise PincalError(f"effect '{self.type}' needs a joint")
        if self.type == "cyclic" and self.harmonic not in HARMONICS:
            raise PincalError(f"cyclic effect harmonic must be one of {HARMONICS}, got {self.harmonic}")
        if self.type == "backlash" and self.source not in BACKLASH_SOURCES:
            raise PincalError(f"backlash source must be one of {BACKLASH_SOURCES}, got {self.source}")

    @property
    def n_values(self) -> int:
        return {"cyclic": 2, "drift": 3}.get(self.type, 1)

    @property
    def label(self) -> str:
        parts = [self.type]
        if self.joint:
            parts.append(self.joint)
        if self.harmonic:
            parts.append(f"h{self.harmonic}")
        if self.source:
            parts.append(self.source)
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
            time, whichever set it belongs to. None without them.
    """

    q: np.ndarray
    gravity: np.ndarray
    time: np.ndarray | None
    order: np.ndarray
    context_q: np.ndarray | None = None
    context_time: np.ndarray | None = None


def gravity_torques(
    chain: KinematicChain, q: np.ndarray, payload_kg: float = 0.0, payload_point: np.ndarray | None = None
) -> np.ndarray:
    """Gravity torques (K, N) of the chain's URDF inertias, plus a point mass
    ``payload_kg`` at ``payload_point`` (in the tool frame) [N·m or N]."""
    model = chain.model.copy()
    if payload_kg > 0:
        point = np.zeros(3) if payload_point is None else np.asarray(payload_point, dtype=float)
        tip = model.frames[chain.tip_frame_id]
        at_tool = tip.placement * pin.SE3(chain.tool) * pin.SE3(np.eye(3), point)
        model.appendBodyToJoint(tip.parentJoint, pin.Inertia(payload_kg, np.zeros(3), np.zeros((3, 3))), at_tool)
    data = model.createData()
    configurations = chain.configurations(q)
    return np.stack([pin.computeGeneralizedGravity(model, data, c) for c in configurations])


def time_column(data: MeasurementSet, name: str | None = None) -> np.ndarray | None:
    """The rows' time [s] from ``name`` or the first of :data:`TIME_COLUMNS` present."""
    names = [name] if name else [n for n in TIME_COLUMNS if n in data.extra]
    if name and name not in data.extra:
        raise PincalError(
            f"{data.source}: no time column '{name}'; numeric extra columns are: "
            f"{', '.join(data.extra) or 'none'}"
        )
    if not names:
        return None
    time = np.asarray(data.extra[names[0]], dtype=float)
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise PincalError(
            f"{data.source}, line {int(data.lines[bad[0]])}, column '{names[0]}': empty or non-finite time; "
            "fill it in or choose another column with --time-column"
        )
    return time


def effect_inputs(
    chain: KinematicChain,
    data: MeasurementSet,
    payload_kg: float = 0.0,
    payload_point: np.ndarray | None = None,
    time: np.ndarray | None = None,
    time_reference: float | None = None,
    context_q: np.ndarray | None = None,
    context_time: np.ndarray | None = None,
) -> EffectInputs:
    """Gravity torques, time (minus ``time_reference``, default its mean) and
    time order of the rows of ``data``. ``context_q`` (M, N) with
    ``context_time`` (M,) [s] are the joint readings of other rows of the same
    session, interleaved in time, for approach flanks (readings only)."""
    order = np.arange(data.n_rows) if time is None else np.argsort(time, kind="stable")
    if time is not None and time_reference is None:
        time_reference = float(np.mean(time))
    centred = None if time is None else time - time_reference
    with_context = context_q is not None and context_time is not None and time is not None
    return EffectInputs(
        q=np.asarray(data.q, dtype=float),
        gravity=gravity_torques(chain, data.q, payload_kg, payload_point),
        time=centred,
        order=order,
        context_q=np.asarray(context_q, dtype=float) if with_context else None,
        context_time=np.asarray(context_time, dtype=float) - time_reference if with_context else None,
    )


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
    registration: Registration, world: np.ndarray, scale: float = 0.0, drift: np.ndarray | None = None
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
    if effect.type == "compliance":
        return inputs.gravity[:, joint : joint + 1]
    if effect.type == "encoder_scale":
        return q[:, None]
    if effect.type == "cyclic":
        h = effect.harmonic
        return np.column_stack([np.sin(h * q), np.cos(h * q)])
    if effect.source == "gravity":
        return np.sign(inputs.gravity[:, joint : joint + 1])
    if inputs.context_q is None:
        return approach_flank(q, inputs.order)[:, None]
    merged = np.concatenate([q, inputs.context_q[:, joint]])
    order = np.argsort(np.concatenate([inputs.time, inputs.context_time]), kind="stable")
    return approach_flank(merged, order)[: len(q), None]


def joint_shifts(
    effects: Sequence[Effect], values: Sequence[np.ndarray], inputs: EffectInputs, joint_names: Sequence[str]
) -> np.ndarray:
    """Total shift of every joint at every row (K, N) [rad or m]."""
    shifts = np.zeros_like(inputs.q)
    for effect, value in zip(effects, values):
        if effect.type in JOINT_EFFECTS:
            if effect.joint not in joint_names:
                raise PincalError(
                    f"effect '{effect.label}': no joint '{effect.joint}' on the chain; joints are: {', '.join(joint_names)}"
                )
            j = list(joint_names).index(effect.joint)
            shifts[:, j] += joint_basis(effect, inputs, j) @ np.atleast_1d(value)
    return shifts


def parse_effect(text: str) -> tuple[Effect, np.ndarray]:
    """``TYPE:JOINT:VALUE`` (``cyclic:JOINT:H:SIN:COS``, ``backlash:JOINT:VALUE[:SOURCE]``,
    ``drift:VX:VY:VZ`` [m/s], ``sensor_scale:VALUE``) → effect and values."""
    parts = text.split(":")
    try:
        kind = parts[0]
        if kind == "cyclic":
            effect, values = Effect(kind, parts[1], harmonic=int(parts[2])), np.array([float(parts[3]), float(parts[4])])
        elif kind == "backlash":
            source = parts[3] if len(parts) > 3 else "gravity"
            effect, values = Effect(kind, parts[1], source=source), np.array([float(parts[2])])
        elif kind == "drift":
            effect, values = Effect(kind), np.array([float(v) for v in parts[1:4]], dtype=float).reshape(3)
        elif kind == "sensor_scale":
            effect, values = Effect(kind), np.array([float(parts[1])])
        else:
            effect, values = Effect(kind, parts[1]), np.array([float(parts[2])])
        if not np.all(np.isfinite(values)) or (kind == "sensor_scale" and values[0] <= -1.0):
            raise ValueError("non-finite value or a scale of -1 or less")
        return effect, values
    except (IndexError, ValueError):
        raise PincalError(
            f"bad effect '{text}': use TYPE:JOINT:VALUE, cyclic:JOINT:H:SIN:COS, "
            "backlash:JOINT:VALUE[:gravity|approach], drift:VX:VY:VZ or sensor_scale:VALUE"
        ) from None


def effect_to_dict(effect: Effect, values: np.ndarray, std: np.ndarray | None = None) -> dict:
    """REPORT.json form: {"type", "joint", "value"}; cyclic gives harmonic, sin, cos;
    backlash adds source; drift's value is [vx, vy, vz] in m/s."""
    values = np.atleast_1d(np.asarray(values, dtype=float))
    std = None if std is None else np.atleast_1d(np.asarray(std, dtype=float))
    out: dict = {"type": effect.type, "joint": effect.joint}
    if effect.type == "cyclic":
        out.update(harmonic=effect.harmonic, sin=float(values[0]), cos=float(values[1]))
        if std is not None:
            out.update(sin_std=float(std[0]), cos_std=float(std[1]))
        return out
    out["value"] = values.tolist() if effect.type == "drift" else float(values[0])
    if std is not None:
        out["std"] = std.tolist() if effect.type == "drift" else float(std[0])
    if effect.type == "backlash":
        out["source"] = effect.source
    return out


def effect_from_dict(entry: dict) -> tuple[Effect, np.ndarray]:
    """Inverse of :func:`effect_to_dict`."""
    try:
        kind = entry["type"]
        if kind == "cyclic":
            return Effect(kind, entry["joint"], harmonic=int(entry["harmonic"])), np.array(
                [float(entry["sin"]), float(entry["cos"])]
            )
        effect = Effect(kind, entry.get("joint"), source=entry.get("source"))
        return effect, np.atleast_1d(np.asarray(entry["value"], dtype=float))
    except (KeyError, TypeError, ValueError) as exc:
        raise PincalError(f"bad effect entry {entry} in the report ({exc})") from None
