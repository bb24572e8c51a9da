"""Refuse candidate configurations in self-collision (``pincal plan``'s default) or closer than a
clearance (``--min-distance``).

The URDF's collision geometry is loaded with Pinocchio (``buildGeomFromUrdf``,
coal underneath) and reduced to the chain like the kinematic model: every
joint off the chain is locked at its neutral value, so links that never move
relative to each other share a joint and are not paired. As in an SRDF's
"default"/"adjacent" pairs, pairs closer than the clearance at the zero
configuration (clipped into the joint limits), or in contact there (coal's
collision test without margin) — adjacent links touch or overlap there —, are
ignored. A candidate is refused when any remaining pair is closer than the
clearance (coal's collision test with a security margin: distance < margin);
with a clearance of 0, when two links are in contact.

With the robot's SRDF (``plan --srdf``, self-collision only), its ``disable_collisions`` pairs are the ones
not checked (Pinocchio's ``removeCollisionPairsFromXML``; those disabled as "Never" in collision are checked
still, :data:`SRDF_REASONS`), instead of those in contact at the zero configuration: a whole robot's zero is
no resting pose (TALOS's grippers sit inside its thighs there), and the zero rule would leave such pairs
unchecked in every posture. Links ignored at zero more than :data:`NEAR_JOINTS` joints apart are named by
:attr:`Clearance.unrelated_ignored`, so that a plan without the SRDF can say so.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import pinocchio as pin
from lxml import etree

from pincal.errors import ModelError
from pincal.model.chain import KinematicChain
from pincal.model.description import read_description
from pincal.model.packages import with_resolved_meshes
from pincal.model.tree import KinematicTree
from pincal.progress import Counter, Progress

__all__ = ["CollisionCheck", "Clearance", "SRDF_REASONS", "NEAR_JOINTS", "check_clearance", "has_collision_geometry"]

#: How a plan's candidates were checked: for self-collision (the default where the URDF has collision
#: geometry), for a clearance (``--min-distance``), not at all (``--no-collision-check``), or not for want of
#: geometry (the URDF has no ``<collision>``).
CollisionCheck = Literal["self-collision", "min-distance", "off", "no collision geometry"]

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
        unrelated_ignored: those of :attr:`pairs_ignored` whose links are not adjacent (module docstring).
        srdf: the SRDF whose disabled pairs were not checked (then nothing is ignored at zero), or None.
        pairs_disabled: pairs the SRDF disabled among those of moving links.
        srdf_never_checked: the SRDF's pairs disabled as "Never" in collision, checked still (:data:`SRDF_REASONS`).
    """

    min_distance_m: float
    allowed: np.ndarray
    in_collision: int
    too_close: int
    pairs_checked: int
    pairs_ignored: tuple[str, ...]
    unrelated_ignored: tuple[str, ...] = ()
    srdf: str | None = None
    pairs_disabled: int = 0
    srdf_never_checked: int = 0

    def unrelated_note(self) -> str:
        """What :attr:`unrelated_ignored` means for the plan, in one sentence (empty when there are none)."""
        if not self.unrelated_ignored:
            return ""
        near = "in contact" if self.min_distance_m == 0.0 else f"closer than {self.min_distance_m:g} m"
        return (f"{len(self.unrelated_ignored)} pair(s) of links more than {NEAR_JOINTS} joints apart are {near} at "
                f"the zero configuration and so never checked (e.g. {self.unrelated_ignored[0]})"
                + (": give the robot's SRDF with --srdf to check them" if self.min_distance_m == 0.0 else ""))

    def srdf_words(self) -> str:
        """What the SRDF left unchecked, for the console (empty without an SRDF): "29 disabled by talos.srdf, whose
        316 'Never' pairs are checked"."""
        if self.srdf is None:
            return ""
        never = f", whose {self.srdf_never_checked} 'Never' pairs are checked" if self.srdf_never_checked else ""
        return f"{self.pairs_disabled} disabled by {Path(self.srdf).name}{never}"

    def as_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "min_distance_m": self.min_distance_m,
            "refused": int(self.in_collision + self.too_close),
            "refused_in_collision": self.in_collision,
            "refused_too_close": self.too_close,
            "pairs_checked": self.pairs_checked,
            "pairs_ignored_at_zero": list(self.pairs_ignored),
        }
        if self.srdf is not None:
            out["srdf"] = {"file": self.srdf, "pairs_disabled": self.pairs_disabled,
                           "never_pairs_checked": self.srdf_never_checked}
        return out


