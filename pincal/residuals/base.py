"""Base of the residual vectors that calibration minimises.

An :class:`Objective` is a residual vector r(x) over a *free* subset x of a
parameter set's flat vector (the other parameters stay at their values in
``base``), with its analytic Jacobian. A :class:`KinematicsCache` computes
forward kinematics and parameter sensitivities once per x; the residual, the
Jacobian (which scipy.optimize.least_squares asks for at the same point) and
the parts of a combined objective all share it.

The paper's objectives compare configurations in pairs (k, k + K/2) so that
they do not depend on the sensor registration (eq 10–11, 14).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
import numpy.typing as npt

from pincal.errors import CalibrationError
from pincal.model.lateral import bend_slots
from pincal.model.sensitivity import ParameterSlot, Sensitivity, SensitivityModel, ToolPoses

__all__ = ["pair_indices", "ParameterSet", "KinematicsCache", "Objective", "BlockObjective"]


def pair_indices(n_rows: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows (k, k + K/2) for k = 0 .. K/2 - 1 (eq 10); an odd last row is unused."""
    half = n_rows // 2
    if half < 1:
        raise CalibrationError(f"need at least 2 calibration rows to form pairs, got {n_rows}")
    first = np.arange(half)
    return first, first + half


ParameterSet = Any  # DHParameterSet, JointOffsets or PlacementErrors (same interface)


class KinematicsCache:
    """Tool poses and parameter sensitivities at the last free-parameter vector.

    Builds one :class:`pincal.model.sensitivity.SensitivityModel` for the free
    parameters; each evaluation only updates its placements.

    Args:
        params: the parameter set (maps a flat vector to the chain's placements).
        free: flat indices of the parameters being fitted.
        base: the flat vector holding the values of the fixed parameters.
        q: joint readings of the configurations used (K, N).
        models: sensitivity models already built for ``params``, by their slots;
            the fits of one problem share them (a model holds no state between
            evaluations: each sets its placements first). Built and added here
            when missing.
        bends: the chain joints' lateral deflections (K, 2N) [rad] of every evaluation not given its own
            (:func:`pincal.model.lateral.bend_angles`, a report's lateral compliances), or None.
    """

    def __init__(
        self,
        params: ParameterSet,
        free: npt.ArrayLike,
        base: npt.ArrayLike,
        q: npt.ArrayLike,
        models: dict[tuple[ParameterSlot, ...], SensitivityModel] | None = None,
        bends: npt.ArrayLike | None = None,
    ) -> None:
        self.params = params
        self.free = np.asarray(free, dtype=int)
        self.base = np.array(base, dtype=float)
        self.q = np.asarray(q, dtype=float)
        slots = params.slots
        self._slots = params.coupled(self.free)  # slots moved by the free parameters
        self._block = np.ix_(self._slots, self.free)  # rows and columns of slot_jacobian used
        key = tuple(slots[i] for i in self._slots)
        models = {} if models is None else models
        if key not in models:
            models[key] = SensitivityModel(params.chain, key)
        self.model = models[key]
        self._models, self._key = models, key
        self.bends = None if bends is None else np.asarray(bends, dtype=float)
        # the last few results with their inputs (bytes of x, shape and bytes of q, the tool), newest last
        self._recent: list[tuple[tuple[bytes, tuple[int, ...], bytes, bytes], tuple[ToolPoses, Sensitivity]]] = []

    def full_vector(self, x: npt.ArrayLike) -> np.ndarray:
        """The flat parameter vector with ``x`` in the free slots."""
        vector = self.base.copy()
        vector[self.free] = x
        return vector

    #: Results kept: a fit's caller evaluates again at the solution, which is the
    #: last but one point evaluated when MINPACK's last trial step was rejected.
    RECENT = 2

    def bent_model(self) -> SensitivityModel:
        """The sensitivity model with every chain joint's ``bend`` slots after the free parameters'
        (:func:`pincal.model.lateral.bend_slots`), shared like the others."""
        key = self._key + bend_slots(self.params.chain)
        if key not in self._models:
            self._models[key] = SensitivityModel(self.params.chain, key)
        return self._models[key]

    def evaluate(self, x: npt.ArrayLike, q: npt.ArrayLike | None = None,
                 bends: npt.ArrayLike | None = None) -> tuple[ToolPoses, Sensitivity]:
        """Tool poses and the free parameters' sensitivities at ``x``, at the
        cache's configurations or at ``q`` (K, N) when given (effects shift them), the joints deflected
        laterally by ``bends`` (K, 2N) [rad] (default: the cache's ``bends``; with either, the
        sensitivities hold the bend slots' columns too, :attr:`Sensitivity.bend_angular`).

        The result is shared with later calls at the same inputs: do not write into it.
        """
        x = np.asarray(x, dtype=float)
        q = self.q if q is None else np.asarray(q, dtype=float)
        bent = self.bends if bends is None else np.asarray(bends, dtype=float)
        tool = self.params.chain.tool
        key = (x.tobytes(), q.shape, q.tobytes(), tool.tobytes() + (b"" if bent is None else b"bent" + bent.tobytes()))
        recent = self._recent
        for index, (inputs, cached) in enumerate(recent):
            if inputs == key:  # computed already: `cached`
                result = cached
                del recent[index]
                break
        else:  # not among the recent results: compute it
            vector = self.full_vector(x)
            model = self.model if bent is None else self.bent_model()
            points = self.params.slot_points(vector)[self._slots]
            if bent is not None:  # the bend slots turn about their joint's origin
                points = np.vstack([points.reshape(-1, 3), np.zeros((len(model.slots) - len(self._slots), 3))])
            model.set_state(self.params.placements(vector), points, tool)
            poses, sens = model.evaluate(q, bent)
            to_slots = self.params.slot_jacobian(vector)
            if to_slots is not None:  # d(slot twist)/d(parameter) is not the identity
                block = to_slots[self._block].T  # (free, slots)
                sens = Sensitivity(
                    angular=block @ sens.angular,  # (K, free, 3): K small products, no BLAS threads
                    linear=block @ sens.linear,
                    origin=sens.origin,
                    joint_angular=sens.joint_angular,
                    joint_linear=sens.joint_linear,
                    bend_angular=sens.bend_angular,
                    bend_linear=sens.bend_linear,
                )
            result = (poses, sens)
            if len(recent) == self.RECENT:
                del recent[0]  # the least recently used
        recent.append((key, result))
        return result


class Objective(ABC):
    """Residual vector over the free parameters held by a :class:`KinematicsCache`."""

    def __init__(self, cache: KinematicsCache) -> None:
        self.cache = cache

    @property
    def n_free(self) -> int:
        return len(self.cache.free)

    @abstractmethod
    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        """Residual vector r(x), shape (m,)."""

    @abstractmethod
    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        """dr/dx, shape (m, n_free)."""


class BlockObjective(Objective):
    """An objective whose unknowns are the kinematic parameters and blocks of its own (registrations, target,
    mount...): ``blocks`` names each block's slice of x, ``n_params`` counts them all, and every one is free."""

    blocks: dict[str, slice]
    n_params: int

    @property
    def n_free(self) -> int:
        return self.n_params
