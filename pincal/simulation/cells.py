"""Postures of real measuring cells: tool paths at constant orientation, as a robot program moves.

A laser-tracker session in an industrial cell is rarely a set of random postures:
the robot runs its program — straight lines, arcs, a surface raster — with the tool
orientation held constant by the controller, so in the controller's (nominal) model
the tool never turns, and the real tool turns only by the robot's own errors. This
module gives the joint readings of such paths: damped least-squares inverse
kinematics (Nakamura & Hanafusa 1986) of the chain's tool on Pinocchio's frame
Jacobian, each pose started from the previous one, as a controller interpolates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from pincal.errors import PincalError
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.sensor import Registration
from pincal.simulation.sensor import SimulatedEffects, SimulatedSensor, measure

__all__ = [
    "IK_TOLERANCE", "IK_MAX_STEP", "IK_DAMPING", "IK_ITERATIONS", "PATHS", "INDUSTRIAL_6R_TABLE", "INDUSTRIAL_6R_START",
    "inverse_kinematics", "path_positions", "ToolPath", "constant_orientation_path", "sensor_at", "measure_truth",
]

#: Pose error [m, rad] at which the inverse kinematics stops: far below any sensor's noise.
IK_TOLERANCE = 1e-12
#: Largest joint step of one inverse-kinematics iteration [rad or m]: keeps each pose on the
#: branch of the previous one (a controller's interpolation does not flip the elbow).
IK_MAX_STEP = 0.2
#: Damping of the least-squares step, λ² [m² or rad²]: tiny, only against exact singularities.
IK_DAMPING = 1e-10
IK_ITERATIONS = 200

PATHS = ("line", "arc", "raster")

#: A 6-axis industrial arm in modified DH (Craig; degrees and metres), KR-16-like but no vendor's
#: table: A2 turns forward to reach a bench in front of it, wrist joints ±350°. The simulated
#: cells of tests and scripts/scenarios.py use it (``pincal urdf-from-dh --convention modified --degrees``).
INDUSTRIAL_6R_TABLE = """\
joint,a,alpha,d,theta,lower,upper
A1,0,0,0.675,0,-185,185
A2,0.26,-90,0,-90,-155,155
A3,0.68,0,0,0,-130,154
A4,-0.035,-90,0.67,0,-350,350
A5,0,90,0,0,-130,130
A6,0,-90,0.115,180,-350,350
"""
#: A posture of that arm near the bench (tool down at x ≈ 1.2 m, z ≈ 0.5 m) to start paths from [rad].
INDUSTRIAL_6R_START = np.radians([0.0, 50.0, 10.0, 0.0, 30.0, 0.0])


def inverse_kinematics(chain: KinematicChain, rotation: np.ndarray, position: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """Joint readings (N,) putting the chain's tool at (``rotation``, ``position``) in the root frame,
    from ``q0`` (the chain's current placements; readings of continuous joints wrapped to ±π).

    Raises:
        PincalError: the pose is out of reach from ``q0`` (no convergence).
    """
    model, data = chain.model, chain.data
    frame = chain.tip_frame_id
    tool = pin.SE3(chain.tool)
    goal = pin.SE3(np.asarray(rotation, dtype=float), np.asarray(position, dtype=float))
    q = np.asarray(q0, dtype=float).copy()
    for _ in range(IK_ITERATIONS):
        configuration = chain.configurations(q[None, :])[0]
        pin.forwardKinematics(model, data, configuration)
        pin.updateFramePlacement(model, data, frame)
        current = data.oMf[frame] * tool
        error = pin.log6(current.actInv(goal)).vector  # in the tool frame
        if np.linalg.norm(error) < IK_TOLERANCE:
            return q
        jacobian = pin.computeFrameJacobian(model, data, configuration, frame, pin.LOCAL)
        jacobian = tool.inverse().toActionMatrix() @ jacobian  # the tool's body Jacobian
        step = np.linalg.solve(jacobian.T @ jacobian + IK_DAMPING * np.eye(len(q)), jacobian.T @ error)
        q += step * min(1.0, IK_MAX_STEP / max(np.abs(step).max(), 1e-300))
    raise PincalError(f"inverse kinematics: no posture reaches {np.round(position, 4).tolist()} m from the start")


def path_positions(kind: str, count: int, centre: np.ndarray, size_m: float, rows_per_line: int = 50,
                   heights: int = 3) -> np.ndarray:
    """Tool positions (count, 3) [m] along a path in the root frame's horizontal plane about ``centre``.

    ``line``: back and forth along x over ``size_m``, the passes stepped in z by size/6 through
    ``heights`` heights (1: every pass on one straight line); ``arc``: back and forth along a half
    circle of diameter ``size_m``, stepped likewise (1: one arc); ``raster``: a surface
    ``size_m`` × 2/3 ``size_m`` swept along x, reversing every ``rows_per_line`` rows.
    """
    if kind not in PATHS:
        raise PincalError(f"path must be one of {', '.join(PATHS)}, got '{kind}'")
    k = np.arange(count)
    line, i = np.divmod(k, rows_per_line)
    u = i / max(rows_per_line - 1, 1)
    u = np.where(line % 2 == 0, u, 1.0 - u)  # reversing
    out = np.tile(np.asarray(centre, dtype=float), (count, 1))
    if kind == "line":
        out[:, 0] += size_m * (u - 0.5)
        out[:, 2] += size_m / 6 * ((line % heights) - (heights - 1) / 2)
    elif kind == "arc":
        angle = np.pi * u
        out[:, 0] += size_m / 2 * np.cos(angle)
        out[:, 1] += size_m / 2 * np.sin(angle) - size_m / 4
        out[:, 2] += size_m / 6 * ((line % heights) - (heights - 1) / 2)
    else:
        lines = max(int(np.ceil(count / rows_per_line)), 1)
        out[:, 0] += size_m * (u - 0.5)
        out[:, 1] += size_m * 2 / 3 * (line / max(lines - 1, 1) - 0.5)
    return out


@dataclass(frozen=True)
class ToolPath:
    """A path of the tool's positions, :func:`path_positions`'s arguments.

    Attributes:
        kind: one of :data:`PATHS`.
        count: positions along it.
        centre: its centre in the root frame (3,) [m].
        size_m: its extent [m].
        rows_per_line: positions per pass.
        heights: passes stepped in z (``line``, ``arc``).
    """

    kind: str
    count: int
    centre: np.ndarray
    size_m: float = 0.6
    rows_per_line: int = 50
    heights: int = 3

    def positions(self) -> np.ndarray:
        """The tool positions (count, 3) [m]."""
        return path_positions(self.kind, self.count, self.centre, self.size_m, self.rows_per_line, self.heights)


def constant_orientation_path(chain: KinematicChain, path: ToolPath, rotation: np.ndarray, q_start: np.ndarray,
                              turn_rad: float = 0.0, rng: np.random.Generator | None = None) -> np.ndarray:
    """Joint readings (count, N) of the chain's tool moving along ``path`` with its orientation ``rotation``
    held (in the chain's current — the controller's — model), each commanded orientation turned by a random
    rotation vector of ``turn_rad`` RMS per axis (0: exactly constant, as a controller holds it)."""
    positions, count = path.positions(), path.count
    turns = np.zeros((count, 3)) if not turn_rad else (rng or np.random.default_rng(0)).normal(0.0, turn_rad,
                                                                                                (count, 3))
    q = inverse_kinematics(chain, rotation, positions[0], q_start)
    out = np.empty((count, chain.n_joints))
    for k in range(count):
        q = inverse_kinematics(chain, np.asarray(rotation) @ Rotation.from_rotvec(turns[k]).as_matrix(),
                               positions[k], q)
        out[k] = q
    return out


def sensor_at(distance_m: float, bearing_deg: float = 20.0, height_m: float = -0.5) -> Registration:
    """A sensor ``distance_m`` from the robot base, facing it: sensor_T_base with the base at that
    distance along a bearing of ``bearing_deg`` from the sensor's x axis and ``height_m`` below its origin."""
    bearing = np.radians(bearing_deg)
    horizontal = np.sqrt(max(distance_m**2 - height_m**2, 0.0))
    translation = np.array([horizontal * np.cos(bearing), horizontal * np.sin(bearing), height_m])
    rotation = Rotation.from_euler("ZYX", [bearing_deg + 180.0, 1.5, -0.8], degrees=True).as_matrix()
    return Registration(rotation=rotation, translation=translation)


def measure_truth(params, truth: np.ndarray, q: np.ndarray, registration: Registration,
                  rng: np.random.Generator, sensor: SimulatedSensor, role: str = "calibration",
                  effects: SimulatedEffects | None = None) -> MeasurementSet:
    """What the sensor reports at readings ``q`` when the robot's geometry is ``truth`` (a vector of the
    parameter set ``params``): :func:`pincal.simulation.sensor.measure` with the chain's placements set to
    the truth and restored after."""
    chain = params.chain
    with chain.placed(params.placements(np.asarray(truth, dtype=float))):
        return measure(chain, q, registration, rng, sensor, role, effects)