def has_collision_geometry(urdf: str | Path, xacro_args: Sequence[tuple[str, str]] = ()) -> bool:
    """Whether the URDF (a ``.xacro`` expanded with ``xacro_args``) has a ``<collision>`` element on a link; read
    as text, no mesh opened."""
    root = etree.fromstring(read_description(Path(urdf), xacro_args).text.encode("utf-8"))
    return any(element.getparent() is not None and element.getparent().tag == "link"
               for element in root.iter("collision"))


def _geometry(urdf: Path, chain: KinematicChain | KinematicTree, xacro_args: Sequence[tuple[str, str]] = (),
              package_dirs: Mapping[str, Path] | None = None) -> tuple[pin.Model, pin.GeometryModel]:
    """Chain model and collision geometry reduced like :class:`KinematicChain` does (a ``.xacro`` is
    expanded in memory with ``xacro_args``; ``package://`` meshes found as :mod:`pincal.model.packages` says)."""
    text = with_resolved_meshes(read_description(urdf, xacro_args).text, urdf, package_dirs)
    try:
        model = pin.buildModelFromXML(text)
        geometry = pin.buildGeomFromUrdfString(model, text, pin.GeometryType.COLLISION)
    except (RuntimeError, ValueError) as exc:
        raise ModelError(f"{urdf}: cannot load the collision geometry ({exc})") from None
    if geometry.ngeoms == 0:
        raise ModelError(f"{urdf}: no <collision> geometry in this URDF; --min-distance needs it (or drop the option)")
    locked = [j for j in range(1, model.njoints) if model.names[j] not in chain.joint_names]
    if locked:
        model, geometry = pin.buildReducedModel(model, geometry, locked, pin.neutral(model))
    if tuple(model.names[1:]) != chain.joint_names:
        raise ModelError(f"{urdf}: the collision model's joints {list(model.names[1:])} do not match the chain's")
    return model, geometry


def check_clearance(
    urdf: str | Path, chain: KinematicChain | KinematicTree, q: np.ndarray, min_distance: float,
    xacro_args: Sequence[tuple[str, str]] = (),
    progress: Progress | None = None,
    package_dirs: Mapping[str, Path] | None = None,
    srdf: str | Path | None = None,
) -> Clearance:
    """Which configurations ``q`` (K, N) keep every moving pair of links at least ``min_distance`` [m] apart
    (0: which are free of self-collision).

    ``progress(done, total)`` counts the configurations checked (those too close twice: then for contact;
    once with ``min_distance`` 0).
    ``package_dirs``: NAME → the folder of package NAME, searched first for ``package://NAME/...`` meshes.
    ``srdf``: the robot's SRDF, whose ``disable_collisions`` pairs are not checked, instead of those in
    contact (closer than ``min_distance``) at the zero configuration.

    Raises:
        ModelError: collision geometry that cannot be loaded, or an SRDF that cannot be read or that disables
            no pair of this URDF's links (another robot's?).
    """
    if srdf is not None and min_distance > 0.0:  # before the meshes are read
        raise ModelError(f"{srdf}: an SRDF's disabled pairs are those that may touch, not those that may come closer "
                         f"than a clearance: give --srdf for the self-collision check, or --min-distance without it")
    model, geometry = _geometry(Path(urdf), chain, xacro_args, package_dirs)
    geometry.addAllCollisionPairs()  # pairs on different joints only
    every = len(geometry.collisionPairs)
    if srdf is not None:  # its pairs replace the zero rule
        never = _disable_srdf_pairs(model, geometry, Path(srdf))
        ignored: list[str] = []
        unrelated: list[str] = []
    else:
        never = 0
        ignored, unrelated = _ignored_at_zero(model, geometry, chain, min_distance)
    checked = len(geometry.collisionPairs)
    configurations = chain.configurations(q)
    counter = Counter(progress)
    counter.expect(len(configurations))
    close = _collisions(model, geometry, configurations, min_distance, counter)
    touching = close.copy()  # with no clearance, every pair too close is in contact
    if min_distance > 0.0:
        counter.expect(int(close.sum()))
        touching[close] = _collisions(model, geometry, configurations[close], 0.0, counter)
    counter.settle()
    return Clearance(
        min_distance_m=float(min_distance),
        allowed=~close,
        in_collision=int(touching.sum()),
        too_close=int(close.sum() - touching.sum()),
        pairs_checked=checked,
        pairs_ignored=tuple(ignored),
        unrelated_ignored=tuple(unrelated),
        srdf=None if srdf is None else str(srdf),
        pairs_disabled=every - checked if srdf is not None else 0,
        srdf_never_checked=never,
    )


