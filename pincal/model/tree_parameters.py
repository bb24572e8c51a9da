"""The kinematic parameters of a tree (:class:`pincal.model.tree.KinematicTree`): one set, shared.

Each target's chain has its parameter set of :data:`pincal.model.parameter_sets.LEVELS`
(``offsets``: a zero per joint; ``full``: an SE(3) error per joint placement and one of the
tip). A parameter is named by what it belongs to (``torso_1.offset``, ``arm_left_2.tx``,
``left_hand.rz``), so a joint on several chains gives the same names in each: the tree's
parameters are the union of the chains' by name, each once, and a chain's vector is the
tree vector at its indices (:attr:`TreeParameters.index`). A parameter of a joint that
does not support a target is not among that target's: its derivative there is zero.
"""

from __future__ import annotations

import numpy as np

from pincal.model.dh.parameters import ParameterInfo
from pincal.model.parameter_sets import LEVELS, ChainParameters, ParameterLevel
from pincal.model.sensitivity import ParameterSlot
from pincal.model.tree import KinematicTree, TreePlacements

__all__ = ["TreeParameters"]


class TreeParameters:
    """The union, by name, of the parameter sets of ``level`` of every target's chain.

    Args:
        tree: the tree.
        level: ``offsets`` or ``full``.

    Attributes:
        chains: each target's own parameter set, in target order.
        size: how many parameters the tree has.
        index: for each target, the tree index of each of its chain's parameters, (n_t,).
        info: name, owner and unit of every tree parameter, the first target's first.
        slots: where each acts, as in the chain it came from (its kind and axis; the prior's kinds read them).
        chain: the tree (what :func:`pincal.fit.prior.parameter_kinds` reads the joints' kinds and axes of).
    """

    def __init__(self, tree: KinematicTree, level: ParameterLevel) -> None:
        self.tree = self.chain = tree
        self.level = level
        self.chains: tuple[ChainParameters, ...] = tuple(LEVELS[level](t.chain) for t in tree.targets)
        position: dict[str, int] = {}
        info: list[ParameterInfo] = []
        slots: list[ParameterSlot] = []
        index = []
        for params in self.chains:
            for item, slot in zip(params.info, params.slots):
                if item.name not in position:
                    position[item.name] = len(info)
                    info.append(item)
                    slots.append(slot)
            index.append(np.array([position[item.name] for item in params.info], dtype=np.intp))
        self.info: tuple[ParameterInfo, ...] = tuple(info)
        self.slots: tuple[ParameterSlot, ...] = tuple(slots)
        self.index: tuple[np.ndarray, ...] = tuple(index)
        self.size = len(info)

    def chain_vector(self, target: int, vector: np.ndarray) -> np.ndarray:
        """Target ``target``'s chain parameters at the tree vector ``vector`` (n,) [m, rad]."""
        return np.asarray(vector, dtype=float)[self.index[target]]

    def placements(self, vector: np.ndarray) -> TreePlacements:
        """Each target's chain placements at ``vector`` (the tree's calibrated model as a value)."""
        return tuple(tuple(params.placements(self.chain_vector(t, vector))) for t, params in enumerate(self.chains))
