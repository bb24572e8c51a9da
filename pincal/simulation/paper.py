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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain, pose_from_xyz_rpy
from pincal.model.dh.table import DHDeviations, DHTable
from pincal.model.effects import (
    Effect,
)
from pincal.model.sensor import Registration
from pincal.simulation.sensor import (
    DEFAULT_REGISTRATION,
    SimulatedEffects,
    SimulatedSensor,
    cpa_configurations,
    measure,
    random_configurations,
    simulated_conditions,
    simulated_shifts,
    warm_up,
)

__all__ = [
    "DEFAULT_TOOL_XYZ", "DEFAULT_TOOL_RPY", "SimulationSettings", "SimulatedExperiment", "simulate_experiment",
    "SECONDS_PER_ROW", "PAUSE_GAP_S",
]

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

    The chain is measured with the ground truth's placements and ``tool`` (``chain.placed``) and
    left as it was.
    ``effects`` are injected into the measurements without being declared; the
    rows get a ``time`` column (:data:`SECONDS_PER_ROW` apart, validation rows
    interleaved with the calibration rows) when there are effects; with a ``thermal`` effect a
    ``temperature_c`` column, a warm-up from 20 to 26 °C (:func:`pincal.simulation.sensor.warm_up`); with a
    ``pause_step`` the rows stop for :data:`PAUSE_GAP_S` halfway through the calibration and validation rows
    and the registration steps by it after the pause.
    """
    rng = np.random.default_rng(settings.seed)
    tool = pose_from_xyz_rpy(DEFAULT_TOOL_XYZ, DEFAULT_TOOL_RPY) if tool is None else tool
    truth = deviations.apply(nominal)
    lower = np.array([j.lower for j in chain.joints])
    upper = np.array([j.upper for j in chain.joints])
    sigma_p = settings.sigma_pos_mm / 1000.0
    sigma_a = np.radians(settings.sigma_rot_deg)
    with chain.placed(truth.joint_origins(), tool=tool):
        q_cpa = cpa_configurations(lower, upper, settings.n_cpa)
        q_cal = random_configurations(chain, rng, settings.n_calibration)
        q_val = random_configurations(chain, rng, settings.n_validation)
        times = _row_times(effects, len(q_cpa), len(q_cal), len(q_val))
        stepped = None
        if any(e.type == "pause_step" for e, _ in effects):  # a pause halfway through the late rows
            assert times is not None  # effects give times
            halfway = SECONDS_PER_ROW * (len(q_cpa) + (len(q_cal) + len(q_val)) // 2)
            stepped = times >= halfway
            times = times + PAUSE_GAP_S * stepped
        temperature = warm_up(times) if times is not None and any(e.type == "thermal" for e, _ in effects) else None
        conditions = simulated_conditions(effects, temperature, stepped)
        shifts = None  # over the whole session: approach flanks carry from one part to the next
        if effects:
            shifts = simulated_shifts(chain, np.vstack([q_cpa, q_cal, q_val]), effects, times)
        cut = np.cumsum([len(q_cpa), len(q_cal)])
        parts = [slice(0, cut[0]), slice(cut[0], cut[1]), slice(cut[1], None)]
        val_scale = 1.0 if settings.validation_noise else 0.0
        cpa, cal, val = (
            measure(chain, q, registration, rng, SimulatedSensor(sigma_p * noise, sigma_a * noise), role,
                    SimulatedEffects(effects, time=_part(times, p.start, p.stop), shifts=_part(shifts, p.start, p.stop),
                                     conditions=None if conditions is None else conditions.select(p),
                                     temperature=_part(temperature, p.start, p.stop)))
            for q, p, role, noise in zip((q_cpa, q_cal, q_val), parts, ("cpa", "calibration", "validation"),
                                         (1.0, 1.0, val_scale)))
    assert cpa.rotations is not None and cal.rotations is not None  # measured with orientations (measure's default)
    calibration = MeasurementSet(
        joint_names=cpa.joint_names,
        q=np.vstack([cpa.q, cal.q]),
        points=np.vstack([cpa.points, cal.points]),
        rotations=np.vstack([cpa.rotations, cal.rotations]),
        roles=np.concatenate([cpa.roles, cal.roles]),
        lines=np.arange(2, cpa.n_rows + cal.n_rows + 2),
        extra={name: np.concatenate([cpa.extra[name], cal.extra[name]]) for name in cpa.extra},
        source="<simulation>",
    )
    return SimulatedExperiment(calibration, val, truth, registration, tool)


#: Time between simulated rows when effects are injected [s].
SECONDS_PER_ROW = 10.0
#: The pause of a simulated ``pause_step`` [s]: 8 h, as on a real laser-tracker raster (an 8.4 h pause stepped 76 µm).
PAUSE_GAP_S = 8 * 3600.0


def _row_times(effects, n_cpa: int, n_calibration: int, n_validation: int) -> np.ndarray | None:
    """Times of the CPA, calibration and validation rows (in that order): the
    CPA runs first, then calibration and validation rows evenly interleaved."""
    if not effects:
        return None
    slots = np.arange(n_calibration + n_validation)
    validation: np.ndarray | list[int] = (
        np.round(np.linspace(0, len(slots) - 1, n_validation + 2)[1:-1]).astype(int) if n_validation else [])
    is_validation = np.isin(slots, validation)
    late = n_cpa + slots
    return SECONDS_PER_ROW * np.concatenate([np.arange(n_cpa), late[~is_validation], late[is_validation]]).astype(float)


def _part(values: np.ndarray | None, start: int, stop: int | None) -> np.ndarray | None:
    return None if values is None else values[start:stop]