def _ignored_at_zero(model: pin.Model, geometry: pin.GeometryModel, chain: KinematicChain | KinematicTree,
                     min_distance: float) -> tuple[list[str], list[str]]:
    """Remove from ``geometry``'s pairs those closer than ``min_distance`` [m], or in contact, at the zero
    configuration (clipped into the joint limits); returns their names and those of them more than
    :data:`NEAR_JOINTS` joints apart."""
    data, geometry_data = model.createData(), geometry.createData()
    zero = np.clip(np.zeros((1, chain.n_joints)), [j.lower for j in chain.joints], [j.upper for j in chain.joints])
    pin.computeDistances(model, data, geometry, geometry_data, chain.configurations(zero)[0])
    # in contact: as the collision test that refuses candidates says, not by the distance, which coal
    # gives as 0 for intersecting meshes and as a few nanometres for some that touch (Kinova's base and
    # link 1: 6e-9 m, yet in collision at every configuration)
    pin.computeCollisions(model, data, geometry, geometry_data, chain.configurations(zero)[0], False)
    names = [o.name for o in geometry.geometryObjects]
    keep, ignored, unrelated = [], [], []
    for pair, result, contact in zip(geometry.collisionPairs, geometry_data.distanceResults,
                                     geometry_data.collisionResults):
        if result.min_distance < min_distance or contact.isCollision():  # closer, or in contact
            ignored.append(f"{names[pair.first]}~{names[pair.second]}")
            if _joints_apart(model, geometry, pair) > NEAR_JOINTS:
                unrelated.append(ignored[-1])
        else:
            keep.append(pair)
    geometry.removeAllCollisionPairs()
    for pair in keep:
        geometry.addCollisionPair(pair)
    return ignored, unrelated


#: The SRDF's reasons for a disabled pair that pincal honours (MoveIt's setup assistant writes them): links
#: adjacent, in collision in its default pose, or in every posture it sampled. A pair disabled as "Never" — in
#: collision in none of its samples — is checked still: the samples were of the author's meshes and limits
#: (TALOS's forearm and wrist, "Never" in talos.srdf, intersect in 9 of 60 postures drawn within this URDF's).
SRDF_REASONS = ("Adjacent", "Default", "Always")


