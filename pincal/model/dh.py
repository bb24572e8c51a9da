"""Denavit–Hartenberg tables (distal variant) and their URDF joint placements.

The distal convention of Franaszek & Marvel (2022), eq 4–5::

    F_n = Rz(theta_n + eps_n) · Tz(d_n) · Tx(r_n) · Rx(alpha_n)

with theta_n the encoder angle of joint n, eps_n its zero offset, alpha_n the link
twist, r_n the link length and d_n the link offset. Frame n is attached to link n;
joint n turns about the z axis of frame n-1.

A URDF joint can only place the joint axis and then rotate about it
(``parent_T_child = origin · Rz(q)``), so the DH product is regrouped: the
translation and twist of row n-1 and the zero offset of row n go into the origin
of joint n, see :meth:`DHTable.joint_origins`. The child link of joint n is frame
n-1 turned by ``theta_n + eps_n``; the fixed joint after the last revolute joint
carries row N's ``Tz·Tx·Rx`` and its child is DH frame N (the flange).

Units: angles in radians, lengths in metres (Table 1 of the paper is in degrees
and millimetres; the constants below convert).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import numpy.typing as npt

from pincal.errors import PincalError

#: Order of the four DH rows in a flat parameter vector.
DH_FIELDS = ("alpha", "epsilon", "r", "d")


def rot_x(angle: float) -> np.ndarray:
    """Homogeneous rotation about x by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_z(angle: float) -> np.ndarray:
    """Homogeneous rotation about z by ``angle`` [rad]."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """Homogeneous translation [m]."""
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


@dataclass(frozen=True)
class DHTable:
    """A distal DH table of N revolute joints.

    Attributes:
        alpha: link twists alpha_n [rad], shape (N,).
        epsilon: encoder zero offsets eps_n [rad], shape (N,).
        r: link lengths r_n [m], shape (N,).
        d: link offsets d_n [m], shape (N,).
    """

    alpha: np.ndarray
    epsilon: np.ndarray
    r: np.ndarray
    d: np.ndarray

    def __post_init__(self) -> None:
        arrays = {}
        for name in DH_FIELDS:
            value = np.array(getattr(self, name), dtype=float).reshape(-1)
            value.setflags(write=False)
            arrays[name] = value
        sizes = {a.size for a in arrays.values()}
        if len(sizes) != 1 or 0 in sizes:
            raise PincalError(
                "DH table rows must have the same non-zero length, got "
                + ", ".join(f"{k}={v.size}" for k, v in arrays.items())
            )
        for name, value in arrays.items():
            if not np.all(np.isfinite(value)):
                raise PincalError(f"DH table row {name} has a non-finite value: {value}")
            object.__setattr__(self, name, value)

    @property
    def n_joints(self) -> int:
        return int(self.alpha.size)

    @classmethod
    def from_degrees_mm(
        cls,
        alpha_deg: Sequence[float],
        epsilon_deg: Sequence[float],
        r_mm: Sequence[float],
        d_mm: Sequence[float],
    ) -> "DHTable":
        """Build a table from the paper's units (degrees, millimetres)."""
        return cls(
            alpha=np.radians(alpha_deg),
            epsilon=np.radians(epsilon_deg),
            r=np.asarray(r_mm, dtype=float) / 1000.0,
            d=np.asarray(d_mm, dtype=float) / 1000.0,
        )

    def to_vector(self) -> np.ndarray:
        """Flat vector ``[alpha, epsilon, r, d]`` (rad, rad, m, m), shape (4N,)."""
        return np.concatenate([getattr(self, name) for name in DH_FIELDS])

    @classmethod
    def from_vector(cls, vector: npt.ArrayLike) -> "DHTable":
        """Inverse of :meth:`to_vector`."""
        v = np.asarray(vector, dtype=float).reshape(4, -1)
        return cls(alpha=v[0], epsilon=v[1], r=v[2], d=v[3])

    def __add__(self, other: "DHTable") -> "DHTable":
        if not isinstance(other, DHTable):
            return NotImplemented
        if other.n_joints != self.n_joints:
            raise PincalError(
                f"cannot add DH tables of {self.n_joints} and {other.n_joints} joints"
            )
        return DHTable.from_vector(self.to_vector() + other.to_vector())

    def __sub__(self, other: "DHTable") -> "DHTable":
        if not isinstance(other, DHTable):
            return NotImplemented
        return DHTable.from_vector(self.to_vector() - other.to_vector())

    def link_transform(self, n: int, theta: float) -> np.ndarray:
        """F_n of eq 4–5 for row ``n`` (0-based) at encoder angle ``theta`` [rad]."""
        return (
            rot_z(theta + self.epsilon[n])
            @ trans(z=self.d[n])
            @ trans(x=self.r[n])
            @ rot_x(self.alpha[n])
        )

    def forward(self, theta: npt.ArrayLike) -> np.ndarray:
        """Flange pose ``F_1 ··· F_N`` (eq 2 without the tool), shape (4, 4)."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        if theta.size != self.n_joints:
            raise PincalError(f"expected {self.n_joints} joint angles, got {theta.size}")
        pose = np.eye(4)
        for n in range(self.n_joints):
            pose = pose @ self.link_transform(n, theta[n])
        return pose

    @classmethod
    def from_joint_origins(
        cls,
        origins: Sequence[npt.ArrayLike],
        tol: float = 1e-9,
        names: Sequence[str] | None = None,
    ) -> "DHTable":
        """Inverse of :meth:`joint_origins`: read a table back from N + 1 origins.

        Args:
            origins: origin of joint 1 .. N and of the flange joint (4x4 each).
            tol: largest deviation from the DH shape accepted.
            names: joint names, for messages (default: "origin <index>").

        Raises:
            PincalError: an origin is not of the DH shape; the message names it.
        """
        mats = [np.asarray(o, dtype=float) for o in origins]
        n_joints = len(mats) - 1
        if n_joints < 1:
            raise PincalError("need at least two origins (one joint and the flange)")
        labels = list(names) if names is not None else [f"origin {i}" for i in range(len(mats))]
        alpha, eps, r, d = (np.zeros(n_joints) for _ in range(4))
        eps[0] = np.arctan2(mats[0][1, 0], mats[0][0, 0])
        if np.abs(mats[0] - rot_z(eps[0])).max() > tol:
            raise PincalError(f"{labels[0]}: not a pure rotation about z (DH Rz(eps_1))")
        for n in range(n_joints):
            m = mats[n + 1]
            last = n + 1 == n_joints
            r[n], d[n] = m[0, 3], m[2, 3]
            alpha[n] = np.arctan2(-m[1, 2], m[2, 2])
            expected = trans(z=d[n]) @ trans(x=r[n]) @ rot_x(alpha[n])
            if not last:
                eps[n + 1] = np.arctan2(-m[0, 1], m[0, 0])
                expected = expected @ rot_z(eps[n + 1])
            deviation = np.abs(m - expected).max()
            if deviation > tol:
                shape = "Tz(d) Tx(r) Rx(alpha)" + ("" if last else " Rz(eps)")
                raise PincalError(
                    f"{labels[n + 1]}: not of the DH shape {shape} (deviation {deviation:.3g})"
                )
        return cls(alpha=alpha, epsilon=eps, r=r, d=d)

    def joint_origins(self) -> list[np.ndarray]:
        """URDF joint origins realising this table; see :func:`dh_joint_origins`."""
        return dh_joint_origins(self.to_vector())


def dh_joint_origins(vector: npt.ArrayLike) -> list[np.ndarray]:
    """URDF joint origins realising the table ``[alpha, epsilon, r, d]`` (4N,), N + 1 matrices.

    Entry 0 is the origin of joint 1 in DH frame 0: ``Rz(eps_1)``. Entry n
    (1 <= n < N) is the origin of joint n+1 in the child link of joint n:
    ``Tz(d_n) Tx(r_n) Rx(alpha_n) Rz(eps_{n+1})``. Entry N is the origin of the
    fixed flange joint: ``Tz(d_N) Tx(r_N) Rx(alpha_N)``. Chaining
    ``origin_n · Rz(theta_n)`` reproduces ``F_1 ··· F_N`` exactly.
    """
    alpha, epsilon, r, d = np.asarray(vector, dtype=float).reshape(4, -1)
    n = alpha.size
    eps_next = np.append(epsilon[1:], 0.0)  # the flange row has no Rz
    ca, sa = np.cos(alpha), np.sin(alpha)
    ce, se = np.cos(eps_next), np.sin(eps_next)
    rows = np.zeros((n, 4, 4))
    # Tz(d) Tx(r) Rx(alpha) Rz(eps) in closed form
    rows[:, 0, 0], rows[:, 0, 1], rows[:, 0, 3] = ce, -se, r
    rows[:, 1, 0], rows[:, 1, 1], rows[:, 1, 2] = ca * se, ca * ce, -sa
    rows[:, 2, 0], rows[:, 2, 1], rows[:, 2, 2], rows[:, 2, 3] = sa * se, sa * ce, ca, d
    rows[:, 3, 3] = 1.0
    return [rot_z(epsilon[0])] + list(rows)


@dataclass(frozen=True)
class DHDeviations:
    """A named set of deviations from a default table (Table 2 of the paper).

    Attributes:
        name: label used on the command line (``small``, ``large``, ...).
        delta: the deviations as a :class:`DHTable` (rad, m).
    """

    name: str
    delta: DHTable = field(repr=False)

    def apply(self, table: DHTable) -> DHTable:
        """Ground truth = defaults + deviations."""
        return table + self.delta


# Table 1 of Franaszek & Marvel (2022): KUKA LWR 4+ default DH parameters
# (degrees, millimetres).
KUKA_LWR4_DH = DHTable.from_degrees_mm(
    alpha_deg=[-90, -90, -90, 90, 90, -90, 0],
    epsilon_deg=[180, 90, 0, 0, 0, 0, 0],
    r_mm=[0, 0, 0, 0, 0, 0, 0],
    d_mm=[310.5, 0, 400, 0, 390, 0, 78],
)

# Table 2: deviations. Delta-epsilon is shared by both sets.
_TABLE2_DEPS_DEG = [0, -1.4, 0.68, 0.24, 0.54, 1.37, 0.85]

TABLE2_SMALL = DHDeviations(
    name="small",
    delta=DHTable.from_degrees_mm(
        alpha_deg=[0.15, -0.1, 0.07, -0.04, 0.02, -0.06, 0],
        epsilon_deg=_TABLE2_DEPS_DEG,
        r_mm=[0.25, 0.4, 0.09, 0.3, 0.28, 0.17, 0.06],
        d_mm=[0, 0.06, -0.14, 0.12, 0.27, 0.08, 0.3],
    ),
)

TABLE2_LARGE = DHDeviations(
    name="large",
    delta=DHTable.from_degrees_mm(
        alpha_deg=[3.35, -4.1, 2.7, -3.4, 4.2, -3.6, 0],
        epsilon_deg=_TABLE2_DEPS_DEG,
        r_mm=[0.8, 1.3, 0.65, 1.4, 0.86, 0.38, 0.55],
        d_mm=[0, 0.27, -1.45, 0.4, 1.26, 0.3, 0.35],
    ),
)

DEVIATION_SETS = {dev.name: dev for dev in (TABLE2_SMALL, TABLE2_LARGE)}


def random_deviations_like(
    reference: DHDeviations, rng: np.random.Generator, name: str = "random"
) -> DHDeviations:
    """Deviations of the same size as ``reference``, with random signs and magnitudes.

    Each entry is drawn uniformly in ``[-|ref|, |ref|]`` scaled so that its
    magnitude is at least half the reference's; entries that are zero in the
    reference (alpha_N, d_1, eps_1) stay zero.
    """
    ref = reference.delta.to_vector()
    magnitude = np.abs(ref) * rng.uniform(0.5, 1.0, size=ref.size)
    sign = rng.choice([-1.0, 1.0], size=ref.size)
    return DHDeviations(name=name, delta=DHTable.from_vector(sign * magnitude))
