"""How many of the ordered parameters to keep: every nested subset scored from one factorisation.

The candidates are the prefixes of the identifiable kinematic parameters in the
order of :func:`pincal.fit.identifiability.order_parameters` (best determined
first), each fitted together with the always-estimated unknowns (registration,
target). Refitting every prefix nonlinearly costs rank + 1 fits, each of them
slow when the weakest directions are nearly undetermined; instead:

1. **One factorisation.** At the linearisation point x0 (the nominal kinematics
   with the registration and target fitted), with residual r (m,) and Jacobian
   J, the columns B = [A | k_1 … k_n] (always-estimated A first, then the
   ordered kinematic columns, each scaled to unit norm) have a thin QR
   factorisation B = Q R (Golub & Van Loan 2013, §5.2). With r̃ = Qᵀr, the linear
   least-squares fit of the first a + j columns leaves

       RSS_j = ‖r − Q Qᵀ r‖² + Σ_{i > a + j} r̃_i²                    (S1)

   (Q's leading a + j columns span exactly those columns), for every j in one
   pass. Its residual is e_j = e_{j−1} − q_{a+j} r̃_{a+j}, and the row blocks of
   its hat matrix grow by rank-one terms, H_bb(j) = H_bb(j−1) + q_{a+j,b} q_{a+j,b}ᵀ,
   so the leave-one-row-out residuals (I − H_bb)⁻¹ e_b (Allen 1974) give PRESS
   for every j as well (S2). The information criteria (Akaike 1974, Schwarz
   1978) follow from RSS_j: m ln(RSS_j / m) + c (a + j), c = 2 or ln m.
2. **Determined at all?** Along the weakest kinematic direction w_j of prefix j —
   the right singular vector of R's kinematic block R_KK for its smallest singular value
   s_j, whose Gram matrix is the kinematic information with the always-estimated
   unknowns (registration, target) profiled out — the parameters move as
   u_j = [−R_AA⁻¹ R_AK w_j; w_j] (the always-estimated part following, ‖B u_j‖ = s_j).
   The data's information along w_j (the profile's) is s_j², while the model's curvature
   weighted by the residuals, S = Σ_i e_j,i ∇²f_i, changes the profile's gradient by
   Pᵀ S u_j per unit step, P = [−R_AA⁻¹ R_AK; I] (S u_j's kinematic part with its
   always-estimated part eliminated; wᵀ Pᵀ S u_j = u_jᵀ S u_j). With

       ρ_j = ‖Pᵀ S u_j‖ / s_j²                                         (S3)

   at least one, ‖C⁻¹ S_p w_j‖ ≥ 1 for the profile's information C = R_KKᵀ R_KK and
   curvature S_p (equal to ρ_j when S_p w_j lies along w_j): the curvature is as large
   as the information along w_j, where Gauss–Newton's local contraction (Dennis &
   Schnabel 1983, Theorem 10.2.1: convergence needs the spectral radius of C⁻¹ S_p
   below one) is lost in practice, and the estimate along u_j is made by the noise
   through the curvature, not by the data. A practical criterion, not a proof: the
   spectral radius is at least |w_jᵀ C⁻¹ S_p w_j|, which ρ_j bounds from above.
   Without always-estimated columns this is the earlier ‖S u_j‖ / s_j².
   Levenberg–Marquardt then crawls along the curved valley for hundreds of
   evaluations (794 on a 2 500-row UR5 session whose wrist never bends, as in
   scripts/benchmark.py (f) but with 1e-6 rad of encoder jitter). Such a prefix, and
   every larger one, is not a candidate. Judging the kinematic directions given the
   always-estimated unknowns matters where those are weakly determined: a target
   whose tool hardly turns made every prefix's weakest direction the target's own
   (measured on tests/test_target_hold.py's raster turning 0.1° RMS, seed 8: 0 of 18 kept
   with the whole block's weakest direction and ‖S u‖, 13 now; the test asserts half).
   S u_j is one finite difference of the Jacobian along u_j (:func:`curvature_ratios`).
3. **Finalists refitted.** The linear scores ignore the curvature of the model
   (on the TIAGo data they differ from the nonlinear ones by up to ~7 units of
   AIC). The linear minimum and its neighbours are refitted nonlinearly; from
   then on every candidate whose linear score, lowered by :data:`SAFETY` times
   the largest linearisation error seen on the refitted ones, could still beat
   the best refitted score is refitted too, and so are the neighbours of the
   best (:func:`refine`). The candidate kept is the best *refitted* one.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Literal, cast

import numpy as np
import scipy.linalg

from pincal.errors import CalibrationError
from pincal.fit.identifiability import LEVERAGE_FLOOR, Ordering, Selection, press
from pincal.fit.prior import SCALE_FLOOR, Prior
from pincal.fit.problem import KindProblem, ObjectiveT
from pincal.fit.solver import solve
from pincal.measurements.data import MeasurementSet
from pincal.progress import Counter

__all__ = [
    "SelectionCriterion",
    "SELECTION_CRITERIA", "SELECTION_TOLERANCE", "SAFETY", "MAX_CONDITION", "MAX_CURVATURE_RATIO", "CURVATURE_STEP",
    "NestedFits", "information_criterion", "nested_fits", "curvature_ratios", "refine", "select_subset",
]

#: How the number of identifiable kinematic parameters kept is chosen (``--select``).
SelectionCriterion = Literal["aic", "bic", "press", "all", "prior"]
#: Each :data:`SelectionCriterion` in words.
SELECTION_CRITERIA: dict[SelectionCriterion, str] = {
    "aic": "Akaike information criterion m ln(RSS/m) + 2n on the calibration rows",
    "bic": "Bayesian information criterion m ln(RSS/m) + n ln(m) on the calibration rows",
    "press": "linearised leave-one-row-out cross-validation (PRESS) on the calibration rows",
    "all": "every identifiable parameter (AIC reported)",
    "prior": ("every identifiable parameter, with Gaussian priors of physical scale about nominal (MAP fit, "
              "pincal.fit.prior; value: effective number of kinematic parameters)"),
}

#: Solver tolerance of the nested fits that only score a subset (their criterion
#: moves by ~1e-8; the subset chosen is refitted at the solver's own tolerance).
SELECTION_TOLERANCE = 1e-10

#: A candidate whose linearised score minus SAFETY × (largest |nonlinear − linear| seen on
#: the refitted candidates) is not above the best refitted score is refitted as well.
SAFETY = 2.0
#: Largest condition number of a candidate's (unscaled) Jacobian, as the solver's
#: :data:`pincal.fit.solver.MAX_CONDITION`: beyond it the candidate cannot be fitted.
MAX_CONDITION = 1e12
#: ρ_j of eq S3 at or above which prefix j is not determined (Gauss–Newton's local
#: convergence bound, Dennis & Schnabel 1983, Theorem 10.2.1).
MAX_CURVATURE_RATIO = 1.0
#: Largest parameter change [m or rad] of the finite difference giving S u_j: far above
#: rounding (the Jacobian is exact to ~1e-16 relative), far below the curvature's scale.
CURVATURE_STEP = 1e-4


@dataclass(frozen=True)
class NestedFits:
    """Linear least-squares fits of r by the columns A and each prefix of the ordered columns.

    Attributes:
        rss: RSS_j of eq S1 for j = 0 … n, (n + 1,) [units of r²].
        press: PRESS_j of eq S2, (n + 1,), or None when no row blocks were given.
        n_always: a, the number of always-estimated columns.
        m: the number of residuals.
        feasible: (n + 1,) False where the prefix's Jacobian is numerically singular
            (condition number above :data:`MAX_CONDITION`).
        q, r: the thin QR factors of the scaled columns, (m, a + n) and (a + n, a + n).
        scale: the columns' norms (a + n,); projected: r̃ = Qᵀr (a + n,); residual: r (m,).
    """

    rss: np.ndarray
    press: np.ndarray | None
    n_always: int
    m: int
    feasible: np.ndarray
    q: np.ndarray
    r: np.ndarray
    scale: np.ndarray
    projected: np.ndarray
    residual: np.ndarray

    def scores(self, criterion: SelectionCriterion | Prior) -> np.ndarray:
        """The criterion of every prefix: ``aic``, ``bic`` or ``press`` (inf where not feasible; any other
        criterion scores as ``aic``)."""
        unknowns = self.n_always + np.arange(self.rss.size)
        if criterion == "press":
            if self.press is None:
                raise ValueError("PRESS needs the residuals' row blocks")
            values = self.press.copy()
        else:
            per_unknown = np.log(self.m) if criterion == "bic" else 2.0
            values = information_criterion(self.rss, self.m, unknowns, per_unknown)
        values[~self.feasible] = np.inf
        return values

    def fit_residual(self, j: int) -> np.ndarray:
        """e_j, the residual of the linear fit of prefix j (m,)."""
        size = self.n_always + j
        return self.residual - self.q[:, :size] @ self.projected[:size]


def information_criterion(rss: np.ndarray | float, m: int, unknowns: np.ndarray | int,
                          per_unknown: float) -> np.ndarray:
    """m ln(RSS / m) + per_unknown · unknowns: AIC with 2 per unknown, BIC with ln m."""
    return m * np.log(np.asarray(rss, dtype=float) / m) + per_unknown * np.asarray(unknowns, dtype=float)


def nested_fits(
    jacobian: np.ndarray,
    residual: np.ndarray,
    always: Sequence[int],
    ordered: Sequence[int],
    blocks: np.ndarray | None = None,
) -> NestedFits:
    """Eq S1 (and S2 with ``blocks``) for every prefix of ``ordered``, from one thin QR.

    Args:
        jacobian: (m, n_columns) at the linearisation point.
        residual: (m,) there.
        always: columns in every fit (registration, target).
        ordered: kinematic columns, in the order they are added.
        blocks: (K, b) indices of each measurement row's residuals (for PRESS), or None.
    """
    always, ordered = list(always), list(ordered)
    a, n = len(always), len(ordered)
    usable = max(0, min(n, np.shape(residual)[0] - a - 1))  # a prefix must leave a residual degree of freedom
    if usable < n:  # the longer prefixes: not feasible (more unknowns than residuals, or an exact fit)
        fits = nested_fits(jacobian, residual, always, ordered[:usable], blocks)
        pad = n - usable
        return replace(fits, rss=np.concatenate([fits.rss, np.full(pad, fits.rss[-1])]),
                       press=None if fits.press is None else np.concatenate([fits.press, np.full(pad, np.inf)]),
                       feasible=np.concatenate([fits.feasible, np.zeros(pad, dtype=bool)]))
    columns = np.asarray(jacobian, dtype=float)[:, always + ordered]
    scale = np.linalg.norm(columns, axis=0)
    scale[scale == 0.0] = 1.0
    q, r = np.linalg.qr(columns / scale)  # Q (m, a + n), R (a + n, a + n)
    residual = np.asarray(residual, dtype=float)
    projected = q.T @ residual  # r̃
    outside = residual - q @ projected
    tail = np.concatenate([np.cumsum((projected[a:] ** 2)[::-1])[::-1], [0.0]])  # Σ_{i > a + j} r̃_i²
    rss = float(outside @ outside) + tail
    feasible = _feasible(r * scale, a, n)
    press = None if blocks is None else _nested_press(q, projected, residual, a, n, np.asarray(blocks))
    return NestedFits(rss=rss, press=press, n_always=a, m=residual.size, feasible=feasible,
                      q=q, r=r, scale=scale, projected=projected, residual=residual)


def _feasible(r: np.ndarray, a: int, n: int) -> np.ndarray:
    """Whether each prefix's Jacobian, with triangular factor r[:a + j, :a + j] (the same
    singular values; columns unscaled), has a condition number within :data:`MAX_CONDITION`.

    Adding a column never lowers the condition number (singular values interlace), so
    one SVD of the whole factor settles the usual case, and a bisection the others
    (few LAPACK calls: on a loaded machine each can wait milliseconds for BLAS threads).
    """

    def conditioned(j: int) -> bool:
        if a + j == 0:
            return True
        singular = np.linalg.svd(r[: a + j, : a + j], compute_uv=False)
        return bool(singular[-1] > 0 and singular[0] <= MAX_CONDITION * singular[-1])

    out = np.ones(n + 1, dtype=bool)
    if conditioned(n):
        return out
    low, high = -1, n  # prefix `low` conditioned (-1: none known), `high` not
    while high - low > 1:
        middle = (low + high) // 2
        low, high = (middle, high) if conditioned(middle) else (low, middle)
    out[high:] = False
    return out


def _nested_press(q: np.ndarray, projected: np.ndarray, residual: np.ndarray, a: int, n: int,
                  blocks: np.ndarray) -> np.ndarray:
    """Eq S2: PRESS of every prefix, the hat blocks grown by rank-one terms."""
    qb = q[blocks]  # (K, b, a + n)
    hat = np.einsum("kia,kja->kij", qb[:, :, :a], qb[:, :, :a])  # H_bb of the always-only fit
    error = (residual - q[:, :a] @ projected[:a])[blocks]  # (K, b): e_0
    eye = np.eye(blocks.shape[1])
    out = np.empty(n + 1)
    for j in range(n + 1):
        if j:
            column = qb[:, :, a + j - 1]
            hat += column[:, :, None] * column[:, None, :]
            error = error - column * projected[a + j - 1]
        out[j] = _left_out_sum(eye - hat, error)
    return out


def _left_out_sum(complement: np.ndarray, error: np.ndarray) -> float:
    """Σ_k |(I − H_kk)⁻¹ e_k|², or inf when a row block has leverage 1 (the prefix fits that row
    exactly whatever it measured, so leaving it out predicts nothing: PRESS is undefined)."""
    if np.min(np.linalg.eigvalsh(complement), initial=1.0) < LEVERAGE_FLOOR:
        return np.inf
    left_out = np.linalg.solve(complement, error[..., None])
    return float(np.sum(left_out**2))


def curvature_ratios(fits: NestedFits, jacobian: np.ndarray, jacobian_at: Callable[[np.ndarray], np.ndarray],
                     sizes: Sequence[int], stop_at: float = np.inf) -> dict[int, float]:
    """ρ_j of eq S3 for the prefixes ``sizes`` (j ≥ 1), in order, up to the first at or above ``stop_at``.

    Args:
        fits: the factorisation at x0.
        jacobian: the Jacobian's columns [A | ordered] at x0, unscaled (m, a + n).
        jacobian_at: the same columns at x0 + step, for a step (a + n,) over them [m, rad];
            called once per prefix.
        sizes: the prefixes j to evaluate.
        stop_at: evaluate no further once a ratio reaches it.
    """
    a, width = fits.n_always, fits.scale.size
    sizes = list(sizes)
    n = width - a
    # every prefix's weakest kinematic direction given the always-estimated columns from one
    # batched SVD: R's kinematic block R_KK (its Gram matrix is the kinematic information with
    # A profiled out), padded with a diagonal larger than any of its singular values
    padded = np.zeros((len(sizes), n, n))
    big = 2.0 * np.abs(fits.r).sum() + 1.0
    for i, j in enumerate(sizes):
        padded[i, :j, :j] = fits.r[a : a + j, a : a + j]
        padded[i, range(j, n), range(j, n)] = big
    _, singular, right = np.linalg.svd(padded)
    out = {}
    for i, j in enumerate(sizes):
        size = a + j
        kinematic = right[i, -1, :j]
        weakest = np.zeros(width)  # u_j: the kinematic direction, the always-estimated part following it
        weakest[a:size] = kinematic
        if a:
            weakest[:a] = -_solve_upper(fits.r[:a, :a], fits.r[:a, a:size] @ kinematic)
        weakest[:size] /= fits.scale[:size]  # in the parameters' own units
        h = CURVATURE_STEP / np.abs(weakest).max()
        change = (jacobian_at(h * weakest)[:, :size] - jacobian[:, :size]) / (h * fits.scale[:size])
        curvature = change.T @ fits.fit_residual(j)  # S u_j in scaled coordinates
        profiled = curvature[a:size]  # Pᵀ S u_j: the profile's curvature along w_j (A eliminated)
        if a:
            profiled = profiled - fits.r[:a, a:size].T @ _solve_upper_t(fits.r[:a, :a], curvature[:a])
        out[j] = float(np.linalg.norm(profiled) / singular[i, -1] ** 2)
        if out[j] >= stop_at:
            break
    return out


def _solve_upper_t(r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with rᵀ x = b for the upper-triangular R_AA (a least-squares x where it is singular)."""
    try:
        return scipy.linalg.solve_triangular(r, b, trans="T")
    except (np.linalg.LinAlgError, ValueError):
        return np.linalg.lstsq(r.T, b, rcond=None)[0]


