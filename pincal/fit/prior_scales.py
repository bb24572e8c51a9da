"""The prior's scales estimated from the data: empirical Bayes, one scale per kind, refereed by cross-validation.

The MAP fit of :mod:`pincal.fit.prior` holds every identifiable parameter under θ_i ~ N(0, σ_i²),
σ_i the scale of its kind (:data:`pincal.fit.prior_defaults.KINDS`: lengths, angles, joint zeros).
Scales fixed in advance suit the robots they were chosen on: 1 mm / 0.5° held a humanoid arm whose
placements are millimetres off near nominal, 18 of its 30 identifiable parameters. By default the
scales are estimated: type-II maximum likelihood, or empirical Bayes (MacKay 1992; Bishop 2006,
§3.5) — the scales, with the noise scales, that maximise the marginal likelihood of the rows (the
evidence of eq P3 with the prior's own normalisation):

    ln p(rows | s, σ) = −½ (Σ_rows ln s_row² + Σ_i ln σ_i² + ‖ẽ‖² + ln det(J̃ᵀJ̃))          (P4)

(ẽ, J̃ as in eq P3; the term Σ_i ln σ_i², over the kept kinematic parameters, is constant for fixed
scales and so left out of P3).

**Linearised (eq P5).** At the MAP fit x̂ at the scales now, W_k the data rows of noise kind k
(positions, orientations) whitened by their noise scale now, r_k their residual, θ̂ the kinematic
part of x̂, ρ_k = s_k(now) / s_k and Λ = diag 1/σ_i² (zero for the registration and the target):

    A = Σ_k ρ_k² W_kᵀW_k + Λ,   b = Σ_k ρ_k² W_kᵀr_k + Λθ̂,   d = −A⁻¹b,
    ‖ẽ‖² = Σ_k ρ_k² ‖r_k‖² + θ̂ᵀΛθ̂ + bᵀd                                                (P5)

so P4 costs one Cholesky factorisation of the n × n matrix A per trial. Its gradient gives MacKay's
conditions: ∂/∂ln ρ_k = m_k − ρ_k² (‖r_k + W_k d‖² + tr A⁻¹W_kᵀW_k), zero at eq P2; ∂/∂ln σ_j =
Σ_{i∈j} (θ_i*² + [A⁻¹]_ii) / σ_j² − n_j, zero where σ_j² = ‖θ_j*‖² / γ_j with θ* = θ̂ + d and
γ_j = Σ_{i∈j} (1 − [A⁻¹]_ii / σ_j²) the kind's well-determined parameters. L-BFGS-B maximises P5
within the bounds, the fit is redone at the new scales, and again until they settle.

**Guards.** Empirical Bayes fails in two known ways. On few rows a scale collapses to zero (a kind
whose few well-determined parameters the rows put near nominal: γ_j → 0) or explodes (a kind the
rows hardly see). A hyperprior holds the scales the rows hardly inform near the defaults:

    ln σ_j ~ N(ln σ_j(default), τ²),   τ = :data:`HYPERPRIOR_SPREAD`                        (P6)

(the spread of ISO 2768-1's general tolerance classes), and the scales maximise P4 + P6 — the
posterior mode of the scales; each stays within its physical range besides
(:data:`pincal.fit.prior_defaults.ESTIMATE_BOUNDS`, machining tolerances to the coarsest general
tolerance). On a 3D tracker raster at constant orientation, which hardly turns the tool, the
evidence alone shrank the angles' scale to 0.001–0.02° (the truth's 0.017°) and predicted a parallel
raster 3 % worse than the defaults; with P6 it stays at 0.02–0.05°. And the evidence trusts the
model: where the rows hold effects it lacks, it takes them for placement errors and widens the
scales to fit them (Grünwald & van Ommen 2017: under misspecification Bayesian inference overfits).
TIAGo's arm (data/tiago_mocap: a noise of 1.45 mm against the markers' 0.2 mm, a backlash ``pincal
diagnose`` finds) is such a case: the evidence prefers 4.8 mm to 1 mm lengths by a Bayes factor of
e⁵⁴, while 10-fold cross-validation on the same rows finds the held-out configurations predicted no
better (mean squared error 1.03 × the defaults', standard error 0.15) and the other day is predicted
worse (3.52 against 3.10 mm).
Cross-validation does not trust the model, so it referees (:func:`cross_validated`): the estimate
replaces the default scales only where its P4 + P6 is the larger and its cross-validated error is
lower than theirs by more than one standard error of the paired difference over the folds — the
one-standard-error rule of ``--level auto`` (Breiman et al. 1984), the physical defaults being the
simpler answer. Why not cross-validation alone, over a grid
of scales: a fold's error jumps with the rows dealt to it, and the grid's minimum with it, where
the evidence is a smooth function of the three scales that every row informs once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import cast

import numpy as np
import numpy.typing as npt
from scipy.linalg import cho_factor, cho_solve
from scipy.optimize import minimize

from pincal.errors import CalibrationError
from pincal.fit.folds import DEFAULT_FOLDS, configuration_keys, row_folds
from pincal.fit.prior import SCALE_FLOOR, PriorResidual
from pincal.fit.prior_defaults import ESTIMATE_BOUNDS
from pincal.fit.problem import KindProblem, ObjectiveT, Refit
from pincal.fit.solver import Solution, gram

__all__ = [
    "SETTLE_TOLERANCE", "MAX_ROUNDS", "HYPERPRIOR_SPREAD", "bounds_si", "hyperprior", "prior_log_evidence",
    "LinearisedFit", "estimate_scales", "scale_folds", "CrossValidation", "cross_validated", "chosen_scales",
]

#: Relative change of every estimated scale (prior and noise) below which the rounds of eq P5 stop: the
#: prior's weight then moves by 2 % (it scales as 1/σ²), well inside the estimate's own sampling error
#: (a scale estimated from n parameters varies by ~1/sqrt(2n): 10 % for 50).
SETTLE_TOLERANCE = 1e-2
#: Most rounds of eq P5 and a refit (two or three settle it; the bound stops a cycle).
MAX_ROUNDS = 8
#: Standard deviation of ln σ_j in the hyperprior about the default scales (eq P6): ln(13.3) / 2. The
#: general tolerances of ISO 2768-1 over 400–1000 mm run from class f (±0.3 mm) to class v (±4 mm), a
#: factor 13.3 whose geometric middle, 1.1 mm, is the default length scale; f and v then lie one
#: standard deviation either side. A scale the rows inform (TIAGo's lengths: the evidence moves by
#: e⁵⁴) hardly feels it (0.7 nats at 4.8 mm); one they hardly inform stays near its default.
HYPERPRIOR_SPREAD = math.log(13.3) / 2.0


def bounds_si() -> np.ndarray:
    """:data:`pincal.fit.prior_defaults.ESTIMATE_BOUNDS` in SI units (m, rad, rad), (3, 2)."""
    (low_l, high_l), (low_a, high_a), (low_z, high_z) = ESTIMATE_BOUNDS
    return np.array([[low_l * 1e-3, high_l * 1e-3], [math.radians(low_a), math.radians(high_a)],
                     [math.radians(low_z), math.radians(high_z)]])


def hyperprior(log_sigma: np.ndarray, centre: np.ndarray) -> tuple[float, np.ndarray]:
    """ln of the hyperprior of the scales (eq P6) at ``log_sigma`` (ln σ_j [SI]), up to a constant, and
    its gradient: ln σ_j ~ N(ln centre_j, :data:`HYPERPRIOR_SPREAD`²)."""
    z = (np.asarray(log_sigma) - np.log(centre)) / HYPERPRIOR_SPREAD
    return float(-0.5 * np.sum(z**2)), -z / HYPERPRIOR_SPREAD


def prior_log_evidence(data_evidence: float, sigma: np.ndarray) -> float:
    """Eq P4 from eq P3 (``data_evidence``, a problem's ``log_evidence``) and the kept parameters' σ_i."""
    return float(data_evidence - np.sum(np.log(np.asarray(sigma, dtype=float))))


def _factor(a: np.ndarray) -> tuple[tuple[np.ndarray, bool], np.ndarray]:
    """Cholesky factor of ``a`` scaled to a unit diagonal, and the scale: a = S F Fᵀ S."""
    scale = 1.0 / np.sqrt(np.maximum(np.diag(a), np.finfo(float).tiny))
    try:
        return cho_factor(a * scale[:, None] * scale[None, :]), scale
    except np.linalg.LinAlgError:
        raise CalibrationError("the linearised MAP fit is singular at these scales") from None


@dataclass(frozen=True)
class LinearisedFit:
    """A MAP fit linearised at its solution (eq P5): its whitened data rows, the noise kind of each,
    and its kinematic unknowns with their kinds and prior scales.

    Attributes:
        jacobian: the data rows of the Jacobian, whitened by the noise scales now, (m, n).
        residual: the whitened data residual, (m,).
        group: each data row's noise kind (index into ``noise``), (m,).
        noise: the noise scales now [m, rad], (K,).
        kinematic: the kinematic columns of the unknowns, (n_kin,).
        theta: θ̂, the kinematic unknowns at the solution [m, rad], (n_kin,).
        kinds: each kinematic unknown's kind (index into :data:`pincal.fit.prior.KINDS`), (n_kin,).
        sigma: each kinematic unknown's prior std σ_i in the fit [m, rad], (n_kin,).
    """

    jacobian: np.ndarray
    residual: np.ndarray
    group: np.ndarray
    noise: np.ndarray
    kinematic: np.ndarray
    theta: np.ndarray
    kinds: np.ndarray
    sigma: np.ndarray

    @classmethod
    def at(cls, objective: PriorResidual, solution: Solution, row_groups: tuple[slice, ...], noise: npt.ArrayLike,
           kinds: np.ndarray) -> LinearisedFit:
        """Of a MAP fit: its data rows (divided by the objective's ``noise`` weight: whitened) in the
        ``row_groups`` of the noise scales ``noise`` now, its kinematic unknowns of ``kinds``."""
        return cls.of(objective, solution.x, solution.jacobian, solution.residual, row_groups, noise, kinds)

    @classmethod
    def of(cls, objective: PriorResidual, x: np.ndarray, jacobian: np.ndarray, residual: np.ndarray,
           row_groups: tuple[slice, ...], noise: npt.ArrayLike, kinds: np.ndarray) -> LinearisedFit:
        """As :meth:`at`, from the objective's unknowns ``x``, Jacobian and residual there (prior rows last)."""
        m = residual.size - objective.n_prior
        group = np.full(m, -1)
        for k, rows in enumerate(row_groups):
            group[rows] = k
        kin = objective.blocks["kinematic"]
        return cls(jacobian=jacobian[:m] / objective.noise, residual=residual[:m] / objective.noise,
                   group=group, noise=np.asarray(noise, dtype=float), kinematic=np.arange(kin.start, kin.stop),
                   theta=np.asarray(x)[kin].copy(), kinds=np.asarray(kinds, dtype=int),
                   sigma=objective.noise / objective.weight)

    def on(self, rows: np.ndarray) -> LinearisedFit:
        """The same linearisation over the data rows ``rows`` only (boolean, (m,)): what a fit of those rows
        would see (the model is linear: the solution it moves from does not matter)."""
        return replace(self, jacobian=self.jacobian[rows], residual=self.residual[rows], group=self.group[rows])

    def at_scales(self, sigma_kinds: np.ndarray) -> LinearisedFit:
        """The same linearisation with the prior scales of the kinds ``sigma_kinds`` (3,) [SI]."""
        return replace(self, sigma=np.asarray(sigma_kinds, dtype=float)[self.kinds])

    @property
    def present(self) -> np.ndarray:
        """The kinds with a kinematic unknown, ascending."""
        return np.unique(self.kinds)

    def _normal(self, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A and b of eq P5 at the fit's own scales over the data rows ``rows`` (boolean), (n, n) and (n,)."""
        lam = 1.0 / self.sigma**2
        jac = self.jacobian[rows]
        a = gram(jac)
        a[self.kinematic, self.kinematic] += lam
        b = jac.T @ self.residual[rows]
        b[self.kinematic] += lam * self.theta
        return a, b

    def _groups(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per noise kind k: W_kᵀW_k (K, n, n), W_kᵀr_k (K, n), ‖r_k‖² (K,) and m_k (K,)."""
        kinds = range(self.noise.size)
        return (np.array([gram(self.jacobian[self.group == k]) for k in kinds]),
                np.array([self.jacobian[self.group == k].T @ self.residual[self.group == k] for k in kinds]),
                np.bincount(self.group, self.residual**2, self.noise.size),
                np.bincount(self.group, minlength=self.noise.size).astype(float))

    def evidence(self, u: np.ndarray, groups: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
                 ) -> tuple[float, np.ndarray]:
        """Eq P4 by P5 and its gradient at u = (ln ρ_k for each noise kind, ln σ_j [SI] for each
        :attr:`present` kind) (module docstring); ``groups``: :meth:`_groups`, computed once by the caller."""
        grams, gradients, squares, rows = self._groups() if groups is None else groups
        n_noise = self.noise.size
        rho2 = np.exp(2.0 * u[:n_noise])
        sigma = np.exp(u[n_noise:])[np.searchsorted(self.present, self.kinds)]
        lam = 1.0 / sigma**2
        a = np.tensordot(rho2, grams, axes=1)
        a[self.kinematic, self.kinematic] += lam
        b = rho2 @ gradients
        b[self.kinematic] += lam * self.theta
        factor, scale = _factor(a)
        d = -scale * cho_solve(factor, scale * b)
        inverse = scale[:, None] * cho_solve(factor, np.diag(scale))
        logdet = 2.0 * float(np.sum(np.log(np.diag(factor[0])))) - 2.0 * float(np.sum(np.log(scale)))
        misfit = float(rho2 @ squares + np.sum(lam * self.theta**2) + b @ d)
        log_noise = float(np.sum(rows * (2.0 * np.log(self.noise) - np.log(rho2))))
        value = -0.5 * (log_noise + float(np.sum(np.log(sigma**2))) + misfit + logdet)
        # gradient: MacKay's conditions (module docstring)
        errors = squares + 2.0 * gradients @ d + np.einsum("i,kij,j->k", d, grams, d)
        traces = np.einsum("ij,kji->k", inverse, grams)
        grad_noise = rows - rho2 * (errors + traces)
        star = self.theta + d[self.kinematic]
        per = lam * (star**2 + np.diag(inverse)[self.kinematic]) - 1.0
        grad_prior = np.array([per[self.kinds == j].sum() for j in self.present])
        return value, np.concatenate([grad_noise, grad_prior])

    def maximise(self, sigma_kinds: np.ndarray, centre: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The noise scales (K,) and the scales of the kinds (3,) [SI] maximising eq P5 plus the hyperprior
        about ``centre`` (3,) [SI] (:func:`hyperprior`; default: ``sigma_kinds``) from the noise now and
        ``sigma_kinds`` (3,) [SI], within :func:`bounds_si` (kinds without an unknown keep theirs)."""
        centre = np.asarray(sigma_kinds if centre is None else centre, dtype=float)
        bounds = bounds_si()
        present = self.present
        start = np.clip(np.asarray(sigma_kinds, dtype=float)[present], bounds[present, 0], bounds[present, 1])
        u0 = np.concatenate([np.zeros(self.noise.size), np.log(start)])
        # ρ_k may raise a noise scale without bound, and lower it to eq P2's floor
        limits: list[tuple[float | None, float]] = [(None, float(np.log(max(s / SCALE_FLOOR, 1.0))))
                                                    for s in self.noise]
        limits += [(float(np.log(bounds[j, 0])), float(np.log(bounds[j, 1]))) for j in present]

        groups = self._groups()

        def negative(u: np.ndarray) -> tuple[float, np.ndarray]:
            value, grad = self.evidence(u, groups)
            prior, prior_grad = hyperprior(u[self.noise.size:], centre[present])
            return -(value + prior), -np.concatenate([grad[: self.noise.size], grad[self.noise.size:] + prior_grad])

        u = minimize(negative, u0, jac=True, method="L-BFGS-B", bounds=limits).x
        out = np.asarray(sigma_kinds, dtype=float).copy()
        out[present] = np.exp(u[self.noise.size:])
        return self.noise / np.exp(u[: self.noise.size]), out

    def fold_errors(self, folds: list[np.ndarray], reference: np.ndarray) -> np.ndarray:
        """Each fold's mean squared error of prediction (F,): the fit of the other rows (exact for the
        linearised fit: its prior rows and every unpenalised unknown refitted) at its held-out data rows
        ``folds[f]`` (indices), in units of the noise scales ``reference`` (K,) [m, rad]; inf where
        the other rows leave the fit singular."""
        out = []
        for rows in folds:
            train = np.ones(self.residual.size, dtype=bool)
            train[rows] = False
            a, b = self._normal(train)
            try:
                factor, scale = _factor(a)
            except CalibrationError:
                out.append(np.inf)
                continue
            d = -scale * cho_solve(factor, scale * b)
            error = (self.residual[rows] + self.jacobian[rows] @ d) * (self.noise / reference)[self.group[rows]]
            out.append(float(np.mean(error**2)))
        return np.array(out)


def estimate_scales(problem: KindProblem[ObjectiveT], objective: ObjectiveT, solution: Solution, refit: Refit,
                    kinds: np.ndarray, start: np.ndarray, first: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[KindProblem[ObjectiveT], ObjectiveT, Solution, np.ndarray]:
    """Rounds of eq P5 + P6 from a MAP fit of ``problem`` (:class:`pincal.fit.problem.KindProblem`):
    the scales maximising the linearised posterior of the scales, the fit redone at them, until they
    settle (:data:`SETTLE_TOLERANCE`, at most :data:`MAX_ROUNDS`).

    Args:
        objective, solution: the MAP fit (a :class:`pincal.fit.prior.PriorResidual` and its solution).
        refit: the kept kinematic parameters and how the pipeline refits them.
        kinds: the kind of every kinematic parameter of the problem (:func:`pincal.fit.prior.parameter_kinds`), (n,).
        start: the scales of the kinds the fit was made with [m, rad, rad], (3,), the hyperprior's centre.
        first: the first round's maximum (noise scales, scales of the kinds), when the caller has it.

    Returns:
        The problem of the last fit (``problem`` at its noise scales and ``prior``), that fit (its
        objective and solution) and the scales of the kinds it was made with [SI], (3,).
    """
    centre = sigma = np.asarray(start, dtype=float)
    for _ in range(MAX_ROUNDS):
        now = problem.scales()
        present = np.array([s for s in now if s is not None])
        if first is None:
            model = LinearisedFit.at(cast(PriorResidual, objective), solution, problem.scale_rows(objective), present,
                                     kinds[refit.kept])
            noise, estimate = model.maximise(sigma, centre)
        else:
            (noise, estimate), first = first, None
        moved = np.concatenate([np.abs(np.log(estimate / sigma)), np.abs(np.log(noise / present))])
        if moved.max() < SETTLE_TOLERANCE:
            break  # the fit is made at the scales its own linearisation prefers
        values = iter(noise.tolist())
        problem = problem.with_scales(tuple(None if s is None else next(values) for s in now)).with_prior(
            estimate[kinds])
        objective, solution = refit.of(problem, solution.x)
        sigma = estimate
    return problem, objective, solution, sigma


def scale_folds(q: np.ndarray, strata: np.ndarray, entries: np.ndarray) -> list[np.ndarray]:
    """The data rows (residual entries) of each fold: the rows' configurations (joint readings ``q``,
    (K, N)) dealt to :data:`pincal.fit.folds.DEFAULT_FOLDS` folds (fewer configurations: one each),
    each of ``strata`` (K,) alike (a session, a fixture's socket), row k's entries ``entries[k]``."""
    keys = configuration_keys(q)
    folds = min(DEFAULT_FOLDS, len(np.unique(keys, axis=0)))
    return [np.asarray(entries)[rows].ravel() for rows in row_folds(keys, strata, folds) if rows.size]


@dataclass(frozen=True)
class CrossValidation:
    """The estimate against the default scales over the same folds (:func:`cross_validated`).

    Attributes:
        ratio: mean over the folds of the estimate's mean squared error over the defaults' (1: alike).
        standard_error: the standard error of that ratio (std of the paired difference over the
            folds / sqrt(folds), over the defaults' mean).
        folds: how many folds.
    """

    ratio: float
    standard_error: float
    folds: int

    @property
    def better(self) -> bool:
        """Whether the estimate predicts held-out configurations better by more than one standard error."""
        return bool(np.isfinite(self.ratio) and self.ratio < 1.0 - self.standard_error)


def cross_validated(estimate: LinearisedFit, default: LinearisedFit, folds: list[np.ndarray]) -> CrossValidation:
    """The one-standard-error comparison of the module docstring: both fits' fold errors
    (:meth:`LinearisedFit.fold_errors`) in the default fit's noise units, paired over ``folds``."""
    mine = estimate.fold_errors(folds, default.noise)
    theirs = default.fold_errors(folds, default.noise)
    if not (np.all(np.isfinite(mine)) and np.all(np.isfinite(theirs))) or len(folds) < 2:
        return CrossValidation(np.inf, np.inf, len(folds))
    mean = float(np.mean(theirs))
    difference = mine - theirs
    return CrossValidation(float(np.mean(mine)) / mean,
                           float(np.std(difference, ddof=1) / np.sqrt(difference.size)) / mean, len(folds))


def chosen_scales(fit: LinearisedFit, rows: np.ndarray, q: np.ndarray, strata: np.ndarray, entries: np.ndarray,
                  defaults: np.ndarray) -> np.ndarray:
    """The σ_i (n_kin,) [m, rad] this module's rule chooses from the data rows ``rows`` (boolean, (m,)) of a
    linearised fit alone: eq P5 maximised on them from the scales ``defaults`` of the kinds (3,) [SI] (its
    maximum's evidence is at least the defaults'), and the estimate kept where it beats the defaults by
    one standard error over folds of those rows (``q``, ``strata``, ``entries``: the rows', as
    :func:`scale_folds` takes them, ``entries`` numbering ``fit``'s data rows). For cross-validation at
    scale (:mod:`pincal.fit.fold_update`): a fold's scales then owe nothing to its held-out rows."""
    at_defaults = fit.on(rows).at_scales(defaults)
    try:
        _, estimate = at_defaults.maximise(defaults)
        candidate = at_defaults.at_scales(estimate)
        check = cross_validated(candidate, at_defaults, scale_folds(q, strata, (np.cumsum(rows) - 1)[entries]))
    except CalibrationError:
        return at_defaults.sigma
    return candidate.sigma if check.better else at_defaults.sigma
