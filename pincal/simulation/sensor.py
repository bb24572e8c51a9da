"""The simulated sensor: noise-free and noisy measurements of a chain through a registration (eq 20–22)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from pincal.errors import ModelError, PincalError
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain, points_in_base
from pincal.model.effects import (
    BEND_EFFECTS,
    Effect,
    EffectInputs,
    gravity_torques,
    joint_shifts,
    sensed_points,
)
from pincal.model.lateral import bend_angles, bent_tool_poses
from pincal.model.mass_moments import bending_moments
from pincal.model.sensor import Registration
from pincal.model.thermal import RowConditions
from pincal.model.tree import KinematicTree

__all__ = [
    "DEFAULT_REGISTRATION", "cpa_configurations", "SimulatedSensor", "SimulatedEffects", "measure", "simulated_shifts",
    "simulated_bends",
    "perfect_measurements", "random_configurations", "sampling_limits", "REFERENCE_C", "TEMPERATURE_COLUMN", "warm_up",
    "simulated_conditions",
]

#: The temperature at which a simulated robot's URDF lengths hold [°C]: ISO 1's reference temperature.
REFERENCE_C = 20.0
#: The column simulated temperatures are written to [°C] (the first of pincal.model.thermal.TEMPERATURE_COLUMNS).
TEMPERATURE_COLUMN = "temperature_c"

#: The arbitrary sensor registration of the simulations: sensor_T_base.
DEFAULT_REGISTRATION = Registration(
    rotation=Rotation.from_euler("ZYX", [35.0, -12.0, 8.0], degrees=True).as_matrix(),
    translation=np.array([1.85, -0.62, 0.43]),
)


def cpa_configurations(lower: np.ndarray, upper: np.ndarray, per_joint: int,
                       start: np.ndarray | None = None) -> np.ndarray:
    """Eq 23: joint n at lower_n + k·delta_n (k = 1..K_alpha), the others at zero (or at ``start``, (N,): one
    joint moving at a time from a posture); (N·K_alpha, N)."""
    n = len(lower)
    rows = []
    for joint in range(n):
        step = (upper[joint] - lower[joint]) / (per_joint + 1)
        block = np.zeros((per_joint, n)) if start is None else np.tile(np.asarray(start, dtype=float), (per_joint, 1))
        block[:, joint] = lower[joint] + step * np.arange(1, per_joint + 1)
        rows.append(block)
    return np.vstack(rows)


@dataclass(frozen=True)
class SimulatedSensor:
    """What the simulated sensor measures, and how noisily (eq 20–22).

    Attributes:
        sigma_pos_m: std of each measured coordinate [m].
        sigma_rot_rad: std of each ZYX angle of a measured orientation [rad].
        points: target points in the tool frame (P, 3) [m]; default: the tool origin.
        target_rotation: the measured frame's rotation in the tool frame (default identity).
        with_rotation: also report orientations.
    """

    sigma_pos_m: float
    sigma_rot_rad: float
    points: np.ndarray | None = None
    target_rotation: np.ndarray | None = None
    with_rotation: bool = True


@dataclass(frozen=True)
class SimulatedEffects:
    """Unmodelled effects acting on the robot and sensor of a simulation, and what they depend on.

    Attributes:
        effects: the effects with their values (see :mod:`pincal.model.effects`); the readings are
            written unchanged, the sensor sees the shifted joints.
        time: row times [s], written as the extra column ``time``; drift grows with it from t = 0.
        shifts: joint shifts of these rows (K, N) when computed over a longer sequence (approach
            flanks depend on the previous row); default: computed from these rows alone
            (:func:`simulated_shifts`).
        conditions: the rows' thermal expansion and pause steps (:func:`simulated_conditions`), or None.
        temperature: row temperatures [°C], written as the extra column :data:`TEMPERATURE_COLUMN`.
    """

    effects: Sequence[tuple[Effect, np.ndarray]] = ()
    time: np.ndarray | None = None
    shifts: np.ndarray | None = None
    conditions: RowConditions | None = None
    temperature: np.ndarray | None = None


def measure(
    chain: KinematicChain,
    q: np.ndarray,
    registration: Registration,
    rng: np.random.Generator,
    sensor: SimulatedSensor,
    role: str,
    effects: SimulatedEffects | None = None,
) -> MeasurementSet:
    """What the simulated sensor reports at configurations ``q`` (eq 20–22).

    Args:
        sensor: what it measures and its noise (:class:`SimulatedSensor`).
        role: each row's role.
        effects: unmodelled effects and their inputs (:class:`SimulatedEffects`; default: none).
    """
    sigma_pos_m, sigma_rot_rad = sensor.sigma_pos_m, sensor.sigma_rot_rad
    points, target_rotation, with_rotation = sensor.points, sensor.target_rotation, sensor.with_rotation
    simulated = SimulatedEffects() if effects is None else effects
    time, shifts, temperature = simulated.time, simulated.shifts, simulated.temperature
    conditions = simulated.conditions
    actual = np.asarray(q, dtype=float)
    scale = 0.0
    drift: np.ndarray | None = np.zeros((len(q), 3))
    if simulated.effects:
        if shifts is None:
            shifts = simulated_shifts(chain, actual, simulated.effects, time)
        actual = actual + shifts
        for effect, value in simulated.effects:
            if effect.type == "sensor_scale":
                scale = float(value[0])
            elif effect.type == "drift":
                if time is None:
                    raise PincalError("a simulated drift needs row times")
                drift = time[:, None] * np.asarray(value, dtype=float)
    bends = simulated_bends(chain, np.asarray(q, dtype=float), simulated.effects)
    if bends is None:
        tool_rotations, tool_positions = chain.tool_poses(actual)
    else:  # lateral compliances turn the chain at their joints (eq L1 of pincal.model.lateral)
        poses = bent_tool_poses(chain, actual, bends)
        tool_rotations, tool_positions = poses.tool_rotations, poses.tool_positions
    points = np.zeros((1, 3)) if points is None else np.asarray(points, dtype=float)
    world = points_in_base(tool_positions, tool_rotations, points)
    if conditions is not None:  # eq T1-T2 of pincal.model.thermal
        world, drift = conditions.world(world), conditions.offsets(drift)
    sensed = sensed_points(registration, world, scale, drift)
    sensed = sensed + rng.normal(0.0, 1.0, sensed.shape) * sigma_pos_m
    rotations = None
    if with_rotation:
        target = np.eye(3) if target_rotation is None else target_rotation
        noise = Rotation.from_euler("ZYX", rng.normal(0.0, 1.0, (len(q), 3)) * sigma_rot_rad)
        rotations = noise.as_matrix() @ registration.apply_rotations(tool_rotations @ target)
    return MeasurementSet(
        joint_names=chain.joint_names,
        q=q,
        points=sensed,
        rotations=rotations,
        roles=np.array([role] * len(q), dtype=object),
        lines=np.arange(2, len(q) + 2),
        extra={**({} if time is None else {"time": np.asarray(time, dtype=float)}),
               **({} if temperature is None else {TEMPERATURE_COLUMN: np.asarray(temperature, dtype=float)})},
        source="<simulation>",
    )


def warm_up(time: np.ndarray, start_c: float = REFERENCE_C, rise_k: float = 6.0, tau_s: float = 1800.0) -> np.ndarray:
    """A cell warming up from ``start_c``: T(t) = start + rise (1 − exp(−t / τ)) [°C] at times ``time`` [s]
    from the start (default 20 → 26 °C with τ = 30 min, the exponential approach of a machine warming up)."""
    return start_c + rise_k * (1.0 - np.exp(-np.asarray(time, dtype=float) / tau_s))


def simulated_conditions(effects: Sequence[tuple[Effect, np.ndarray]], temperature: np.ndarray | None,
                         stepped: np.ndarray | None) -> RowConditions | None:
    """The rows' changes of eq T1–T2 (:mod:`pincal.model.thermal`) under ``effects``: a ``thermal`` α
    scales lengths by 1 + α (T − :data:`REFERENCE_C`) at row temperatures ``temperature`` [°C]; a
    ``pause_step`` d adds d to the rows where ``stepped`` (K,) is true (after the pause). None without either."""
    expansion = steps = None
    for effect, value in effects:
        if effect.type == "thermal":
            if temperature is None:
                raise PincalError("a simulated thermal expansion needs row temperatures")
            expansion = float(value[0]) * (np.asarray(temperature, dtype=float) - REFERENCE_C)
        elif effect.type == "pause_step":
            if stepped is None:
                raise PincalError("a simulated pause step needs the rows after the pause")
            steps = np.asarray(stepped, dtype=float)[:, None] * np.asarray(value, dtype=float).reshape(1, 3)
    return None if expansion is None and steps is None else RowConditions(expansion, steps)


def simulated_shifts(
    chain: KinematicChain, q: np.ndarray, effects: Sequence[tuple[Effect, np.ndarray]], time: np.ndarray | None
) -> np.ndarray:
    """Joint shifts (K, N) the effects cause at readings ``q`` taken at ``time`` (row order if None)."""
    inputs = EffectInputs(
        q=q,
        gravity=gravity_torques(chain, q),
        time=time,
        order=np.arange(len(q)) if time is None else np.argsort(time, kind="stable"),
        joint_names=tuple(chain.joint_names),
    )
    return chain.followed_shifts(joint_shifts([e for e, _ in effects], [v for _, v in effects], inputs,
                                              chain.joint_names))


def simulated_bends(chain: KinematicChain, q: np.ndarray, effects: Sequence[tuple[Effect, np.ndarray]]
                    ) -> np.ndarray | None:
    """The lateral deflections (K, 2N) [rad] the ``lateral`` effects among ``effects`` cause at readings ``q``
    under the URDF's inertias (eq L1 of :mod:`pincal.model.lateral`); None without one."""
    if not any(e.type in BEND_EFFECTS for e, _ in effects):
        return None
    inputs = EffectInputs(q=q, gravity=np.zeros_like(q), time=None, order=np.arange(len(q)),
                          joint_names=tuple(chain.joint_names), bending=bending_moments(chain, q))
    return bend_angles([e for e, _ in effects], [v for _, v in effects], inputs, chain.joint_names)


