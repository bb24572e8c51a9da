"""The effects of :mod:`pincal.model.effects` on a tree: every joint's loads under everything it carries.

A joint shared by several chains (a torso's) carries every arm: its gravity torque, and its loads per mass
moment (eq M1–M2 of :mod:`pincal.model.mass_moments`), are those of the whole tree at the row's readings of
every tree joint, not those of one target's chain (whose model has the other arms locked at zero).
:class:`TreeBody` is the tree as one Pinocchio model — the URDF with every joint off the targets' chains
locked — that the chain functions of :mod:`pincal.model.effects` take in a chain's place: :func:`tree_inputs`
gives the effect inputs of the tree's rows (columns: the tree's joints), :func:`target_inputs` a target's
part of them (its chain's columns), :func:`acting_on` which effects move a target. An effect is the same
value in every target it moves: a compliance of the torso bends both arms by the same angle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain, reduced_model
from pincal.model.effects import (
    BEND_EFFECTS,
    JOINT_EFFECTS,
    Effect,
    EffectInputs,
    RowContext,
    effect_inputs,
    with_loads,
)
from pincal.model.tree import KinematicTree, TreeTarget

__all__ = ["TreeBody", "tree_inputs", "target_inputs", "acting_on"]


class TreeBody(KinematicChain):
    """The tree's joints as one Pinocchio model, with the interface of a chain's loads: :attr:`model` (the URDF
    with the joints off every target's chain locked at neutral, each joint placed where its chain has it: inside
    :meth:`KinematicTree.placed`, the calibrated geometry), :attr:`joints` in the tree's order,
    :meth:`configurations` and the ``<mimic>`` followers' columns. Only for loads and candidates of effects:
    its tool is the identity at the first target's tip link, and its poses are those of no target."""

    def __init__(self, tree: KinematicTree) -> None:  # noqa: D107 -- a chain's attributes set from the tree's
        model = tree.model
        ids = [model.getJointId(name) for name in tree.joint_names]
        locked = [j for j in range(1, model.njoints) if j not in ids]
        reduced = reduced_model(model, locked) if locked else model.copy()
        for target in tree.targets:  # each joint where its chain has it now (inside tree.placed: the calibrated)
            chain = target.chain.model
            for name in target.chain.joint_names:
                reduced.jointPlacements[reduced.getJointId(name)] = chain.jointPlacements[chain.getJointId(name)]
        self.model = reduced
        self.data = reduced.createData()
        self.source = tree.source
        self.tip_link = tree.targets[0].link
        self.joint_ids = tuple(reduced.getJointId(name) for name in tree.joint_names)
        self.tip_frame_id = tree.targets[0].chain.tip_frame_id
        self.joints = tree.joints
        self.beyond_tip_joints, self.other_branch_joints = {}, tree.other_branch_joints
        self._tool = np.eye(4)
        self._continuous = [j.kind == "continuous" for j in tree.joints]


def tree_inputs(tree: KinematicTree, data: MeasurementSet, time: np.ndarray | None = None,
                context: RowContext | None = None, loads: bool = False) -> EffectInputs:
    """The effect inputs of the rows of ``data`` (columns: the tree's joints, :attr:`KinematicTree.joint_names`):
    each joint's gravity torque under the URDF's inertias of everything it carries, at every tree joint's
    reading (:func:`pincal.model.effects.effect_inputs` of :class:`TreeBody`); ``loads``: with the loads per mass
    moment too (:func:`pincal.model.effects.with_loads`, for compliances of unknown masses)."""
    body = TreeBody(tree)
    inputs = effect_inputs(body, data, time=time, context=context)
    return with_loads(inputs, body) if loads else inputs


def target_inputs(inputs: EffectInputs, target: TreeTarget) -> EffectInputs:
    """The part of the tree's effect inputs ``inputs`` that ``target``'s chain reads: its joints' columns
    (the mass moments stay the tree's: a moment of the other arm loads the torso, and bends it)."""
    columns = target.columns
    return replace(inputs, q=inputs.q[:, columns], gravity=inputs.gravity[:, columns],
                   bending=None if inputs.bending is None else inputs.bending[:, columns],
                   context_q=None if inputs.context_q is None else inputs.context_q[:, columns],
                   loads=None if inputs.loads is None else inputs.loads[:, columns],
                   joint_names=tuple(target.chain.joint_names))


def acting_on(effects: Sequence[Effect], target: TreeTarget) -> list[int]:
    """The indices of ``effects`` that move ``target``: a joint effect or lateral compliance of a joint on its chain
    (and its driver too), every effect of the sensor's side."""
    names = set(target.chain.joint_names)
    return [i for i, effect in enumerate(effects)
            if effect.type not in (*JOINT_EFFECTS, *BEND_EFFECTS)
            or (effect.joint in names and (effect.driver or effect.joint) in names)]
