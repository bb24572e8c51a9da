"""A serial arm given by a DH table: either convention, revolute and prismatic joints, limits.

:class:`DHRobot` is what ``pincal urdf-from-dh`` reads from a table file
(:mod:`pincal.model.dh.files`) and writes as a URDF
(:func:`pincal.model.dh.urdf.urdf_from_dh`). Its joint origins come from the
one DH-row core :func:`pincal.model.dh.table.dh_chain_origins`; :meth:`DHRobot.forward`
is the DH product itself, multiplied out of elementary transforms, so the two
can be checked against each other.

Conventions (angles [rad], lengths [m]):

* ``standard`` (distal, the paper's eq 4–5): row n holds alpha_n, a_n,
  theta_n, d_n and ``F_n = Rz(theta_n + q_n) Tz(d_n) Tx(a_n) Rx(alpha_n)``;
* ``modified`` (Craig's): row i holds alpha_{i-1}, a_{i-1}, theta_i, d_i and
  ``T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i + q_i) Tz(d_i)``.

For a prismatic joint q adds to d instead of theta.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from pincal.errors import ModelError
from pincal.model.dh.table import check_convention, dh_chain_origins, rot_x, rot_z, trans

__all__ = ["DH_JOINT_TYPES", "DEFAULT_LIMITS", "DEFAULT_VELOCITY", "DEFAULT_EFFORT", "DHRobot"]

#: Joint types a DH row can have.
DH_JOINT_TYPES = ("revolute", "prismatic", "continuous")
#: Position limits used when the table gives none: one turn either way [rad] for
#: revolute joints (every reading a single-turn encoder can give), ±1 m for
#: prismatic joints.
DEFAULT_LIMITS = {"revolute": (-np.pi, np.pi), "prismatic": (-1.0, 1.0),
                  "continuous": (-np.pi, np.pi)}  # a continuous joint's: where it is checked, never written
#: Velocity limit used when the table gives none [rad/s or m/s]: a placeholder,
#: not a property of any robot (URDF requires a value; calibration ignores it).
DEFAULT_VELOCITY = 1.0
#: Effort limit used when the table gives none [N·m or N]: a placeholder, as above.
DEFAULT_EFFORT = 100.0


def _column(values: npt.ArrayLike, n: int, what: str) -> np.ndarray:
    out = np.array(values, dtype=float).reshape(-1)
    if out.size != n:
        raise ModelError(f"DH robot: column {what} has {out.size} values for {n} joints")
    if not np.all(np.isfinite(out)):
        raise ModelError(f"DH robot: column {what} has a non-finite value: {out.tolist()}")
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class DHRobot:
    """A serial arm described by a DH table, one row per joint.

    Attributes:
        convention: ``standard`` or ``modified`` (see the module docstring).
        names: joint names, in chain order (N,).
        alpha: link twists [rad] (N,); alpha_n (standard) or alpha_{n-1} (modified).
        a: link lengths [m] (N,); a_n (standard) or a_{n-1} (modified).
        theta: joint angle offsets [rad] (N,): the DH angle is ``theta + q``
            for a revolute joint.
        d: link offsets [m] (N,): the DH offset is ``d + q`` for a prismatic joint.
        types: ``revolute``, ``prismatic`` or ``continuous`` (revolute without position limits) per joint (N,).
        lower, upper: position limits [rad or m] (N,).
        velocity: velocity limits [rad/s or m/s] (N,).
        effort: effort limits [N·m or N] (N,).
    """

    convention: str
    names: tuple[str, ...]
    alpha: np.ndarray
    a: np.ndarray
    theta: np.ndarray
    d: np.ndarray
    types: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray

    if TYPE_CHECKING:  # for type checkers only: the constructor takes array-likes (__post_init__ converts them)

        def __init__(  # noqa: PLR0913 - the dataclass's own constructor: one argument per column of the table
            self, convention: str, names: tuple[str, ...], alpha: npt.ArrayLike, a: npt.ArrayLike,
            theta: npt.ArrayLike, d: npt.ArrayLike, types: tuple[str, ...], lower: npt.ArrayLike,
            upper: npt.ArrayLike, velocity: npt.ArrayLike, effort: npt.ArrayLike,
        ) -> None: ...

    def __post_init__(self) -> None:
        check_convention(self.convention)
        names = tuple(str(n) for n in self.names)
        n = len(names)
        if n == 0:
            raise ModelError("DH robot: the table has no joints")
        if len(set(names)) != n or not all(names):
            raise ModelError(f"DH robot: joint names must be distinct and non-empty, got {list(names)}")
        types = tuple(str(t) for t in self.types)
        if len(types) != n or any(t not in DH_JOINT_TYPES for t in types):
            raise ModelError(f"DH robot: joint types must be one of {', '.join(DH_JOINT_TYPES)} "
                             f"per joint, got {list(types)}")
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "types", types)
        for field in ("alpha", "a", "theta", "d", "lower", "upper", "velocity", "effort"):
            object.__setattr__(self, field, _column(getattr(self, field), n, field))
        bad = np.flatnonzero(self.lower > self.upper)
        if bad.size:
            raise ModelError(f"DH robot: joint '{names[bad[0]]}' has lower limit "
                             f"{self.lower[bad[0]]:g} > upper limit {self.upper[bad[0]]:g}")

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def joint_origins(self, flange: npt.ArrayLike | None = None) -> list[np.ndarray]:
        """URDF origins of the N joints and of the fixed flange joint (4x4 each).

        Args:
            flange: constant ``frameN_T_flange`` appended to the last DH frame
                (identity if None) [m].
        """
        origins = dh_chain_origins(self.convention, self.alpha, self.a, self.theta, self.d)
        if flange is not None:
            origins[-1] = origins[-1] @ np.asarray(flange, dtype=float)
        return origins

    def link_transform(self, n: int, q: float) -> np.ndarray:
        """The DH transform of row ``n`` (0-based) at joint value ``q`` [rad or m],
        multiplied out of elementary transforms (no shared code with the origins)."""
        revolute = self.types[n] != "prismatic"  # revolute or continuous: q adds to theta
        angle = self.theta[n] + (q if revolute else 0.0)
        offset = self.d[n] + (0.0 if revolute else q)
        if self.convention == "standard":
            return rot_z(angle) @ trans(z=offset) @ trans(x=self.a[n]) @ rot_x(self.alpha[n])
        return rot_x(self.alpha[n]) @ trans(x=self.a[n]) @ rot_z(angle) @ trans(z=offset)

    def forward(self, q: npt.ArrayLike) -> np.ndarray:
        """Pose of the last DH frame in DH frame 0 for joint values ``q`` (N,) [rad or m], (4, 4)."""
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.size != self.n_joints:
            raise ModelError(f"expected {self.n_joints} joint values, got {q.size}")
        pose = np.eye(4)
        for n in range(self.n_joints):
            pose = pose @ self.link_transform(n, q[n])
        return pose
