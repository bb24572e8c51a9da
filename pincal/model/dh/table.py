"""Denavit–Hartenberg tables and their URDF joint placements, in both conventions.

:class:`DHTable` is the paper's table: the distal (standard) convention of
Franaszek & Marvel (2022), eq 4–5::

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

:func:`dh_chain_origins` places the joints of a table in either convention,
``standard`` (distal, as above) or ``modified`` (proximal, Craig's
``Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``), every origin through the
one DH row → joint origin core :func:`dh_origin_rows`;
:func:`dh_chain_from_origins` reads a table back from the origins.

Units: angles in radians, lengths in metres (Table 1 of the paper is in degrees
and millimetres; the constants below convert).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from pincal.errors import ModelError, PincalError
from pincal.model.dh.conventions import DH_CONVENTIONS

__all__ = [
    "DH_FIELDS", "rot_x", "rot_z", "trans", "DHTable", "dh_joint_origins", "DH_CONVENTIONS", "check_convention",
    "dh_origin_rows", "dh_chain_origins", "dh_chain_from_origins", "DHDeviations", "KUKA_LWR4_DH", "TABLE2_SMALL",
    "TABLE2_LARGE", "DEVIATION_SETS", "random_deviations_like",
]

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
    ) -> DHTable:
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
    def from_vector(cls, vector: npt.ArrayLike) -> DHTable:
        """Inverse of :meth:`to_vector`."""
        v = np.asarray(vector, dtype=float).reshape(4, -1)
        return cls(alpha=v[0], epsilon=v[1], r=v[2], d=v[3])

    def __add__(self, other: DHTable) -> DHTable:
        if not isinstance(other, DHTable):
            return NotImplemented
        if other.n_joints != self.n_joints:
            raise PincalError(
                f"cannot add DH tables of {self.n_joints} and {other.n_joints} joints"
            )
        return DHTable.from_vector(self.to_vector() + other.to_vector())

    def __sub__(self, other: DHTable) -> DHTable:
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
    ) -> DHTable:
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
    ``origin_n · Rz(theta_n)`` reproduces ``F_1 ··· F_N`` exactly. This is
    :func:`dh_chain_origins` with the ``standard`` convention.
    """
    alpha, epsilon, r, d = np.asarray(vector, dtype=float).reshape(4, -1)
    return dh_chain_origins("standard", alpha, r, epsilon, d)


def check_convention(convention: str) -> str:
    """``convention`` if it is one of :data:`DH_CONVENTIONS` (the one check of pincal's DH code).

    Raises:
        ModelError: naming the conventions.
    """
    if convention not in DH_CONVENTIONS:
        raise ModelError(f"unknown DH convention '{convention}'; use one of {', '.join(DH_CONVENTIONS)}")
    return convention


def dh_origin_rows(
    alpha: npt.ArrayLike,
    a: npt.ArrayLike,
    theta: npt.ArrayLike,
    d_before: npt.ArrayLike,
    d_after: npt.ArrayLike,
) -> np.ndarray:
    """``Tz(d_before) · Tx(a) · Rx(alpha) · Rz(theta) · Tz(d_after)`` in closed form, (n, 4, 4).

    The one "DH row → joint origin" of pincal: every joint origin of a DH chain,
    in either convention, is of this shape (:func:`dh_chain_origins`). Angles
    [rad], lengths [m], arrays of the same length n. ``Tx`` and ``Rx`` commute,
    so ``Rx(alpha) Tx(a)`` (Craig's order) is the same matrix.
    """
    alpha, a, theta, d_before, d_after = (
        np.asarray(v, dtype=float).reshape(-1) for v in (alpha, a, theta, d_before, d_after)
    )
    ca, sa = np.cos(alpha), np.sin(alpha)
    ct, st = np.cos(theta), np.sin(theta)
    (n,) = np.broadcast_shapes(alpha.shape, a.shape, theta.shape, d_before.shape, d_after.shape)
    # the 16 entries of each matrix, row-major: an entry's n values are contiguous, cheap to fill
    entries = np.zeros((16, n))
    # rotation Rx(alpha) Rz(theta); translation (a, 0, d_before) + Rx(alpha) Rz(theta) (0, 0, d_after)
    entries[0], entries[1], entries[3] = ct, -st, a
    entries[4], entries[5], entries[6], entries[7] = ca * st, ca * ct, -sa, -sa * d_after
    entries[8], entries[9], entries[10], entries[11] = sa * st, sa * ct, ca, d_before + ca * d_after
    entries[15] = 1.0
    return np.ascontiguousarray(entries.T).reshape(n, 4, 4)