def _solve_upper(r: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with r x = b for the upper-triangular R_AA (a least-squares x where it is singular)."""
    try:
        return scipy.linalg.solve_triangular(r, b)
    except (np.linalg.LinAlgError, ValueError):
        return np.linalg.lstsq(r, b, rcond=None)[0]


def refine(
    linear: np.ndarray, refit: Callable[[list[int]], dict[int, float | None]], safety: float = SAFETY
) -> tuple[int | None, dict[int, float | None]]:
    """Refit finalists until no other candidate can beat the best refitted one.

    Args:
        linear: linearised score of each candidate size 0 … n (inf: not a candidate).
        refit: refits the given sizes (ascending) and returns their nonlinear
            scores (None where the fit failed).
        safety: multiple of the largest linearisation error a candidate's linear
            score is lowered by before comparing it with the best refitted score.

    Returns:
        The best refitted size (None if every fit failed) and every refitted score.
    """
    linear = np.asarray(linear, dtype=float)
    candidates = [int(s) for s in np.flatnonzero(np.isfinite(linear))]
    exact: dict[int, float | None] = {}
    if not candidates:
        return None, exact
    first = int(np.argmin(linear))
    pending = {s for s in (first - 1, first, first + 1) if s in candidates}
    while pending:
        exact.update(refit(sorted(pending)))
        fitted = {s: v for s, v in exact.items() if v is not None}
        untried = [s for s in candidates if s not in exact]
        if not fitted:  # every fit so far failed: try the next best linear candidate
            pending = {min(untried, key=lambda s: linear[s])} if untried else set()
            continue
        best = min(fitted, key=fitted.__getitem__)
        error = max(abs(v - linear[s]) for s, v in fitted.items())
        pending = {s for s in untried if linear[s] - safety * error <= fitted[best]}
        pending |= {s for s in (best - 1, best + 1) if s in untried}
    fitted = {s: v for s, v in exact.items() if v is not None}
    return (min(fitted, key=fitted.__getitem__) if fitted else None), exact


def select_subset(problem: KindProblem[ObjectiveT], ordering: Ordering, base: np.ndarray, rows: MeasurementSet,
                  criterion: SelectionCriterion | Prior, counter: Counter | None = None
                  ) -> tuple[Selection, np.ndarray]:
    """Choose how many of the ordered identifiable parameters to keep.

    ``aic``: Akaike's information criterion m ln(RSS/m) + 2n (Akaike 1974), which
    estimates the expected prediction error on new measurements; ``bic``: the
    same with ln(m) per parameter (Schwarz 1978); ``press``: linearised
    leave-one-row-out cross-validation (Allen 1974); ``all``: every
    identifiable parameter; ``prior``: every identifiable one, the problem's
    objectives carrying the prior rows (:mod:`pincal.fit.prior`). Every prefix of the ordering is scored from one QR
    factorisation of the Jacobian at the start (:func:`nested_fits`);
    only finalists are refitted (:func:`refine`), and the
    kept subset is the best refitted one. ``counter`` ticks once per refit.
    """
    counter = Counter(None) if counter is None else counter
    rank = ordering.rank
    block = 3 * rows.n_points + (3 if rows.rotations is not None else 0)
    fitted: dict[int, tuple[np.ndarray, np.ndarray, ObjectiveT]] = {}  # size -> (kept, x, objective) of each refit
    notes: list[str] = []

    def refit(sizes: list[int]) -> dict[int, float | None]:
        counter.expect(len(sizes))
        out: dict[int, float | None] = {}
        for n_kept in sizes:
            kept = np.sort(ordering.order[:n_kept])
            objective = problem.objective(kept, base)
            smaller = [s for s in fitted if s < n_kept]
            x0 = _warm_start(objective, fitted[max(smaller)], kept) if smaller else objective.start_vector()
            try:
                solution = solve(objective, x0, what="selection", tolerance=SELECTION_TOLERANCE)
            except CalibrationError:
                out[n_kept] = None
                continue
            finally:
                counter.tick()
            fitted[n_kept] = (kept, solution.x, objective)
            m, rss = solution.residual.size, float(solution.residual @ solution.residual)
            if criterion == "press":
                jac = objective.jacobian(solution.x)
                out[n_kept] = press(_row_blocks(jac, rows, block), _row_blocks(solution.residual, rows, block), block)
            else:
                out[n_kept] = float(information_criterion(rss, m, solution.x.size,
                                                          np.log(m) if criterion == "bic" else 2.0))
        return out

    if criterion in ("all", "prior"):  # prior: the problem's objectives carry its rows (pincal.fit.prior)
        linear = np.full(rank + 1, np.inf)
        linear[rank] = 0.0
    else:  # every prefix from one factorisation at the start (eq S1, S2)
        everything = np.sort(ordering.order[:rank])
        objective = problem.objective(everything, base)
        x0 = objective.start_vector()
        jac, residual = objective.jacobian(x0), objective.residual(x0)
        kin = objective.blocks["kinematic"]
        column = {int(p): kin.start + i for i, p in enumerate(everything)}
        always = [c for c in range(jac.shape[1]) if not kin.start <= c < kin.stop]
        columns = always + [column[int(p)] for p in ordering.order[:rank]]
        blocks = None  # each row's residual entries: leave-one-row-out's, and only its (rows of any size elsewhere)
        if criterion == "press":
            blocks = _row_blocks(np.arange(residual.size), rows, block).reshape(rows.n_rows, block)
        fits = nested_fits(jac, residual, always, columns[len(always):], blocks)
        weighted = _weighted_by_the_data(problem, objective, fits)
        if weighted is not None:  # the rows reweighted: every score, and every refit, at the data's scales
            problem = weighted
            objective = problem.objective(everything, base)
            jac, residual = objective.jacobian(x0), objective.residual(x0)
            fits = nested_fits(jac, residual, always, columns[len(always):], blocks)
        linear = fits.scores(criterion)
        used = columns[: fits.scale.size]  # nested_fits drops prefixes that leave no residual degree of freedom
        undetermined = _first_undetermined(fits, objective, x0, jac[:, used], used, linear)
        if undetermined is not None:
            size, ratio = undetermined
            linear[size:] = np.inf
            notes.append(f"the weakest {rank - size + 1} of the {rank} identifiable combinations are not determined "
                         f"by these measurements (with {size} kept, the model's curvature outweighs the data's "
                         f"information along the weakest: ratio {ratio:.2g} >= 1); at most {size - 1} are kept")
    chosen, exact = refine(linear, refit)
    if chosen is None:
        raise CalibrationError(f"{rows.source}: no subset of the kinematic parameters could be fitted to its "
                               f"{rows.n_rows} row(s); add calibration rows or use a lower --level")
    sizes = [n for n in range(rank + 1) if exact.get(n) is not None or (n not in exact and np.isfinite(linear[n]))]
    selection = Selection(
        criterion=SELECTION_CRITERIA["prior" if isinstance(criterion, Prior) else criterion],
        sizes=tuple(sizes),
        # sizes holds only the exact scores that are not None
        scores=tuple(float(cast(float, exact[n])) if n in exact else float(linear[n]) for n in sizes),
        chosen=chosen,
        notes=tuple(notes),
        refitted=tuple(sorted(n for n in exact if exact[n] is not None)),
        solution=fitted[chosen][1],
    )
    return selection, np.sort(ordering.order[:chosen])


def _weighted_by_the_data(problem: KindProblem[ObjectiveT], objective: ObjectiveT, fits: NestedFits
                          ) -> KindProblem[ObjectiveT] | None:
    """``problem`` with each kind of row (positions, orientations) weighted by its noise scale as the
    widest prefix's linear fit leaves it (eq S1's e_j), or None with one kind of row.

    The criteria compare the prefixes' RSS over all rows, m ln(RSS/m) + c n: with one kind of row the
    scale only shifts every score alike, with two their relative weight decides which misfit counts.
    The start's scales (:data:`pincal.fit.sensor_problem.START_SIGMA_POS_M`, ``..._ROT_RAD``: 1 mm to
    1 mrad) weigh an orientation noise of 0.1° 300 times a position noise of 0.1 mm, so the criterion
    would drop parameters whose loss shows in the positions only: on a UR5's 12 planned 6D rows, AIC
    kept 12 of 18 identifiable parameters and the held-out error came out 0.69 mm instead of 0.12 mm.
    The widest fit's residual estimates each kind's noise with the least bias the candidates allow (as
    Mallows' Cp takes σ² from the fullest model); each estimate is kept above
    :data:`pincal.fit.prior.SCALE_FLOOR`, which rows reproduced to rounding would otherwise fall to.
    """
    scales = problem.scales()
    kinds = problem.scale_rows(objective)
    if len(kinds) < 2:
        return None
    residual = fits.fit_residual(int(np.flatnonzero(fits.feasible)[-1]))
    measured = iter([float(np.sqrt(np.mean(residual[rows] ** 2))) for rows in kinds])
    return problem.with_scales(tuple(None if scale is None else max(scale * next(measured), SCALE_FLOOR)
                                     for scale in scales))


def _first_undetermined(fits: NestedFits, objective: ObjectiveT, x0: np.ndarray, jac: np.ndarray, columns: list[int],
                        linear: np.ndarray) -> tuple[int, float] | None:
    """The smallest prefix with ρ_j >= 1 (eq S3) and its ρ, or None;
    one Jacobian evaluation per prefix, smallest first, up to that one."""

    def jacobian_at(step: np.ndarray) -> np.ndarray:
        x = x0.copy()
        x[columns] += step
        return objective.jacobian(x)[:, columns]

    sizes = [size for size in range(1, len(linear)) if np.isfinite(linear[size])]
    ratios = curvature_ratios(fits, jac, jacobian_at, sizes, stop_at=MAX_CURVATURE_RATIO)
    return next(((size, ratio) for size, ratio in ratios.items() if ratio >= MAX_CURVATURE_RATIO), None)


def _warm_start(objective: ObjectiveT, previous: tuple[np.ndarray, np.ndarray, ObjectiveT],
                kept: np.ndarray) -> np.ndarray:
    """Start a larger subset from the previous subset's solution."""
    prev_kept, prev_x, prev_objective = previous
    x0 = objective.start_vector()
    kin = objective.blocks["kinematic"]
    values = dict(zip(prev_kept.tolist(), prev_x[prev_objective.blocks["kinematic"]]))
    x0[kin] = [values.get(int(i), 0.0) for i in kept]
    x0[kin.stop :] = prev_x[prev_objective.blocks["kinematic"].stop :]
    return x0


def _row_blocks(values: np.ndarray, rows: MeasurementSet, block: int) -> np.ndarray:
    """Reorder residual rows (positions first, then orientations) into per-row blocks."""
    k, p = rows.n_rows, rows.n_points
    n_pos = 3 * k * p
    pos = values[:n_pos].reshape((k, 3 * p) + values.shape[1:])
    if rows.rotations is None:
        return pos.reshape((k * block,) + values.shape[1:])
    rot = values[n_pos:].reshape((k, 3) + values.shape[1:])
    return np.concatenate([pos, rot], axis=1).reshape((k * block,) + values.shape[1:])
