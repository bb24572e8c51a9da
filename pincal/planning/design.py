"""Choosing N configurations among candidates: criteria, greedy selection and exchange passes.

The parameters are those the whole candidate set can identify (pivoted QR,
:func:`pincal.fit.identifiability.order_parameters`: the others no subset can
determine), each scaled so that one candidate's information about it is 1 on
average over the candidates. With M the information of the chosen rows, plus
the rows already recorded, plus the calibration's physical prior Λ =
diag(1/σ_i²) on the kinematic parameters when it fits with one (``--select
prior``, eq P1 of :mod:`pincal.fit.prior`: M is then the posterior precision
the calibration will have), plus a numerical ε·I, ε = :data:`PRIOR`, that only
matters while M is singular, and P = M⁻¹:

* ``accuracy`` — minimise tr(P B), B = mean over the workspace sample and the
  target points of A_eᵀ A_e: the predicted mean *squared* position error of
  the calibrated model [m²] (I-optimality, Atkinson, Donev & Tobias 2007,
  §10.6); reported as the expected mean error E‖e‖ [mm];
* ``d`` — maximise ln det M (D-optimality, Kiefer 1959; FIGAROH's criterion);
* ``a`` — minimise tr P (A-optimality, on the scaled parameters).

Greedy selection adds the candidate that improves the criterion most; exchange
passes (Fedorov 1972, sequential form) then try to replace each chosen
configuration by the best other one until no swap helps. The exchange ends in a
local optimum that depends on where it starts (near the fewest configurations
that determine the parameters: the README's 12-point KUKA plan, seed 1, ended
6 % apart in predicted mean error with and without the prior, a 0.6 % change
of the problem), so it also starts from :data:`STARTS` − 1 random subsets drawn
with the plan's seed, and the best end is kept. Adding or removing
row block F_k (m × n) is a rank-m update of P (Sherman–Morrison–Woodbury):
with S = I ± F_k P F_kᵀ, P' = P ∓ P F_kᵀ S⁻¹ F_k P, ln det changes by
± ln det S and tr(P B) by ∓ tr(S⁻¹ F_k P B P F_kᵀ). The quantities of every
candidate (F P, F P Fᵀ, F P B P Fᵀ) are updated by the same rank-m terms, so a
step costs O(K m² n) for K candidates, not O(K m n²).

:func:`continuous_design` bounds what any choice can reach: the optimal
weights over the candidates (the convex relaxation), certified by the
equivalence theorem (scripts/plan_design_bound.py compares plans with it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from pincal.errors import PincalError
from pincal.fit.gaussian_norm import mean_norm
from pincal.fit.identifiability import condition_number, order_parameters
from pincal.progress import Counter

__all__ = [
    "CRITERIA", "PRIOR", "MAX_PASSES", "STARTS", "PASS_TOLERANCE", "SWAP_TOLERANCE", "QUADRATURE", "SINGULAR",
    "Prediction", "TargetPrediction", "DesignProblem", "Selection", "select", "priority_order", "ContinuousDesign",
    "CONTINUOUS_ITERATIONS", "CONTINUOUS_EFFICIENCY", "continuous_design",
]

CRITERIA = {
    "accuracy": "predicted mean squared position error of the calibrated model over the workspace sample "
                "(I-optimality), reported as the expected mean error [mm]",
    "d": "D-optimality: ln det of the information of the identifiable parameters (each scaled to unit "
         "mean information per candidate), maximised",
    "a": "A-optimality: trace of the covariance of the identifiable parameters (same scaling), minimised",
}
#: Prior information ε·I on the scaled parameters; keeps M invertible before it has full rank.
PRIOR = 1e-6
#: Exchange passes at most; each tries to replace every chosen configuration once.
MAX_PASSES = 10
#: Starts of the exchange: the greedy selection and STARTS − 1 random subsets (the best end is kept).
STARTS = 4
#: A pass improving the criterion by less than this (relative) is the last.
PASS_TOLERANCE = 1e-3
#: Relative improvement of the criterion below which a swap is not made.
SWAP_TOLERANCE = 1e-9
#: Sphere quadrature of the expected error norm (:func:`pincal.fit.gaussian_norm.mean_norm`):
#: 12 Gauss–Legendre × 24 trapezoid nodes, within 0.3 % of its 24 × 48 default for error
#: covariances with axis ratios up to 20 and 16 times faster.
QUADRATURE = (12, 24)
#: A design whose information has eigenvalues below this fraction of the largest
#: does not determine the parameters (its predicted error is reported as None).
SINGULAR = 1e-12


@dataclass(frozen=True)
class Prediction:
    """Linearised (noise-limited) accuracy of the model calibrated on a set of configurations.

    Attributes:
        mean_position_mm: mean over the workspace sample and target points of E‖position error‖ [mm].
        max_position_mm: the largest of those expected errors [mm].
        mean_rotation_deg / max_rotation_deg: the same for the target's orientation [deg] (pose only).
        condition: condition number of the column-scaled Jacobian of the rows.
    """

    mean_position_mm: float
    max_position_mm: float
    mean_rotation_deg: float | None
    max_rotation_deg: float | None
    condition: float

    def as_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass(frozen=True)
class TargetPrediction:
    """One target's share of a prediction (several targets on a tree): the mean and largest over the workspace
    sample and its points of E‖position error‖ [mm], for the plan and the median over the random choices (None:
    not determined).

    Attributes:
        link: the target's tip link; points: its point numbers (1 is x1,y1,z1).
        plan / random: (mean, max) [mm], or None.
    """

    link: str
    points: tuple[int, ...]
    plan: tuple[float, float] | None
    random: tuple[float, float] | None


class DesignProblem:
    """Candidates' information on the identifiable parameters, scaled.

    Args:
        blocks: weighted Jacobian blocks of the candidates, (K, m, n_all).
        kinematic: columns of the kinematic parameters (the others are always estimated).
        existing: blocks of rows already recorded, (K0, m, n_all).
        error_position: workspace position rows [m/unit], (E, P, 3, n_all).
        error_rotation: workspace orientation rows [rad/unit], (E, 3, n_all), or None.
        prior_precision: Λ's diagonal, 1/σ_i² [1/unit²] for each of the n_all columns (zero where
            no prior), or None: no prior (the calibration keeps a subset, eq S1–S3).
    """

    def __init__(self, blocks, kinematic, existing, error_position, error_rotation,
                 prior_precision=None) -> None:
        n_all = blocks.shape[2]
        others = np.setdiff1d(np.arange(n_all), kinematic)
        pool = np.concatenate([blocks, existing]).reshape(-1, n_all)
        ordering = order_parameters(pool, np.asarray(kinematic, dtype=int), others)
        self.identifiable = np.sort(ordering.order[: ordering.rank])
        self.not_identifiable = np.sort(ordering.order[ordering.rank :])
        self.columns = np.concatenate([self.identifiable, others]).astype(int)
        scale = np.sqrt(np.einsum("kij,kij->j", blocks, blocks) / len(blocks))[self.columns]
        scale[scale == 0] = 1.0
        self.scale = scale
        self.blocks = blocks[:, :, self.columns] / scale
        self.existing = existing[:, :, self.columns] / scale
        self.position = error_position[..., self.columns] / scale
        self.rotation = None if error_rotation is None else error_rotation[..., self.columns] / scale
        workspace = self.position.reshape(-1, 3, self.n)
        self.workspace = np.einsum("eim,ein->mn", workspace, workspace) / len(workspace)  # B [m²]
        self.base = np.einsum("kim,kin->mn", self.existing, self.existing)
        if prior_precision is not None:  # Λ in the scaled parameters: θ' = θ·scale
            self.base = self.base + np.diag(np.asarray(prior_precision, dtype=float)[self.columns] / scale**2)

    @property
    def n(self) -> int:
        return len(self.columns)

    @property
    def n_candidates(self) -> int:
        return len(self.blocks)

    def information(self, chosen) -> np.ndarray:
        """Information of the recorded rows, the prior (if any) and the candidates ``chosen`` (no ε·I)."""
        rows = self.blocks[np.asarray(chosen, dtype=int)]
        return self.base + np.einsum("kim,kin->mn", rows, rows)

    def criterion(self, chosen, criterion: str) -> float:
        """The criterion's value: ln det M (d), tr M⁻¹ (a) or the expected mean position error [mm] (accuracy)."""
        info = self.information(chosen)
        if criterion == "d":
            sign, logdet = np.linalg.slogdet(info)
            return float(logdet) if sign > 0 else float("-inf")
        if _singular(info):
            return float("inf")
        if criterion == "a":
            return float(np.trace(np.linalg.inv(info)))
        return cast(Prediction, self.predict(chosen)).mean_position_mm  # not singular: checked above

    def predict(self, chosen, condition: bool = True) -> Prediction | None:
        """Expected errors of the model calibrated on the recorded rows and ``chosen``; None if singular.

        ``condition=False`` skips the condition number (reported as NaN).
        """
        info = self.information(chosen)
        if _singular(info):
            return None
        pos, rot = self.expected_errors(np.linalg.inv(info))
        rot_mean, rot_max = (None, None) if rot is None else (float(rot.mean()), float(rot.max()))
        rows = np.concatenate([self.existing, self.blocks[np.asarray(chosen, dtype=int)]]).reshape(-1, self.n)
        cond = condition_number(rows) if condition else float("nan")
        return Prediction(float(pos.mean()), float(pos.max()), rot_mean, rot_max, cond)

    def point_errors(self, chosen) -> np.ndarray | None:
        """E‖position error‖ [mm] of each workspace configuration and target point, (E, P), of the model calibrated
        on the recorded rows and ``chosen``; None if singular."""
        info = self.information(chosen)
        if _singular(info):
            return None
        return self.expected_errors(np.linalg.inv(info))[0].reshape(len(self.position), -1)

    def expected_errors(self, covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """E‖position error‖ [mm] at each workspace configuration and target point, (E·P,), and
        E‖orientation error‖ [deg], (E,) or None, of a model whose scaled parameters have ``covariance`` (n, n)."""
        position = self.position.reshape(-1, 3, self.n)
        pos = mean_norm(position @ covariance @ position.transpose(0, 2, 1), *QUADRATURE) * 1000.0
        if self.rotation is None:
            return pos, None
        rotation = self.rotation @ covariance @ self.rotation.transpose(0, 2, 1)
        return pos, np.degrees(mean_norm(rotation, *QUADRATURE))


def _singular(info: np.ndarray) -> bool:
    eig = np.linalg.eigvalsh(info)
    return not eig[-1] > 0 or eig[0] <= SINGULAR * eig[-1]


class _Search:
    """Greedy selection and exchange over candidate blocks ``F`` (K, m, n).

    Args:
        blocks: the candidates' scaled blocks.
        base: information already there (recorded rows), (n, n).
        weight: B of tr(P B) (identity for ``a``, the workspace for ``accuracy``); None for ``d``.
        allowed: candidates that may be chosen, (K,).
    """

    def __init__(self, blocks: np.ndarray, base: np.ndarray, weight: np.ndarray | None, allowed: np.ndarray) -> None:
        self.F, self.base, self.B = blocks, base, weight
        self.allowed = allowed
        self.chosen = np.zeros(len(blocks), dtype=bool)
        self.eye = np.eye(self.F.shape[1])
        self.refresh()

    def refresh(self) -> None:
        """Recompute P, the criterion and every candidate's quantities from scratch (no accumulated rounding)."""
        rows = self.F[self.chosen]
        info = self.base + PRIOR * np.eye(len(self.base)) + np.einsum("kim,kin->mn", rows, rows)
        self.P = np.linalg.inv(info)
        K, m, n = self.F.shape
        self.G = (self.F.reshape(-1, n) @ self.P).reshape(K, m, n)
        self.Q = self.G @ self.F.transpose(0, 2, 1)
        if self.B is None:
            self.value = -np.linalg.slogdet(info)[1] / n  # −ln of the geometric-mean eigenvalue
        else:
            self.T = (self.G.reshape(-1, n) @ self.B).reshape(K, m, n) @ self.G.transpose(0, 2, 1)
            self.value = float(np.trace(self.P @ self.B))

    def deltas(self, sign: float, index=slice(None), Q=None, T=None) -> np.ndarray:
        """Change of the minimised criterion (−ln det M, or tr P B) by adding (+1) or removing (−1)
        each row (``Q``, ``T``: the candidates' quantities to use instead of the current ones)."""
        Q = self.Q if Q is None else Q
        S = self.eye + sign * Q[index]
        if self.B is None:  # det(M ± FᵀF) = det M · det(I ± F P Fᵀ), for either sign
            return -np.linalg.slogdet(S)[1]
        T = self.T if T is None else T
        return -sign * np.trace(np.linalg.solve(S, T[index]), axis1=-2, axis2=-1)

    def _step(self, k: int | np.integer, sign: float):
        """The rank-m terms of adding (+1) or removing (−1) candidate ``k``: P' = P − sign Z Zᵀ,
        and every candidate's F Z, Q' and T' (``T'`` None for ``d``)."""
        K, m, n = self.F.shape
        L = np.linalg.cholesky(self.eye + sign * self.Q[k])
        Z = np.linalg.solve(L, self.G[k]).T  # (n, m): Z Zᵀ = P F_kᵀ S⁻¹ F_k P
        FZ = (self.F.reshape(-1, n) @ Z).reshape(K, m, m)
        FZt = FZ.transpose(0, 2, 1)
        Q = self.Q - sign * FZ @ FZt
        T = None
        if self.B is not None:
            GBZ = (self.G.reshape(-1, n) @ (self.B @ Z)).reshape(K, m, m)
            cross = FZ @ GBZ.transpose(0, 2, 1)
            T = self.T - sign * (cross + cross.transpose(0, 2, 1)) + FZ @ (Z.T @ self.B @ Z) @ FZt
        return Z, FZ, Q, T

    def update(self, k: int | np.integer, sign: float, step=None) -> None:
        """Add (+1) or remove (−1) candidate ``k``: rank-m Woodbury updates."""
        K, m, n = self.F.shape
        Z, FZ, self.Q, T = self._step(k, sign) if step is None else step
        if T is not None:
            self.T = T
        self.P = self.P - sign * Z @ Z.T
        self.G = self.G - sign * (FZ.reshape(-1, m) @ Z.T).reshape(K, m, n)
        self.chosen[k] = sign > 0

    def best_addition(self, Q=None, T=None) -> tuple[int, float]:
        delta = self.deltas(+1.0, Q=Q, T=T)
        delta[self.chosen | ~self.allowed] = np.inf
        k = int(np.argmin(delta))
        return k, float(delta[k])

    def greedy(self, count: int, refresh_every: int = 20, counter: Counter | None = None) -> list[int]:
        """``count`` greedy additions (``counter`` ticks once per addition; announced by the caller)."""
        counter = Counter(None) if counter is None else counter
        order = []
        for step in range(count):
            k, _ = self.best_addition()
            self.update(k, +1.0)
            order.append(k)
            if (step + 1) % refresh_every == 0:
                self.refresh()
            counter.tick()
        self.refresh()
        return order

    def exchange(self, passes: int = MAX_PASSES, counter: Counter | None = None) -> int:
        """Sequential exchange passes until one improves the criterion by less than
        :data:`PASS_TOLERANCE` (relative; for ``d`` in the geometric-mean eigenvalue); returns the swaps made.
        ``counter`` ticks once per configuration tried; the first pass is announced by the caller."""
        counter = Counter(None) if counter is None else counter
        swaps = 0
        for number in range(passes):
            before, changed = self.value, 0
            if number:
                counter.expect(int(self.chosen.sum()))
            for k in np.flatnonzero(self.chosen):
                back = float(self.deltas(-1.0, [k])[0])  # criterion change of removing k
                removal = self._step(k, -1.0)  # tried first without changing the state
                self.chosen[k] = False
                candidate, delta = self.best_addition(removal[2], removal[3])
                self.chosen[k] = True
                if candidate != k and delta < -back - SWAP_TOLERANCE * max(abs(back), 1e-300):
                    self.update(k, -1.0, removal)
                    self.update(candidate, +1.0)
                    changed += 1
                counter.tick()
            self.refresh()
            swaps += changed
            gain = before - self.value if self.B is None else (before - self.value) / abs(before)
            if not changed or gain < PASS_TOLERANCE:
                break
        return swaps


@dataclass(frozen=True)
class Selection:
    """Chosen candidates and how the search went.

    Attributes:
        chosen: candidate indices, in the order the greedy then the exchange left them, (N,).
        priority: the same indices re-added greedily one by one: the best first, (N,).
        swaps: configurations replaced by the exchange passes.
    """

    chosen: np.ndarray
    priority: np.ndarray
    swaps: int


def select(problem: DesignProblem, count: int, criterion: str, allowed: np.ndarray | None = None,
           counter: Counter | None = None, starts: int = STARTS, seed: int = 0) -> Selection:
    """Choose ``count`` candidates minimising (``d``: maximising) the criterion.

    Exchange passes run from the greedy selection and from ``starts`` − 1 random
    subsets of the allowed candidates (drawn with ``seed``); the best end is kept.
    ``counter`` counts the greedy additions, the configurations each exchange pass
    tries and the additions of :func:`priority_order` (another pass is announced
    when it starts).

    Raises:
        PincalError: unknown criterion, or fewer allowed candidates than ``count``.
    """
    if criterion not in CRITERIA:
        raise PincalError(f"--criterion must be one of {', '.join(CRITERIA)}, got '{criterion}'")
    allowed = np.ones(problem.n_candidates, dtype=bool) if allowed is None else np.asarray(allowed, bool)
    if count > int(allowed.sum()):
        raise PincalError(f"--count {count} is more than the {int(allowed.sum())} usable candidates; "
                          "lower --count or give more candidates")
    counter = Counter(None) if counter is None else counter
    starts = max(1, int(starts))
    counter.expect((2 + starts) * count)  # greedy, each start's first exchange pass, the priority order
    rng = np.random.default_rng(seed)
    best, swaps = None, 0
    for start in range(starts):
        search = _Search(problem.blocks, problem.base, _weight(problem, criterion), allowed)
        if start == 0:
            search.greedy(count, counter=counter)
        else:
            search.chosen[rng.choice(np.flatnonzero(allowed), count, replace=False)] = True
            search.refresh()
        made = search.exchange(counter=counter)
        if best is None or search.value < best.value:
            best, swaps = search, made
    assert best is not None  # starts >= 1
    chosen = np.flatnonzero(best.chosen)
    return Selection(chosen=chosen, priority=priority_order(problem, chosen, criterion, counter), swaps=swaps)


def _weight(problem: DesignProblem, criterion: str) -> np.ndarray | None:
    return None if criterion == "d" else (np.eye(problem.n) if criterion == "a" else problem.workspace)


def priority_order(problem: DesignProblem, chosen: np.ndarray, criterion: str,
                   counter: Counter | None = None) -> np.ndarray:
    """``chosen`` ordered greedily: each next one improves the criterion most given the previous ones
    (``counter`` ticks once per addition; announced by the caller)."""
    chosen = np.asarray(chosen, dtype=int)
    search = _Search(problem.blocks[chosen], problem.base, _weight(problem, criterion), np.ones(len(chosen), bool))
    return chosen[np.array(search.greedy(len(chosen), counter=counter), dtype=int)]


@dataclass(frozen=True)
class ContinuousDesign:
    """The best approximate (continuous) design: weights over the candidates instead of N of them.

    With weights w (Σ w_k = 1) the information per measured configuration is
    M(w) = Σ w_k F_kᵀ F_k; the criterion is convex in w, so its optimum over the
    candidates is found to any accuracy and bounds every exact design: N
    configurations, each chosen at most once, give tr(B M_N⁻¹) ≥ ψ*/N
    (``accuracy``, ``a``) and ln det M_N ≤ n ln N + ln det M(w*) (``d``).

    Attributes:
        weights: w, (K,), zero outside ``allowed``.
        value: ψ(w) = tr(B M(w)⁻¹) for ``accuracy`` [m² per configuration] and ``a``;
            ln det M(w) for ``d``.
        efficiency: certified lower bound on the efficiency of w (general equivalence
            theorem, Kiefer & Wolfowitz 1960; Pukelsheim 1993, §5.15): with d_k the
            directional derivative of candidate k (see :func:`continuous_design`),
            ψ*/ψ(w) ≥ ψ(w)/max_k d_k for ``accuracy`` and ``a``, and
            (det M*/det M(w))^(−1/n) ≥ n/max_k d_k for ``d``; 1 at the optimum.
        bound: the optimum's value certified by ``efficiency``: ψ* ≥ ψ(w)·efficiency, or
            ln det M* ≤ ln det M(w) − n ln efficiency.
        iterations: multiplicative steps taken.
    """

    weights: np.ndarray
    value: float
    efficiency: float
    bound: float
    iterations: int


#: Multiplicative steps of :func:`continuous_design` at most, and its default target efficiency.
CONTINUOUS_ITERATIONS = 5000
CONTINUOUS_EFFICIENCY = 0.999


def continuous_design(problem: DesignProblem, criterion: str, allowed: np.ndarray | None = None,
                      efficiency: float = CONTINUOUS_EFFICIENCY,
                      iterations: int = CONTINUOUS_ITERATIONS) -> ContinuousDesign:
    """Optimal weights over the candidates by the multiplicative algorithm.

    With P = M(w)⁻¹ and H_k = F_kᵀF_k, the directional derivatives are
    d_k = tr(B P H_k P) (``accuracy``: B the workspace; ``a``: B = I) and
    d_k = tr(P H_k) (``d``); Σ w_k d_k is ψ(w) or n, and w is optimal iff no
    d_k exceeds it (equivalence theorem). Each step sets w_k ← w_k (d_k/Σ w d)^ρ,
    ρ = 1/2 for ``accuracy`` and ``a`` and ρ = 1 for ``d``, which never worsens the
    criterion (Silvey, Titterington & Torsney 1978; Yu 2010, Ann. Statist. 38,
    1593–1606), until the certified efficiency reaches ``efficiency``.

    Raises:
        PincalError: unknown criterion, recorded rows in the problem (the bound holds
            for new configurations alone), or no allowed candidate.
    """
    if criterion not in CRITERIA:
        raise PincalError(f"--criterion must be one of {', '.join(CRITERIA)}, got '{criterion}'")
    if len(problem.existing):
        raise PincalError("the continuous design bounds plans without recorded rows; leave out --existing")
    allowed = np.ones(problem.n_candidates, dtype=bool) if allowed is None else np.asarray(allowed, dtype=bool)
    if not allowed.any():
        raise PincalError("no usable candidate for the continuous design")
    F = problem.blocks[allowed]  # (K', m, n)
    K, m, n = F.shape
    B = _weight(problem, criterion)
    rows = F.reshape(-1, n)
    w = np.full(K, 1.0 / K)
    for step in range(1, iterations + 1):
        info = (rows * np.repeat(w, m)[:, None]).T @ rows  # M(w)
        P = np.linalg.inv(info)
        G = (rows @ P).reshape(K, m, n)  # F_k P
        if B is None:
            d = np.einsum("kin,kin->k", G, F)  # tr(P H_k)
            value, total, power = float(np.linalg.slogdet(info)[1]), float(n), 1.0
        else:
            d = np.einsum("kin,kin->k", (G.reshape(-1, n) @ B).reshape(K, m, n), G)  # tr(B P H_k P)
            value = total = float(np.trace(P @ B))
            power = 0.5
        achieved = total / float(d.max())
        if achieved >= efficiency or step == iterations:
            break
        w = w * (d / total) ** power
        w /= w.sum()
    bound = value - n * np.log(achieved) if B is None else value * achieved
    weights = np.zeros(problem.n_candidates)
    weights[allowed] = w
    return ContinuousDesign(weights=weights, value=value, efficiency=achieved, bound=float(bound), iterations=step)