def dh_chain_origins(
    convention: str,
    alpha: npt.ArrayLike,
    a: npt.ArrayLike,
    theta: npt.ArrayLike,
    d: npt.ArrayLike,
) -> list[np.ndarray]:
    """URDF joint origins of an N-row DH table: N joint origins, then the fixed flange joint's.

    Each joint moves by ``Rz(q)`` (revolute) or ``Tz(q)`` (prismatic: q adds to d)
    after its origin, about the z axis of its child link; every origin is one
    :func:`dh_origin_rows` row.

    * ``standard`` (distal; Franaszek & Marvel 2022, eq 4–5), row n of the table
      holds alpha_n, a_n, theta_n, d_n and
      ``F_n = Rz(theta_n + q_n) Tz(d_n) Tx(a_n) Rx(alpha_n)``. The origin of joint 1
      is ``Rz(theta_1)``, that of joint n+1 ``Tz(d_n) Tx(a_n) Rx(alpha_n) Rz(theta_{n+1})``,
      the flange's ``Tz(d_N) Tx(a_N) Rx(alpha_N)``. The child link of joint n is
      DH frame n-1 moved by joint n (not DH frame n).
    * ``modified`` (proximal; Craig, *Introduction to Robotics*, eq 3.6), row i
      holds alpha_{i-1}, a_{i-1}, theta_i, d_i and
      ``T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i + q_i) Tz(d_i)``. The origin of
      joint i is ``Tx(a_{i-1}) Rx(alpha_{i-1}) Rz(theta_i) Tz(d_i)`` (Rz(q) and
      Tz(d) commute), so the child link of joint i is DH frame i; the flange's
      origin is the identity.

    Args:
        convention: ``standard`` or ``modified``.
        alpha, a, theta, d: the table's columns (N,) [rad, m, rad, m]; theta is
            the joint's constant offset.

    Returns:
        N + 1 matrices (4, 4): chaining ``origin_n · motion(q_n)`` and the flange
        origin reproduces the DH product exactly.
    """
    alpha, a, theta, d = (np.asarray(v, dtype=float).reshape(-1) for v in (alpha, a, theta, d))
    padded = np.zeros((4, alpha.size + 1))  # the columns with a zero added before or after
    if check_convention(convention) == "standard":
        padded[0, 1:], padded[1, 1:], padded[2, :-1], padded[3, 1:] = alpha, a, theta, d
        rows = dh_origin_rows(padded[0], padded[1], padded[2], padded[3], 0.0)
    else:  # modified
        padded[:, :-1] = alpha, a, theta, d
        rows = dh_origin_rows(padded[0], padded[1], padded[2], 0.0, padded[3])
    return list(rows)


def dh_chain_from_origins(
    convention: str,
    origins: Sequence[npt.ArrayLike],
    tol: float = 1e-9,
    names: Sequence[str] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`dh_chain_origins`: ``(alpha, a, theta, d)`` (N,) each [rad, m, rad, m]
    from N + 1 origins; angles in (-pi, pi].

    Args:
        convention: ``standard`` or ``modified``.
        origins: the N joint origins and the flange joint's (4x4 each).
        tol: largest deviation from the DH shape accepted [m, -].
        names: labels of the origins, for messages.

    Raises:
        PincalError: an origin is not of the convention's shape; the message names it.
    """
    if check_convention(convention) == "standard":
        table = DHTable.from_joint_origins(origins, tol=tol, names=names)
        return table.alpha.copy(), table.r.copy(), table.epsilon.copy(), table.d.copy()
    mats = np.array([np.asarray(o, dtype=float) for o in origins])
    labels = list(names) if names is not None else [f"origin {i}" for i in range(len(mats))]
    if len(mats) < 2:
        raise PincalError("need at least two origins (one joint and the flange)")
    rows = mats[:-1]
    alpha = np.arctan2(-rows[:, 1, 2], rows[:, 2, 2])
    theta = np.arctan2(-rows[:, 0, 1], rows[:, 0, 0])
    a = rows[:, 0, 3]
    d = -np.sin(alpha) * rows[:, 1, 3] + np.cos(alpha) * rows[:, 2, 3]
    expected = dh_origin_rows(alpha, a, theta, 0.0, d)
    for i, (m, e) in enumerate(zip(rows, expected)):
        deviation = np.abs(m - e).max()
        if deviation > tol:
            raise PincalError(f"{labels[i]}: not of the modified DH shape Tx(a) Rx(alpha) Rz(theta) Tz(d) "
                              f"(deviation {deviation:.3g})")
    deviation = np.abs(mats[-1] - np.eye(4)).max()
    if deviation > tol:
        raise PincalError(f"{labels[-1]}: the flange origin of a modified DH chain is the identity "
                          f"(deviation {deviation:.3g})")
    return alpha, a, theta, d


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
