"""Refuse candidate configurations in self-collision or closer than a clearance (``--min-distance``).

The URDF's collision geometry is loaded with Pinocchio (``buildGeomFromUrdf``,
coal underneath) and reduced to the chain like the kinematic model: every
joint off the chain is locked at its neutral value, so links that never move
relative to each other share a joint and are not paired. As in an SRDF's
"default"/"adjacent" pairs, pairs closer than the clearance at the zero
configuration (clipped into the joint limits) — adjacent links touch there —
are ignored. A candidate is refused when any remaining pair is closer than the
clearance (coal's collision test with a security margin: distance < margin).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from pincal.errors import ModelError
from pincal.model.chain import KinematicChain
from pincal.model.description import read_description
from pincal.model.packages import with_resolved_meshes
from pincal.progress import Counter, Progress

__all__ = ["Clearance", "check_clearance"]


@dataclass(frozen=True)
class Clearance:
    """Outcome of the collision check of the candidates.

    Attributes:
        min_distance_m: the clearance asked for [m].
        allowed: candidates kept, (K,).
        in_collision: candidates refused because two links intersect.
        too_close: candidates refused because two links are closer than the clearance (not intersecting).
        pairs_checked: geometry pairs checked.
        pairs_ignored: names of the pairs ignored (closer than the clearance at the zero configuration).
    """

    min_distance_m: float
    allowed: np.ndarray
    in_collision: int
    too_close: int
    pairs_checked: int
    pairs_ignored: tuple[str, ...]

    def as_dict(self) -> dict:
        return {
            "min_distance_m": self.min_distance_m,
            "refused": int(self.in_collision + self.too_close),
            "refused_in_collision": self.in_collision,
            "refused_too_close": self.too_close,
            "pairs_checked": self.pairs_checked,
            "pairs_ignored_at_zero": list(self.pairs_ignored),
        }


def _geometry(urdf: Path, chain: KinematicChain, xacro_args: Sequence[tuple[str, str]] = (),
              package_dirs: Mapping[str, Path] | None = None):
    """Chain model and collision geometry reduced like :class:`KinematicChain` does (a ``.xacro`` is
    expanded in memory with ``xacro_args``; ``package://`` meshes found as :mod:`pincal.model.packages` says)."""
    text = with_resolved_meshes(read_description(urdf, xacro_args).text, urdf, package_dirs)
    try:
        model = pin.buildModelFromXML(text)
        geometry = pin.buildGeomFromUrdfString(model, text, pin.GeometryType.COLLISION)
    except (RuntimeError, ValueError) as exc:
        raise ModelError(f"{urdf}: cannot load the collision geometry for --min-distance ({exc})") from None
    if geometry.ngeoms == 0:
        raise ModelError(f"{urdf}: no <collision> geometry in this URDF; --min-distance needs it (or drop the option)")
    locked = [j for j in range(1, model.njoints) if model.names[j] not in chain.joint_names]
    if locked:
        model, geometry = pin.buildReducedModel(model, geometry, locked, pin.neutral(model))
    if tuple(model.names[1:]) != chain.joint_names:
        raise ModelError(f"{urdf}: the collision model's joints {list(model.names[1:])} do not match the chain's")
    return model, geometry


def check_clearance(
    urdf: str | Path, chain: KinematicChain, q: np.ndarray, min_distance: float,
    xacro_args: Sequence[tuple[str, str]] = (),
    progress: Progress | None = None,
    package_dirs: Mapping[str, Path] | None = None,
) -> Clearance:
    """Which configurations ``q`` (K, N) keep every moving pair of links at least ``min_distance`` [m] apart.

    ``progress(done, total)`` counts the configurations checked (those too close twice: then for contact).
    ``package_dirs``: NAME → the folder of package NAME, searched first for ``package://NAME/...`` meshes."""
    model, geometry = _geometry(Path(urdf), chain, xacro_args, package_dirs)
    geometry.addAllCollisionPairs()  # pairs on different joints only
    data, geometry_data = model.createData(), geometry.createData()
    zero = np.clip(np.zeros((1, chain.n_joints)), [j.lower for j in chain.joints], [j.upper for j in chain.joints])
    pin.computeDistances(model, data, geometry, geometry_data, chain.configurations(zero)[0])
    names = [o.name for o in geometry.geometryObjects]
    keep, ignored = [], []
    for pair, result in zip(geometry.collisionPairs, geometry_data.distanceResults):
        if result.min_distance < min_distance:
            ignored.append(f"{names[pair.first]}~{names[pair.second]}")
        else:
            keep.append(pair)
    geometry.removeAllCollisionPairs()
    for pair in keep:
        geometry.addCollisionPair(pair)
    geometry_data = geometry.createData()
    configurations = chain.configurations(q)
    counter = Counter(progress)
    counter.expect(len(configurations))
    close = _collisions(model, data, geometry, geometry_data, configurations, min_distance, counter)
    touching = np.zeros_like(close)
    counter.expect(int(close.sum()))
    touching[close] = _collisions(model, data, geometry, geometry_data, configurations[close], 0.0, counter)
    counter.settle()
    return Clearance(
        min_distance_m=float(min_distance),
        allowed=~close,
        in_collision=int(touching.sum()),
        too_close=int(close.sum() - touching.sum()),
        pairs_checked=len(keep),
        pairs_ignored=tuple(ignored),
    )


def _collisions(model, data, geometry, geometry_data, configurations: np.ndarray, margin: float,
                counter: Counter) -> np.ndarray:
    """Whether any checked pair is closer than ``margin`` [m] at each configuration, (K,)."""
    for request in geometry_data.collisionRequests:
        request.security_margin = margin
    found = np.zeros(len(configurations), dtype=bool)
    for k, c in enumerate(configurations):
        found[k] = pin.computeCollisions(model, data, geometry, geometry_data, c, True)
        counter.tick()
    return found
