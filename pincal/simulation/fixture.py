"""Simulated socket-fixture data: joint readings that put the ball exactly in a socket.

For each placement (base_T_fixture) and each socket, configurations are found
by inverse kinematics of the chain *as it is* (set the true placements first)
from random starts within the joint limits: scipy's dogleg least squares with
the limits as box constraints (``method="dogbox"``) on the ball's position, with the ball's Jacobian from
Pinocchio's frame Jacobian (v + ω × (p − o), LOCAL_WORLD_ALIGNED). A
redundant arm reaches one socket from many directions, as a hand-guided
recording does. Noise, if wanted, is added to the joint readings afterwards.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pinocchio as pin
from scipy.optimize import least_squares

from pincal.errors import CalibrationError
from pincal.measurements.fixture import Fixture, FixtureData, check_placements
from pincal.model.chain import KinematicChain
from pincal.simulation.sensor import sampling_limits

__all__ = ["IK_TOLERANCE", "IK_ATTEMPTS", "IK_EVALUATIONS", "reach", "simulate_fixture", "ball_and_jacobian"]

#: A configuration is accepted when the ball is this close to the socket [m].
IK_TOLERANCE = 1e-12
#: Random starts tried per row before giving up.
IK_ATTEMPTS = 50
#: Evaluations per start (Gauss-Newton converges quadratically once close).
IK_EVALUATIONS = 30


def ball_and_jacobian(chain: KinematicChain, q: np.ndarray, ball: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ball centre [m] (3,) and its derivative by the joints (3, N) at one configuration ``q``."""
    model, data = chain.model, chain.data
    config = chain.configurations(q[None])[0]
    jacobian = pin.computeFrameJacobian(model, data, config, chain.tip_frame_id, pin.LOCAL_WORLD_ALIGNED)
    tip = data.oMf[chain.tip_frame_id]  # updated by computeFrameJacobian
    tool = tip.homogeneous @ chain.tool
    point = tool[:3, :3] @ ball + tool[:3, 3]
    offset = point - tip.translation
    return point, jacobian[:3] + np.cross(jacobian[3:].T, offset).T


def reach(chain: KinematicChain, target: npt.ArrayLike, ball: npt.ArrayLike, rng: np.random.Generator) -> np.ndarray:
    """A configuration (N,) within the limits that puts ``ball`` (tool frame) at ``target`` (root frame) [m].

    Raises:
        CalibrationError: no start of :data:`IK_ATTEMPTS` reached the target.
    """
    target, ball = np.asarray(target, dtype=float), np.asarray(ball, dtype=float)
    lower, upper = sampling_limits(chain)
    margin = 0.02 * (upper - lower)  # starts away from the stops
    for _ in range(IK_ATTEMPTS):
        start = rng.uniform(lower + margin, upper - margin)
        result = least_squares(
            lambda q: ball_and_jacobian(chain, q, ball)[0] - target,
            start,
            jac=lambda q: ball_and_jacobian(chain, q, ball)[1],
            bounds=(lower, upper),
            method="dogbox",
            xtol=1e-14,
            ftol=None,
            gtol=None,
            max_nfev=IK_EVALUATIONS,
        )
        if np.linalg.norm(result.fun) < IK_TOLERANCE:
            return result.x
    raise CalibrationError(f"no configuration puts the ball at {target} m; move the socket within reach")


def simulate_fixture(
    chain: KinematicChain,
    fixture: Fixture,
    poses: Sequence[np.ndarray],
    ball: npt.ArrayLike,
    rows_per_socket: int,
    rng: np.random.Generator,
    names: Sequence[str] | None = None,
    joint_noise_rad: float = 0.0,
) -> FixtureData:
    """Rows with the ball in every socket of ``fixture`` in every placement.

    Args:
        chain: the true robot (its current placements).
        fixture: socket centres in the fixture frame.
        poses: base_T_fixture of each placement (4, 4).
        ball: the ball centre in the chain's tool frame [m], (3,).
        rows_per_socket: configurations per socket and placement.
        rng: random starts (and noise).
        names: placement names (default ``p0``, ``p1``, ...).
        joint_noise_rad: standard deviation of noise added to every joint reading.
    """
    names = tuple(names) if names is not None else tuple(f"p{s}" for s in range(len(poses)))
    reached, socket, placement = [], [], []
    for s, pose in enumerate(poses):
        pose = np.asarray(pose, dtype=float)
        for i, point in enumerate(fixture.points):
            target = pose[:3, :3] @ point + pose[:3, 3]
            for _ in range(rows_per_socket):
                reached.append(reach(chain, target, ball, rng))
                socket.append(i)
                placement.append(s)
    q = (np.array(reached) + rng.normal(0.0, joint_noise_rad, (len(reached), chain.n_joints)) if joint_noise_rad
         else np.array(reached))
    k = len(q)
    data = FixtureData(chain.joint_names, q, np.array(socket), np.array(placement), names, fixture,
                       np.arange(2, k + 2), np.zeros(k, dtype=int), ("<simulated>",))
    check_placements(data)
    return data
