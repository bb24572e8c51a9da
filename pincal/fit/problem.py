"""What a kind of measurement gives the calibration pipeline: a problem, and how its kept parameters are refitted.

:mod:`pincal.fit.pipeline` runs the same steps on every kind (sensor rows,
:class:`pincal.fit.chain_calibration.FitProblem`; socket-fixture rows,
:class:`pincal.fit.fixture_calibration.FixtureProblem`); :class:`KindProblem` is the interface
they share, here so that the pipeline's parts (:mod:`pincal.fit.prior_scales`, the selection) can
name it without importing the pipeline.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np

from pincal.fit.solver import Solution
from pincal.model.parameter_sets import ChainParameters

__all__ = ["ObjectiveT", "KindProblem", "Refit"]


class _Blocks(Protocol):
    @property
    def blocks(self) -> dict[str, slice]:
        """The unknowns' blocks; "kinematic": the free kinematic parameters."""
        ...

    def residual(self, x: np.ndarray) -> np.ndarray: ...

    def jacobian(self, x: np.ndarray) -> np.ndarray: ...

    def start_vector(self) -> np.ndarray: ...


#: A kind's objective: its residual over the free kinematic parameters and the always-estimated part
#: (with a prior, :class:`pincal.fit.prior.PriorResidual` wrapping it).
ObjectiveT = TypeVar("ObjectiveT", bound=_Blocks)


class KindProblem(Protocol[ObjectiveT]):
    """What a kind of measurement gives the pipeline (and :func:`pincal.fit.selection.select_subset`): a
    value; its variants (another prior, other noise scales) are new problems, which the pipeline threads through."""

    @property
    def params(self) -> ChainParameters | None:
        """The parameter set, None at level registration."""
        ...

    @property
    def prior(self) -> np.ndarray | None:
        """σ_i of every kinematic parameter with a prior (eq P1), given by the pipeline (:meth:`with_prior`)."""
        ...

    def with_prior(self, prior: np.ndarray | None) -> KindProblem[ObjectiveT]:
        """This problem with ``prior`` (None: without one)."""
        ...

    def objective(self, free: np.ndarray, base: np.ndarray) -> ObjectiveT: ...

    def fit(self, free: np.ndarray, base: np.ndarray, x0: np.ndarray | None = None,
            what: str = "fit") -> tuple[ObjectiveT, Solution]: ...

    def scales(self) -> tuple[float | None, ...]:
        """The residual's noise scales now (each [m] or [rad]; None where a kind is not measured)."""
        ...

    def rescaled(self, objective: ObjectiveT, solution: Solution) -> KindProblem[ObjectiveT]:
        """This problem at the noise scales re-estimated from ``solution``'s residual (with a prior: eq P2)."""
        ...

    def with_scales(self, scales: tuple[float | None, ...]) -> KindProblem[ObjectiveT]:
        """This problem with its rows weighted by ``scales`` (as :meth:`scales` gives them)."""
        ...

    def log_evidence(self, objective: ObjectiveT, solution: Solution) -> float:
        """Eq P3 of :mod:`pincal.fit.prior` for a MAP fit of this problem."""
        ...

    def scale_rows(self, objective: ObjectiveT) -> tuple[slice, ...]:
        """The data rows each noise scale of :meth:`scales` weights (those not None, in order)."""
        ...

    def fold_rows(self, objective: ObjectiveT) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each row's joint readings (K, N), stratum (K,) and residual entries (K, b), for the prior's
        folds (:func:`pincal.fit.prior_scales.scale_folds`)."""
        ...


@dataclass(frozen=True)
class Refit:
    """How the pipeline refits the kept kinematic parameters after the selection (at new noise or prior
    scales): which are free, the values of the others, and the fit's name in the solver's messages.

    Attributes:
        kept: indices of the kinematic parameters fitted, sorted.
        base: every kinematic parameter's value where it is not fitted (n,) [m, rad].
        what: the fit's name (``"full fit"``).
    """

    kept: np.ndarray
    base: np.ndarray
    what: str

    def of(self, problem: KindProblem[ObjectiveT], x0: np.ndarray | None) -> tuple[ObjectiveT, Solution]:
        """``problem``'s fit of the kept parameters from ``x0`` (None: the problem's start)."""
        return problem.fit(self.kept, self.base, x0, what=self.what)
