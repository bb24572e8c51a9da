"""Simulated measurements of the paper's experiment (Section 7).

Ground truth = default DH table + deviations (Table 2). The simulated sensor
sees the TCP through an arbitrary registration (Omega, tau) with noise:

    G_k = N_k Omega R_k,   N_k = R_ZYX(xi_k),  xi_k ~ N(0, sigma_a² I)   (eq 20, 22)
    g_k = Omega t_k + tau + zeta_k,            zeta_k ~ N(0, sigma_p² I)  (eq 21)

CPA rows move one joint at a time through K_alpha angles spread over its range
(eq 23), the other joints at zero; calibration and validation rows are drawn
uniformly within the joint limits. Everything is drawn from one seeded
numpy Generator, so a seed reproduces the data exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from typing import Sequence

from .chain import KinematicChain, points_in_base, pose_from_xyz_rpy
from .dh import DHDeviations, DHTable
from .effects import Effect, EffectInputs, gravity_torques, joint_shifts, sensed_points
from .errors import PincalError
from .measurements import MeasurementSet
from .registration import Registration

#: The arbitrary sensor registration of the simulations: sensor_T_base.
DEFAULT_REGISTRATION = Registration(
    rotation=Rotation.from_euler("ZYX", [35.0, -12.0, 8.0], degrees=True).as_matrix(),
    translation=np.array([1.85, -0.62, 0.43]),
)

#: The arbitrary tool F_T (flange_T_tool): TCP 62 mm off the last axis.
DEFAULT_TOOL_XYZ = (0.045, -0.043, 0.118)
DEFAULT_TOOL_RPY = (0.12, -0.25, 0.4)


@dataclass(frozen=True)
class SimulationSettings:
    """Settings of one simulated experiment (defaults: the paper's Section 7).

    Attributes:
        sigma_pos_mm: position noise sigma_p per axis [mm].
        sigma_rot_deg: orientation noise sigma_a per ZYX angle [deg].
        n_cpa: K_alpha, CPA configurations per joint.
        n_calibration: K, random calibration configurations.
        n_validation: J, random validation configurations.
        seed: seed of the random generator.
        validation_noise: add sensor noise to the validation rows too.
    """

    sigma_pos_mm: float = 0.0
    sigma_rot_deg: float = 0.0
    n_cpa: int = 40
    n_calibration: int = 100
    n_validation: int = 50
    seed: int = 0
    validation_noise: bool = True


@dataclass(frozen=True)
class SimulatedExperiment:
    """Simulated data and the truth behind it.

    Attributes:
        calibration: ``cpa`` rows followed by ``calibration`` rows.
        validation: ``validation`` rows.
        truth: ground-truth DH table.
        registration: the true sensor_T_base.
        tool: the true flange_T_tool (4, 4).
    """

    calibration: MeasurementSet
    validation: MeasurementSet
    truth: DHTable
    registration: Registration
    tool: np.ndarray


def cpa_configurations(lower: np.ndarray, upper: np.ndarray, per_joint: int) -> np.ndarray:
    """Eq 23: joint n at lower_n + k·delta_n (k = 1..K_alpha), others at zero; (N·K_alpha, N)."""
    n = len(lower)
    rows = []
    for joint in range(n):
        step = (upper[joint] - lower[joint]) / (per_joint + 1)
        block = np.zeros((per_joint, n))
        block[:, joint] = lower[joint] + step * np.arange(1, per_joint + 1)
        rows.append(block)
    return np.vstack(rows)


def measure(
    chain: KinematicChain,
    q: np.ndarray,
    registration: Registration,
    rng: np.random.Generator,
    sigma_pos_m: float,
    sigma_rot_rad: float,
    role: str,
    points: np.ndarray | None = None,
    target_rotation: np.ndarray | None = None,
    with_rotation: bool = True,
    effects: Sequence[tuple[Effect, np.ndarray]] = (),
    time: np.ndarray | None = None,
    shifts: np.ndarray | None = None,
) -> MeasurementSet:
    """What the simulated sensor reports at configurations ``q`` (eq 20–22).

    Args:
        points: target points in the tool frame (P, 3) [m]; default: the tool origin.
        target_rotation: the measured frame's rotation in the tool frame (default identity).
        with_rotation: also report orientations.
        effects: unmodelled effects acting on the robot and sensor, with their
            values (see :mod:`pincal.effects`); the readings ``q`` are written
            unchanged, the sensor sees the shifted joints.
        time: row times [s], written as the extra column ``time``; drift grows
            with it from t = 0.
        shifts: joint shifts of these rows (K, N) when computed over a longer
            sequence (approach flanks depend on the previous row); default:
            computed from these rows alone (:func:`simulated_shifts`).
    """
    actual = np.asarray(q, dtype=float)
    scale, drift = 0.0, np.zeros((len(q), 3))
    if effects:
        if shifts is None:
            shifts = simulated_shifts(chain, actual, effects, time)
        actual = actual + shifts
        for effect, value in effects:
            if effect.type == "sensor_scale":
                scale = float(value[0])
            elif effect.type == "drift":
                if time is None:
                    raise PincalError("a simulated drift needs row times")
                drift = time[:, None] * np.asarray(value, dtype=float)
    poses = chain.poses(actual)
    points = np.zeros((1, 3)) if points is None else np.asarray(points, dtype=float)
    world = points_in_base(poses.tool_positions, poses.tool_rotations, points)
    sensed = sensed_points(registration, world, scale, drift)
    sensed = sensed + rng.normal(0.0, 1.0, sensed.shape) * sigma_pos_m
    rotations = None
    if with_rotation:
        target = np.eye(3) if target_rotation is None else target_rotation
        noise = Rotation.from_euler("ZYX", rng.normal(0.0, 1.0, (len(q), 3)) * sigma_rot_rad)
        rotations = noise.as_matrix() @ registration.apply_rotations(poses.tool_rotations @ target)
    return MeasurementSet(
        joint_names=chain.joint_names,
        q=q,
        points=sensed,
        rotations=rotations,
        roles=np.array([role] * len(q), dtype=object),
        lines=np.arange(2, len(q) + 2),
        extra={} if time is None else {"time": np.asarray(time, dtype=float)},
        source="<simulation>",
    )


def simulated_shifts(
    chain: KinematicChain, q: np.ndarray, effects: Sequence[tuple[Effect, np.ndarray]], time: np.ndarray | None
) -> np.ndarray:
    """Joint shifts (K, N) the effects cause at readings ``q`` taken at ``time`` (row order if None)."""
    inputs = EffectInputs(
        q=q,
        gravity=gravity_torques(chain, q),
        time=time,
        order=np.arange(len(q)) if time is None else np.argsort(time, kind="stable"),
    )
    return joint_shifts([e for e, _ in effects], [v for _, v in effects], inputs, chain.joint_names)


def perfect_measurements(chain: KinematicChain, data: MeasurementSet, registration: Registration) -> MeasurementSet:
    """``data`` as a noise-free sensor sees the chain in its current placements
    (eq 20–21 without N_k and zeta_k): its tool origin and orientation."""
    poses = chain.poses(data.q)
    return replace(
        data,
        points=registration.apply_points(poses.tool_positions)[:, None, :],
        rotations=registration.apply_rotations(poses.tool_rotations),
    )


def random_configurations(chain: KinematicChain, rng: np.random.Generator, count: int) -> np.ndarray:
    """Joint readings drawn uniformly within the limits (±pi for continuous joints), (count, N)."""
    lower = np.array([j.lower if np.isfinite(j.lower) else -np.pi for j in chain.joints])
    upper = np.array([j.upper if np.isfinite(j.upper) else np.pi for j in chain.joints])
    return rng.uniform(lower, upper, (count, len(lower)))


def simulate_experiment(
    chain: KinematicChain,
    nominal: DHTable,
    deviations: DHDeviations,
    settings: SimulationSettings = SimulationSettings(),
    registration: Registration = DEFAULT_REGISTRATION,
    tool: np.ndarray | None = None,
    effects: Sequence[tuple[Effect, np.ndarray]] = (),
) -> SimulatedExperiment:
    """Simulate CPA, calibration and validation measurements of a DH chain.

    The chain's placements are set to the ground truth and restored afterwards.
    ``effects`` are injected into the measurements without being declared; the
    rows get a ``time`` column (:data:`SECONDS_PER_ROW` apart, validation rows
    interleaved with the calibration rows) when there are effects.
    """
    rng = np.random.default_rng(settings.seed)
    tool = pose_from_xyz_rpy(DEFAULT_TOOL_XYZ, DEFAULT_TOOL_RPY) if tool is None else tool
    truth = deviations.apply(nominal)
    saved_placements, saved_tool = chain.placements(), chain.tool
    chain.set_placements(truth.joint_origins())
    chain.set_tool(tool)
    lower = np.array([j.lower for j in chain.joints])
    upper = np.array([j.upper for j in chain.joints])
    sigma_p = settings.sigma_pos_mm / 1000.0
    sigma_a = np.radians(settings.sigma_rot_deg)
    try:
        q_cpa = cpa_configurations(lower, upper, settings.n_cpa)
        q_cal = random_configurations(chain, rng, settings.n_calibration)
        q_val = random_configurations(chain, rng, settings.n_validation)
        times = _row_times(effects, len(q_cpa), len(q_cal), len(q_val))
        shifts = None  # over the whole session: approach flanks carry from one part to the next
        if effects:
            shifts = simulated_shifts(chain, np.vstack([q_cpa, q_cal, q_val]), effects, times)
        cut = np.cumsum([len(q_cpa), len(q_cal)])
        cpa = measure(chain, q_cpa, registration, rng, sigma_p, sigma_a, "cpa",
                      effects=effects, time=_part(times, 0, cut[0]), shifts=_part(shifts, 0, cut[0]))
        cal = measure(chain, q_cal, registration, rng, sigma_p, sigma_a, "calibration",
                      effects=effects, time=_part(times, cut[0], cut[1]), shifts=_part(shifts, cut[0], cut[1]))
        val_scale = 1.0 if settings.validation_noise else 0.0
        val = measure(
            chain, q_val, registration, rng, sigma_p * val_scale, sigma_a * val_scale, "validation",
            effects=effects, time=_part(times, cut[1], None), shifts=_part(shifts, cut[1], None),
        )
    finally:
        chain.set_placements(saved_placements)
        chain.set_tool(saved_tool)
    calibration = MeasurementSet(
        joint_names=cpa.joint_names,
        q=np.vstack([cpa.q, cal.q]),
        points=np.vstack([cpa.points, cal.points]),
        rotations=np.vstack([cpa.rotations, cal.rotations]),
        roles=np.concatenate([cpa.roles, cal.roles]),
        lines=np.arange(2, cpa.n_rows + cal.n_rows + 2),
        extra={} if times is None else {"time": times[: cpa.n_rows + cal.n_rows]},
        source="<simulation>",
    )
    return SimulatedExperiment(calibration, val, truth, registration, tool)


#: Time between simulated rows when effects are injected [s].
SECONDS_PER_ROW = 10.0


def _row_times(effects, n_cpa: int, n_calibration: int, n_validation: int) -> np.ndarray | None:
    """Times of the CPA, calibration and validation rows (in that order): the
    CPA runs first, then calibration and validation rows evenly interleaved."""
    if not effects:
        return None
    slots = np.arange(n_calibration + n_validation)
    validation = np.round(np.linspace(0, len(slots) - 1, n_validation + 2)[1:-1]).astype(int) if n_validation else []
    is_validation = np.isin(slots, validation)
    late = n_cpa + slots
    return SECONDS_PER_ROW * np.concatenate([np.arange(n_cpa), late[~is_validation], late[is_validation]]).astype(float)


def _part(values: np.ndarray | None, start: int, stop: int | None) -> np.ndarray | None:
    return None if values is None else values[start:stop]


@dataclass(frozen=True)
class ChainExperiment:
    """Simulated measurements of any chain and the truth behind them.

    Attributes:
        calibration / validation: the simulated rows.
        truth: the true parameter vector of the parameter set used.
        registration: the true sensor_T_base.
        points: the true target points in the tool frame [m], (P, 3).
        target_rotation: the measured frame's rotation in the tool frame.
    """

    calibration: MeasurementSet
    validation: MeasurementSet
    truth: np.ndarray
    registration: Registration
    points: np.ndarray
    target_rotation: np.ndarray


def simulate_chain(
    params,
    truth: np.ndarray,
    points: np.ndarray,
    settings: SimulationSettings = SimulationSettings(),
    with_rotation: bool = False,
    target_rotation: np.ndarray | None = None,
    registration: Registration = DEFAULT_REGISTRATION,
) -> ChainExperiment:
    """Simulate random-configuration measurements of ``params.chain`` with the
    true parameters ``truth`` (a vector of the parameter set ``params``); the
    chain's placements are restored afterwards."""
    chain = params.chain
    rng = np.random.default_rng(settings.seed)
    target_rotation = np.eye(3) if target_rotation is None else target_rotation
    saved = chain.placements()
    sigma_p = settings.sigma_pos_mm / 1000.0
    sigma_a = np.radians(settings.sigma_rot_deg)
    try:
        params.apply(truth)
        q_cal = random_configurations(chain, rng, settings.n_calibration)
        q_val = random_configurations(chain, rng, settings.n_validation)
        common = dict(points=points, target_rotation=target_rotation, with_rotation=with_rotation)
        cal = measure(chain, q_cal, registration, rng, sigma_p, sigma_a, "calibration", **common)
        scale = 1.0 if settings.validation_noise else 0.0
        val = measure(chain, q_val, registration, rng, sigma_p * scale, sigma_a * scale, "validation", **common)
    finally:
        chain.set_placements(saved)
    return ChainExperiment(cal, val, np.asarray(truth, dtype=float), registration, np.asarray(points), target_rotation)