def _disable_srdf_pairs(model: pin.Model, geometry: pin.GeometryModel, srdf: Path) -> int:
    """Remove the SRDF's ``disable_collisions`` pairs of :data:`SRDF_REASONS` (or without a reason) from
    ``geometry``'s (Pinocchio's ``removeCollisionPairsFromXML``); returns how many of its "Never" pairs are pairs
    of ``geometry`` (of moving links), checked still."""
    try:
        root = etree.parse(str(srdf)).getroot()
    except (OSError, etree.XMLSyntaxError) as exc:
        raise ModelError(f"{srdf}: cannot read the SRDF ({exc}); give the robot's .srdf file") from None
    pairs = root.findall("disable_collisions")  # where Pinocchio reads them: children of <robot>
    listed = {link for element in pairs for link in (element.get("link1"), element.get("link2")) if link is not None}
    if not listed:
        raise ModelError(f"{srdf}: no <disable_collisions> pair in this SRDF; give the robot's .srdf file "
                         "(or leave --srdf out)")
    def links(element: etree._Element) -> frozenset[str | None]:
        return frozenset((element.get("link1"), element.get("link2")))
    honoured = {links(element) for element in pairs if element.get("reason", "Default") in SRDF_REASONS}
    kept = [element for element in pairs if element.get("reason", "Default") not in SRDF_REASONS
            and links(element) not in honoured]  # a pair listed "Never" and "Adjacent" too: disabled
    for element in kept:
        root.remove(element)
    before = len(geometry.collisionPairs)
    never = geometry.copy()  # what the "Never" pairs alone would remove: how many of them are pairs here
    try:
        pin.removeCollisionPairsFromXML(model, geometry, etree.tostring(root, encoding="unicode"), False)
        for element in pairs:  # then the "Never" pairs alone
            if element not in kept:
                root.remove(element)
        root.extend(kept)
        pin.removeCollisionPairsFromXML(model, never, etree.tostring(root, encoding="unicode"), False)
    except (RuntimeError, ValueError) as exc:
        raise ModelError(f"{srdf}: cannot read the SRDF ({exc})") from None
    if len(geometry.collisionPairs) == before:  # a robot's SRDF disables its adjacent links at least
        unknown = sorted(link for link in listed if not model.existFrame(link))
        why = (f"its {len(pairs)} pairs are all 'Never' in collision, which are checked still"
               if len(kept) == len(pairs) else
               f"{len(unknown)} of its {len(listed)} links are not in the URDF, e.g. {unknown[0]!r}" if unknown else "")
        raise ModelError(f"{srdf}: disables no pair of this URDF's moving links" + (f" ({why})" if why else "")
                         + ": another robot's SRDF? give this robot's, or leave --srdf out")
    return before - len(never.collisionPairs)


#: Links at most this many joints apart (along the tree, in the reduced model) that are in contact at zero form
#: one elbow or wrist, whose meshes often touch by design (a Panda's links 5 and 7, two joints apart; a Kinova's
#: links 3 and 6, three); farther apart they are separate limbs (TALOS's thigh and gripper: nine), which the zero
#: rule would leave unchecked in every posture.
NEAR_JOINTS = 3


def _joints_apart(model: pin.Model, geometry: pin.GeometryModel, pair: pin.CollisionPair) -> int:
    """How many joints lie between the pair's two links along the kinematic tree (0: on one joint)."""
    def ancestry(joint: int) -> list[int]:
        path = [joint]
        while path[-1] != 0:
            path.append(model.parents[path[-1]])
        return path
    a, b = (ancestry(geometry.geometryObjects[i].parentJoint) for i in (pair.first, pair.second))
    common = next(j for j in a if j in b)
    return a.index(common) + b.index(common)


#: Configurations checked per parallel call: the progress advances between calls.
_BATCH = 64


def _threads() -> int:
    """The cores this process may run on (its affinity where the system tells it)."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def _collisions(model: pin.Model, geometry: pin.GeometryModel, configurations: np.ndarray, margin: float,
                counter: Counter) -> np.ndarray:
    """Whether any checked pair is closer than ``margin`` [m] at each configuration, (K,); the configurations
    are shared among the cores (Pinocchio's ``computeCollisionsInParallel``: the same answer as one by one)."""
    threads = _threads()
    pool = pin.GeometryPool(model, geometry, threads)
    for geometry_data in pool.getGeometryDatas():
        for request in geometry_data.collisionRequests:
            request.security_margin = margin
    found = np.zeros(len(configurations), dtype=bool)
    for start in range(0, len(configurations), _BATCH):
        batch = configurations[start:start + _BATCH]
        found[start:start + len(batch)] = pin.computeCollisionsInParallel(threads, pool, np.ascontiguousarray(batch.T),
                                                                          True)
        counter.tick(len(batch))
    return found