def perfect_measurements(chain: KinematicChain, data: MeasurementSet, registration: Registration) -> MeasurementSet:
    """``data`` as a noise-free sensor sees the chain in its current placements
    (eq 20–21 without N_k and zeta_k): its tool origin and orientation."""
    tool_rotations, tool_positions = chain.tool_poses(data.q)
    return replace(
        data,
        points=registration.apply_points(tool_positions)[:, None, :],
        rotations=registration.apply_rotations(tool_rotations),
    )


def sampling_limits(chain: KinematicChain | KinematicTree) -> tuple[np.ndarray, np.ndarray]:
    """The range configurations are drawn from: each joint's URDF limits, one turn (±pi) for a continuous
    joint, which has none [rad or m], (N,) lower and upper; a joint that follows another on the chain
    (URDF ``<mimic>``) keeps its driver within the range its own limits allow, and spans what that gives it."""
    lower = np.array([j.lower if np.isfinite(j.lower) else -np.pi for j in chain.joints])
    upper = np.array([j.upper if np.isfinite(j.upper) else np.pi for j in chain.joints])
    names = chain.joint_names
    for i, joint in enumerate(chain.joints):  # a follower's limits narrow its driver's range (eq M1)
        if joint.mimic is None or joint.mimic.driver not in names:
            continue
        d, m, o = names.index(joint.mimic.driver), joint.mimic.multiplier, joint.mimic.offset
        ends = sorted(((lower[i] - o) / m, (upper[i] - o) / m))
        lower[d], upper[d] = max(lower[d], ends[0]), min(upper[d], ends[1])
        if lower[d] > upper[d]:
            raise ModelError(f"{chain.source}: joint '{joint.name}' follows '{joint.mimic.driver}' (<mimic>) outside "
                             f"its own limits over all of '{joint.mimic.driver}''s; check the <mimic> and the limits")
        lower[i], upper[i] = sorted((m * lower[d] + o, m * upper[d] + o))
    return lower, upper


def random_configurations(chain: KinematicChain | KinematicTree, rng: np.random.Generator, count: int) -> np.ndarray:
    """Joint readings drawn uniformly within the limits (±pi for continuous joints, :func:`sampling_limits`),
    (count, N); a joint that follows another on the chain (URDF ``<mimic>``) follows its draw."""
    lower, upper = sampling_limits(chain)
    return chain.followed(rng.uniform(lower, upper, (count, len(lower))))
