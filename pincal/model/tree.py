"""Several targets on several chains of one URDF: a kinematic tree.

A robot measured with a marker on each hand (two arms on one torso) is the union of
the root → tip paths of several tip links. :class:`KinematicTree` holds one
:class:`~pincal.model.chain.KinematicChain` per target (its own reduced Pinocchio
model, root to its tip link) and the union of their joints: a joint on several
paths (the torso's) is one joint of the tree, with one placement and one reading
column. Each target knows which of the tree's joints support it
(:attr:`TreeTarget.columns`); every other joint does not move it.

Targets are given as ``LINK:POINTS`` (``--tip-link right_hand:1 --tip-link
left_hand:2,3``, :func:`parse_targets`): the numbered points ``x1,y1,z1 ...`` of
the measurement file that the link carries (several points of one rigid target on
one link). Units: metres and radians.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pinocchio as pin

from pincal.errors import ModelError, PincalError
from pincal.measurements.couplings import ReadingCoupling
from pincal.measurements.data import JointMimic, JointSpec
from pincal.model.chain import ChainJoint, KinematicChain
from pincal.model.description import RobotDescription, read_description
from pincal.model.lateral import bent_tool_poses
from pincal.model.urdf_elements import joint_mimics

__all__ = ["TargetSpec", "TreeTarget", "KinematicTree", "parse_targets", "TreePlacements"]

#: The calibrated model of a tree as a value: each target's chain placements (as
#: :meth:`pincal.model.chain.KinematicChain.placements`), in target order.
TreePlacements = tuple[tuple[np.ndarray, ...], ...]


@dataclass(frozen=True)
class TargetSpec:
    """One ``--tip-link LINK:POINTS``.

    Attributes:
        link: the tip link carrying the target.
        points: the 1-based numbers of the measured points (``x1,y1,z1`` is 1) it carries, in order.
    """

    link: str
    points: tuple[int, ...]


def parse_targets(texts: Sequence[str]) -> tuple[TargetSpec, ...]:
    """``--tip-link`` values as targets: ``LINK:1`` or ``LINK:1,2,3`` each, several of them.

    Raises:
        PincalError: a value without its points, a point that is not a positive integer, a point given to two
            links, or a link given twice — one line naming the value and what to write.
    """
    specs: list[TargetSpec] = []
    for text in texts:
        link, _, numbers = text.rpartition(":")
        if not link or not numbers.strip():
            raise PincalError(f"--tip-link '{text}': with several --tip-link, each names the points its link "
                              "carries: --tip-link LINK:1 (point 1 is x1,y1,z1) or LINK:1,2,3")
        try:
            points = tuple(int(n) for n in numbers.split(","))
        except ValueError:
            points = (0,)
        if any(p < 1 for p in points) or len(set(points)) != len(points):
            raise PincalError(f"--tip-link '{text}': the points must be distinct numbers 1, 2, ... of the file's "
                              "x1,y1,z1, x2,y2,z2 ... columns, e.g. LINK:1,2")
        specs.append(TargetSpec(link.strip(), points))
    links = [s.link for s in specs]
    twice = sorted({link for link in links if links.count(link) > 1})
    if twice:
        raise PincalError(f"--tip-link {twice[0]} is given twice; give its points once: --tip-link {twice[0]}:1,2")
    owners: dict[int, str] = {}
    for spec in specs:
        for p in spec.points:
            if p in owners:
                raise PincalError(f"--tip-link: point {p} is given to both {owners[p]} and {spec.link}; a measured "
                                  "point is on one link")
            owners[p] = spec.link
    return tuple(specs)


@dataclass(frozen=True)
class TreeTarget:
    """One target of a tree: its link, its points, its chain and the tree joints that support it.

    Attributes:
        spec: the link and its point numbers.
        chain: the chain root → ``spec.link`` (its tool the identity: the points are estimated in the link).
        columns: for each joint of ``chain``, its index among the tree's joints, (N_t,).
    """

    spec: TargetSpec
    chain: KinematicChain
    columns: np.ndarray

    @property
    def link(self) -> str:
        return self.spec.link


class KinematicTree:
    """The union of the chains root → each target's tip link, of one Pinocchio model.

    Args:
        model: Pinocchio model of the whole URDF.
        targets: the targets (at least one).
        source: where the model came from, for messages.
        mimics: the URDF's ``<mimic>`` joints (:func:`pincal.model.urdf_elements.joint_mimics`), given to
            every target's chain: a follower takes its angle from its driver (eq M1), no column needed.

    Raises:
        ModelError: an unknown link (with the closest names), a chain that is not serial, or a tip link on
            the path to another target's (its placement would move the other's: give the lower one only).
    """

    def __init__(self, model: pin.Model, targets: Sequence[TargetSpec], source: str = "<model>",
                 mimics: Mapping[str, JointMimic] | None = None) -> None:
        if not targets:
            raise ModelError(f"{source}: a tree needs at least one target")
        chains = [KinematicChain(model, t.link, source=source, mimics=mimics) for t in targets]
        _refuse_nested(model, [t.link for t in targets], source)
        order = sorted({model.getJointId(n) for chain in chains for n in chain.joint_names})  # depth first
        names = [model.names[j] for j in order]
        by_name = {j.name: j for chain in chains for j in chain.joints}
        self.source = source
        #: the whole URDF's Pinocchio model (the loads of effects on shared joints: :mod:`pincal.model.tree_effects`)
        self.model = model
        self.joints: tuple[ChainJoint, ...] = tuple(by_name[n] for n in names)
        self.n_joints = len(names)
        self.joint_names: tuple[str, ...] = tuple(names)
        self.joint_specs: list[JointSpec] = [j.spec for j in self.joints]
        #: joint name → ``revolute``, ``continuous`` or ``prismatic`` (as a chain's)
        self.joint_kinds: dict[str, str] = {j.name: j.kind for j in self.joints}
        self.targets: tuple[TreeTarget, ...] = tuple(
            TreeTarget(spec, chain, np.array([names.index(n) for n in chain.joint_names], dtype=np.intp))
            for spec, chain in zip(targets, chains))
        movable = [model.names[j] for j in range(1, model.njoints)]
        #: the URDF's movable joints on no target's chain (a file's column for one is no tree joint)
        self.other_branch_joints = tuple(n for n in movable if n not in names)

    @classmethod
    def from_urdf(cls, urdf_path: str | os.PathLike[str], targets: Sequence[TargetSpec],
                  xacro_args: Mapping[str, str] | Iterable[tuple[str, str]] | None = None) -> KinematicTree:
        """Load ``urdf_path`` (or a ``.xacro`` expanded with ``xacro_args``) and take its tree to ``targets``."""
        return cls.from_description(read_description(urdf_path, xacro_args), targets)

    @classmethod
    def from_description(cls, description: RobotDescription, targets: Sequence[TargetSpec]) -> KinematicTree:
        """The tree of a robot description already read (:func:`pincal.model.description.read_description`)."""
        try:
            model = pin.buildModelFromXML(description.text)
        except Exception as exc:  # Pinocchio raises plain RuntimeError/ValueError
            reason = " ".join(str(exc).split())
            raise ModelError(f"{description.source}: Pinocchio cannot read this URDF ({reason})") from None
        return cls(model, targets, source=description.source, mimics=joint_mimics(description.root()))

    @property
    def followers(self) -> tuple[str, ...]:
        """The tree's joints that follow another joint (URDF ``<mimic>``, eq M1): their readings come from their
        driver's (a tree joint's, or a column of its own off the tree), a file needs no column for them."""
        return tuple(j.name for j in self.joints if j.mimic is not None)

    def follow(self, couplings: Sequence[ReadingCoupling]) -> None:
        """Make each ``--coupling`` the run decided ``follows`` a tree joint that follows its driver (eq M1, offset
        0), on every target's chain that has the joint (:meth:`KinematicChain.follow`) and in the tree's joints, as
        a URDF ``<mimic>`` would, for the whole run: its readers (:attr:`joint_specs`) and REPORT.json's
        ``chain.mimics``.

        Raises:
            MeasurementError: a ``--coupling`` on a joint the URDF already makes follow another.
        """
        for target in self.targets:
            target.chain.follow(couplings)
        by_name = {j.name: j for target in self.targets for j in target.chain.joints}
        self.joints = tuple(by_name[n] for n in self.joint_names)
        self.joint_specs = [j.spec for j in self.joints]

    def followed(self, q: npt.ArrayLike) -> np.ndarray:
        """Tree joint values (K, N) [rad or m] with each follower set from its driver (eq M1), as
        :meth:`KinematicChain.followed`; followers of one driver off the tree (a gripper's fingers) set from the
        first of them, so that one driver value gives them all; a copy."""
        out = np.array(q, dtype=float, copy=True)
        names = self.joint_names
        leaders: dict[str, int] = {}
        for i, joint in enumerate(self.joints):
            mimic = joint.mimic
            if mimic is None:
                continue
            if mimic.driver in names:
                out[..., i] = mimic.multiplier * out[..., names.index(mimic.driver)] + mimic.offset
            elif mimic.driver in leaders:  # the driver's value that the first follower stands for
                lead = leaders[mimic.driver]
                first = self.joints[lead].mimic
                assert first is not None  # a leader follows the driver
                driver = (out[..., lead] - first.offset) / first.multiplier
                out[..., i] = mimic.multiplier * driver + mimic.offset
            else:
                leaders[mimic.driver] = i
        return out

    def configurations(self, q: npt.ArrayLike) -> np.ndarray:
        """Tree joint readings (K, N) → configurations (K, nq) of the URDF's model reduced to the tree's joints
        (continuous joints as (cos, sin), as :meth:`KinematicChain.configurations`)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        if q.shape[1] != self.n_joints:
            raise ModelError(f"expected {self.n_joints} joint values per row, got {q.shape[1]}")
        columns: list[np.ndarray] = []
        for i, joint in enumerate(self.joints):
            columns += [np.cos(q[:, i]), np.sin(q[:, i])] if joint.kind == "continuous" else [q[:, i]]
        return np.column_stack(columns)

    @property
    def n_points(self) -> int:
        """How many measured points the targets carry in all."""
        return sum(len(t.spec.points) for t in self.targets)

    def placements(self) -> TreePlacements:
        """Each target's chain placements now (:meth:`KinematicChain.placements`)."""
        return tuple(tuple(t.chain.placements()) for t in self.targets)

    @contextmanager
    def placed(self, placements: TreePlacements | None = None) -> Iterator[KinematicTree]:
        """The tree with each target's chain at ``placements`` inside a ``with`` block, as
        :meth:`KinematicChain.placed` (None: as it is)."""
        with ExitStack() as stack:
            for index, target in enumerate(self.targets):
                stack.enter_context(target.chain.placed(None if placements is None else list(placements[index])))
            yield self

    def target_points(self, q: np.ndarray, points: Sequence[np.ndarray],
                      bends: Sequence[np.ndarray | None] | None = None) -> np.ndarray:
        """Each measured point in the URDF root frame at tree joint readings ``q`` (K, N) [m], (K, P, 3) in the
        order of the point numbers; ``points``: each target's points in its tip link (P_t, 3) [m]; ``bends``: each
        target's chain joints' lateral deflections (K, 2 N_t) [rad] (:func:`pincal.model.lateral.bend_angles`,
        eq L1), or None (none)."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        out = np.full((len(q), max(p for t in self.targets for p in t.spec.points), 3), np.nan)
        for t, (target, local) in enumerate(zip(self.targets, points)):
            rotations, positions = self._tool_poses(t, q, bends)
            world = positions[:, None, :] + np.einsum("kij,pj->kpi", rotations, np.atleast_2d(local))
            out[:, [p - 1 for p in target.spec.points]] = world
        return out

    def target_rotations(self, q: np.ndarray, frames: Sequence[np.ndarray],
                         bends: Sequence[np.ndarray | None] | None = None) -> np.ndarray:
        """Each target's frame in the URDF root frame at tree joint readings ``q`` (K, N), R_k,t R_T,t: (K, T, 3, 3);
        ``frames``: each target's frame in its tip link R_T,t (3, 3); ``bends``: as :meth:`target_points`'."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return np.stack([self._tool_poses(t, q, bends)[0] @ frame for t, frame in enumerate(frames)], axis=1)

    def _tool_poses(self, t: int, q: np.ndarray, bends: Sequence[np.ndarray | None] | None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Target ``t``'s tip link rotations (K, 3, 3) and positions (K, 3) [m] at tree readings ``q`` (K, N)."""
        target, bent = self.targets[t], None if bends is None else bends[t]
        if bent is None:
            return target.chain.tool_poses(q[:, target.columns])
        poses = bent_tool_poses(target.chain, q[:, target.columns], bent)  # turned at its joints (eq L1)
        return poses.tool_rotations, poses.tool_positions


def _refuse_nested(model: pin.Model, links: Sequence[str], source: str) -> None:
    """Refuse a tip link that lies on the path from the root to another's: the tip's placement (its fixed
    joints) would be a parameter of one target and move the other."""
    body = pin.FrameType.BODY
    ids = {model.getFrameId(link, body): link for link in links}
    for frame_id, link in ids.items():
        up = model.frames[frame_id].parentFrame
        while up != 0:
            if up in ids and ids[up] != link:
                raise ModelError(f"{source}: tip link '{ids[up]}' lies on the chain to '{link}'; give a target on a "
                                 f"link of its own (a marker link below '{ids[up]}' by a fixed joint)")
            up = model.frames[up].parentFrame
