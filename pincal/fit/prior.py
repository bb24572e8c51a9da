"""``--select prior``: every identifiable parameter, each pulled towards nominal by a physical prior.

Instead of keeping a subset of the identifiable kinematic parameters
(:mod:`pincal.fit.selection`), the maximum a posteriori (MAP) fit keeps all of
them (``ordering.rank`` of :func:`pincal.fit.identifiability.order_parameters`;
the non-identifiable ones stay nominal and are reported as not determined) with
independent Gaussian priors θ_i ~ N(0, σ_i²) about the nominal model, one
scale per kind of parameter (:func:`parameter_kinds`): lengths (a translation
or a prismatic joint's zero), angles (a rotation of a placement) and joint zeros
(a revolute joint's turn about its own axis). By default the three scales are
estimated from the data (empirical Bayes, :mod:`pincal.fit.prior_scales`), from
:data:`DEFAULT_TRANSLATION_MM` (1 mm), :data:`DEFAULT_ROTATION_DEG` (0.5°) and
:data:`DEFAULT_JOINT_ZERO_DEG` (0.5°), the placement errors of machined and
assembled arms; ``--prior-scale MM,DEG[,DEG]`` fixes them. The registration and the target are
not penalised. With the residuals r(x) already divided by their noise scales
(σ_pos, σ_rot), the MAP estimate minimises

    ‖r(x)‖² + Σ_i (θ_i / σ_i)²                                       (P1)

(Bishop 2006, §3.3; Tikhonov regularisation), i.e. least squares on r(x)
stacked with the rows θ_i / σ_i (:class:`PriorResidual`); for a residual in
metres with noise σ (socket fixture) the rows are σ θ_i / σ_i.

**Noise scale.** Re-estimated after each fit and the fit repeated, up to
the fixed point (:data:`SCALE_TOLERANCE`). With W the data rows of the whitened Jacobian at the solution
and Λ = diag(1/σ_i²) (zero for the unpenalised columns), the hat matrix of the
regularised fit is H = W (WᵀW + Λ)⁻¹ Wᵀ and its trace the effective number of
parameters (Hastie, Tibshirani & Friedman 2009, §7.6, eq 7.34). Each kind of
residual k (positions, orientations) re-estimates its scale from its rows as

    σ_k² = ‖e_k‖² / (m_k − tr H_kk)                                    (P2)

(e_k in the kind's units, m_k its rows, H_kk its diagonal block): maximum
likelihood's mean square ‖e_k‖²/m_k would shrink σ as the parameters absorb
noise, which weakens the prior and lets them absorb more — on sparse data the
scale collapses.

**Fixed points.** Eq P2 can have more than one: from the nominal model's misfit it may settle
where the prior explains that misfit as noise. :func:`pincal.fit.pipeline.fit_kinematics` then
also iterates it from the unregularised fit's scale and keeps the fixed point with the larger
evidence (:func:`log_evidence`, eq P3), the new one only by a Bayes factor of
:data:`DECISIVE_LOG_EVIDENCE`.

**Posterior.** The covariance of the unknowns is (WᵀW/s² + Λ)⁻¹ with
s² = ‖W-row residual‖² / (m − tr H) from the final fit (eq P2 over all data
rows; with a prior far wider than the data's information it is the usual
s² (WᵀW)⁻¹). A parameter whose posterior standard deviation exceeds
:data:`PRIOR_DOMINATED` × σ_i takes more of its information from the prior than
from the data (posterior precision = prior precision + data precision, so
std / σ_i > 1/√2 ⇔ data precision < prior precision): it is reported as
determined mainly by the prior, its value (near nominal, in the corrected
model) is not presented as measured.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import numpy as np
import numpy.typing as npt

from pincal.errors import CalibrationError
from pincal.fit.identifiability import Selection
from pincal.fit.prior_defaults import (
    DEFAULT_JOINT_ZERO_DEG,
    DEFAULT_ROTATION_DEG,
    DEFAULT_TRANSLATION_MM,
    KINDS,
    SCALE_RANGE,
)
from pincal.fit.solver import Solution, gram

if TYPE_CHECKING:  # annotations only: the settings import this module for Prior, and need no residual loaded
    from pincal.model.dh.parameters import DHParameterSet
    from pincal.model.effects import Effect
    from pincal.model.parameter_sets import ChainParameters
    from pincal.residuals.base import Objective
    from pincal.residuals.camera import CameraResidual
    from pincal.residuals.fixture import FixtureResidual
    from pincal.residuals.sensor import SensorResidual
    from pincal.residuals.tree import TreeResidual

__all__ = [
    "DEFAULT_TRANSLATION_MM", "DEFAULT_ROTATION_DEG", "DEFAULT_JOINT_ZERO_DEG", "KINDS", "PRIOR_DOMINATED",
    "MAX_SCALE_ITERATIONS", "SCALE_TOLERANCE", "SCALE_FLOOR", "DATA_SCALE_GAP", "DECISIVE_LOG_EVIDENCE", "SCALE_RANGE",
    "PRIOR_STATUS", "Prior", "prior_of", "parameter_kinds", "kind_sigmas", "prior_sigmas", "PriorResidual", "settled",
    "hat_diagonal", "effective_scale", "posterior", "log_evidence", "standard_deviations", "data_rows", "dominated",
    "reestimated_scales", "ScaleChoice", "prior_scale", "map_outcome",
]

# DEFAULT_TRANSLATION_MM, DEFAULT_ROTATION_DEG, DEFAULT_JOINT_ZERO_DEG, KINDS and SCALE_RANGE:
# pincal.fit.prior_defaults (the parser reads them)
#: Posterior std / prior std above which a parameter is determined mainly by the prior (1/√2: the
#: data's precision is below the prior's).
PRIOR_DOMINATED = 1.0 / math.sqrt(2.0)
#: Most refits re-estimating the noise scale by eq P2 (each from the last; from the registration
#: fit's scale, noise-free data take ~6 to reach rounding level).
MAX_SCALE_ITERATIONS = 20
#: Relative change of every noise scale below which eq P2 has reached its fixed point: the prior's
#: relative weight then moves by 2e-3 (it scales as 1/σ²).
SCALE_TOLERANCE = 1e-3
#: Lowest noise scale eq P2 gives [m or rad]: 0.1 µm / 0.1 µrad, below any sensor of robot calibration
#: (an interferometer resolves ~0.5 µm). Rows a fit reproduces to rounding (as many unknowns as
#: coordinates, or noise-free rows) would otherwise weigh 1e16 against the prior's and leave the MAP
#: fit singular: 6 6D rows of a 6-axis arm failed so ("the data do not determine all 30 parameters").
SCALE_FLOOR = 1e-7
#: Eq P2 is also iterated from the unregularised fit's noise scales when they are below this fraction
#: of the fixed point's (:func:`pincal.fit.pipeline.fit_kinematics`): the prior, not the data, then
#: set the scale, and a fit the data dominate may be a second fixed point.
DATA_SCALE_GAP = 0.5
#: ln of the Bayes factor above which that second fixed point replaces the first (eq P3): 100,
#: "decisive" on Jeffreys' scale (Jeffreys 1961, Appendix B); nearer ones are the same answer.
DECISIVE_LOG_EVIDENCE = math.log(100.0)
PRIOR_STATUS = ("determined mainly by the prior (posterior std > 0.71 x prior std): kept near nominal, "
                "not measured")


class Prior(str):
    """The selection criterion ``"prior"`` (equal to that string) carrying its scales.

    ``Prior()`` estimates the three scales from the data (:mod:`pincal.fit.prior_scales`), starting
    from the defaults; ``Prior(mm, deg)`` fixes lengths at ``mm`` and angles and joint zeros at ``deg``,
    ``Prior(mm, deg, zero_deg)`` joint zeros at ``zero_deg``. ``estimated=True`` with scales: the
    estimate starts from them.

    Equality: a Prior equals the plain string ``"prior"`` (so ``selection == "prior"`` and
    ``SELECTION_CRITERIA[selection]`` work), and another Prior only with the same scales and the same
    ``estimated``; its hash is the string's. It pickles and copies with its scales.

    Attributes:
        translation_mm: prior std of lengths: translations and prismatic joint zeros [mm].
        rotation_deg: prior std of angles: the rotations of placements [deg].
        joint_zero_deg: prior std of revolute joint zeros [deg].
        estimated: whether a calibration estimates the scales from its data (starting from these).

    Raises:
        CalibrationError: a scale that is not a number within :data:`SCALE_RANGE`.
    """

    translation_mm: float
    rotation_deg: float
    joint_zero_deg: float
    estimated: bool

    def __new__(cls, translation_mm: float | None = None, rotation_deg: float | None = None,
                joint_zero_deg: float | None = None, estimated: bool | None = None) -> Prior:
        if estimated is None:
            estimated = translation_mm is None and rotation_deg is None and joint_zero_deg is None
        translation_mm = DEFAULT_TRANSLATION_MM if translation_mm is None else translation_mm
        rotation_deg = DEFAULT_ROTATION_DEG if rotation_deg is None else rotation_deg
        if joint_zero_deg is None:  # two scales: a joint zero is a rotation, as before there were three
            joint_zero_deg = DEFAULT_JOINT_ZERO_DEG if estimated else rotation_deg
        low, high = SCALE_RANGE
        for name, unit, value in (("translation", "mm", translation_mm), ("rotation", "deg", rotation_deg),
                                  ("joint zero", "deg", joint_zero_deg)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise CalibrationError(f"prior scale: the {name} scale must be a positive number, got {value!r}")
            if not low <= value <= high:
                raise CalibrationError(f"prior scale: the {name} scale must be from {low:g} to {high:g} {unit}, "
                                       f"got {value!r}")
        out = super().__new__(cls, "prior")
        out.translation_mm, out.rotation_deg = float(translation_mm), float(rotation_deg)
        out.joint_zero_deg, out.estimated = float(joint_zero_deg), bool(estimated)
        return out

    def __reduce__(self) -> tuple[type[Prior], tuple[float, float, float, bool]]:
        return type(self), (self.translation_mm, self.rotation_deg, self.joint_zero_deg, self.estimated)

    def _key(self) -> tuple[float, float, float, bool]:
        return self.translation_mm, self.rotation_deg, self.joint_zero_deg, self.estimated

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Prior):
            return self._key() == other._key()
        return str.__eq__(self, other)

    def __ne__(self, other: object) -> bool:
        return not self == other

    __hash__ = str.__hash__

    @property
    def scales(self) -> tuple[float, float, float]:
        """The scales of :data:`KINDS`: lengths [mm], angles [deg], joint zeros [deg]."""
        return self.translation_mm, self.rotation_deg, self.joint_zero_deg

    @property
    def si(self) -> np.ndarray:
        """The scales of :data:`KINDS` in SI units: lengths [m], angles [rad], joint zeros [rad], (3,)."""
        return np.array([self.translation_mm * 1e-3, math.radians(self.rotation_deg),
                         math.radians(self.joint_zero_deg)])

    def as_dict(self) -> dict[str, float]:
        """PLAN.json ``settings.prior_scale``, and REPORT.json ``identifiability.selection.prior_scale``'s
        first three keys: ``translation_mm``, ``rotation_deg``, ``joint_zero_deg``."""
        return {"translation_mm": self.translation_mm, "rotation_deg": self.rotation_deg,
                "joint_zero_deg": self.joint_zero_deg}

    def describe(self) -> str:
        """The scales in words: ``lengths 1 mm, angles 0.5°, joint zeros 0.5°``."""
        return (f"lengths {self.translation_mm:.3g} mm, angles {self.rotation_deg:.3g}°, "
                f"joint zeros {self.joint_zero_deg:.3g}°")


def prior_of(selection: str) -> Prior | None:
    """The prior of a selection criterion: its own for a :class:`Prior`, the defaults for the
    string ``"prior"``, None for any other criterion."""
    if selection != "prior":
        return None
    return selection if isinstance(selection, Prior) else Prior()


def parameter_kinds(params: ChainParameters | DHParameterSet) -> np.ndarray:
    """The kind of every parameter of ``params`` (indices into :data:`KINDS`), (n,): 0 a length (a
    translation, a prismatic joint's zero; unit m), 2 a joint zero (a rotation about the axis of the
    revolute or continuous joint it belongs to — ``PlacementErrors``' r-axis along it, ``JointOffsets``,
    DH's theta), 1 any other angle (the tip's rotations among them: no joint turns there)."""
    chain = getattr(params, "chain", None)
    joints = {} if chain is None else {j.name: j for j in chain.joints}
    slots = getattr(params, "slots", ())
    out = np.ones(len(params.info), dtype=int)
    for i, info in enumerate(params.info):
        if info.unit == "m":
            out[i] = 0
            continue
        joint = joints.get(info.joint)
        if joint is None or joint.kind == "prismatic" or i >= len(slots):
            continue
        slot = slots[i]
        if slot.kind == "revolute" and abs(float(np.dot(slot.axis, joint.axis))) > 1.0 - 1e-9:
            out[i] = 2
    return out


def kind_sigmas(params: ChainParameters | DHParameterSet, scales_si: npt.ArrayLike) -> np.ndarray:
    """σ_i of every parameter of ``params`` from the scales of :data:`KINDS` in SI units (m, rad, rad), (n,)."""
    return np.asarray(scales_si, dtype=float)[parameter_kinds(params)]


def prior_sigmas(params: ChainParameters | DHParameterSet, prior: Prior) -> np.ndarray:
    """σ_i of every parameter of ``params`` in its own unit (m or rad), (n,): the prior's scales
    (an estimated prior's start)."""
    return kind_sigmas(params, prior.si)


class PriorResidual:
    """An objective with the prior rows of eq P1 appended: [r(x); noise · x_kin / σ].

    Args:
        objective: the data objective (its ``blocks["kinematic"]`` are θ of the free parameters).
        sigma: σ_i of the free kinematic parameters, in their order (n_kin,).
        noise: the data residual's noise scale in its own units (1 for whitened residuals).

    Every other attribute is the data objective's.
    """

    def __init__(self, objective: SensorResidual | FixtureResidual | TreeResidual | CameraResidual,
                 sigma: np.ndarray, noise: float = 1.0) -> None:
        self.objective = objective
        self.noise = float(noise)
        self.weight = noise / np.asarray(sigma, dtype=float)
        self.n_prior = self.weight.size

    def __getattr__(self, name: str) -> Any:
        return getattr(self.objective, name)

    @property
    def blocks(self) -> dict[str, slice]:
        """The data objective's blocks of unknowns (the prior adds rows, no unknowns)."""
        return self.objective.blocks

    def start_vector(self) -> np.ndarray:
        return self.objective.start_vector()

    def residual(self, x: npt.ArrayLike) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        return np.concatenate([self.objective.residual(x), self.weight * x[self.objective.blocks["kinematic"]]])

    def jacobian(self, x: npt.ArrayLike) -> np.ndarray:
        data = self.objective.jacobian(x)
        rows = np.zeros((self.weight.size, data.shape[1]))
        kin = self.objective.blocks["kinematic"]
        rows[:, kin] = np.diag(self.weight)
        return np.vstack([data, rows])

    def effect_columns(self, x: npt.ArrayLike, effects: Sequence[Effect]) -> list[np.ndarray]:
        """The data objective's effect columns with zero prior rows appended: effects
        (``pincal diagnose``) have no prior, (m + n_prior, n_values) each. Effects act on sensor rows."""
        return [np.vstack([block, np.zeros((self.n_prior, block.shape[1]))])
                for block in cast("SensorResidual", self.objective).effect_columns(x, effects)]


def settled(before: Sequence[float | None], after: Sequence[float | None]) -> bool:
    """Whether every noise scale (None where absent) changed by less than :data:`SCALE_TOLERANCE` relative."""
    # a scale is None before wherever it is after (a kind not measured)
    return all(a is None or abs(a - cast(float, b)) <= SCALE_TOLERANCE * cast(float, b) for b, a in zip(before, after))


def hat_diagonal(jacobian: np.ndarray, n_prior: int) -> np.ndarray:
    """diag H of eq P2 for the data rows of a MAP Jacobian whose last ``n_prior`` rows are the prior's (m,)."""
    data = jacobian[: jacobian.shape[0] - n_prior]
    inverse = np.linalg.pinv(gram(jacobian))  # (WᵀW + Λ)⁻¹: the prior rows' Gram is Λ
    return np.einsum("ij,jk,ik->i", data, inverse, data)


def effective_scale(residual: np.ndarray, hat: np.ndarray, floor: float = 1.0) -> float:
    """σ of eq P2: sqrt(‖e‖² / (m − tr H)) over the rows given (e in its own units); the
    denominator is at least ``floor`` (a fit that reproduces every row)."""
    return float(np.sqrt(residual @ residual / max(residual.size - float(hat.sum()), floor)))


def posterior(jacobian: np.ndarray, residual: np.ndarray, n_prior: int, noise: float = 1.0) -> tuple[np.ndarray, float]:
    """The posterior covariance (JᵀJ/s² + Λ)⁻¹ of the unknowns and s² (module docstring), from
    the MAP fit's Jacobian and residual (prior rows last, weighted by ``noise`` as in
    :class:`PriorResidual`; data rows whitened when ``noise`` is 1, else in its units)."""
    m = jacobian.shape[0] - n_prior
    data, prior = jacobian[:m], jacobian[m:]
    s2 = effective_scale(residual[:m], hat_diagonal(jacobian, n_prior)) ** 2
    return np.linalg.pinv(gram(data) / s2 + gram(prior) / noise**2), s2


def log_evidence(jacobian: np.ndarray, residual: np.ndarray, log_variances: float) -> float:
    """ln p(data | noise scales) of a MAP fit, linearised at its solution, up to a constant that is the
    same for every scale (the evidence of Bishop 2006, eq 3.86; MacKay 1992):

        −½ (Σ_rows ln σ_row² + ‖ẽ‖² + ln det(J̃ᵀJ̃))                        (P3)

    with ẽ and J̃ the residual and Jacobian with data rows divided by their noise scales and the
    prior rows θ_i/σ_i last (so ‖ẽ‖² = ‖r/σ‖² + θᵀΛθ and J̃ᵀJ̃ = WᵀW + Λ), and ``log_variances`` =
    Σ_rows ln σ_row² [ln m², ln rad²]. Unpenalised unknowns (registration, target) have a flat prior:
    its width is the same constant for every scale. Eq P2's fixed points are stationary points of
    P3 in the scales; where there are several, the larger P3 is the one the data support."""
    _, logdet = np.linalg.slogdet(gram(jacobian))
    return float(-0.5 * (log_variances + residual @ residual + logdet))


def standard_deviations(objective: Objective | PriorResidual, solution: Solution) -> np.ndarray:
    """Standard deviations of a fit's unknowns: the posterior's (:func:`posterior`) for a MAP fit
    (:class:`PriorResidual`), else the solver's (n,)."""
    if not isinstance(objective, PriorResidual):
        return solution.std
    covariance, _ = posterior(solution.jacobian, solution.residual, objective.n_prior, objective.noise)
    return np.sqrt(np.clip(np.diag(covariance), 0.0, None))


def data_rows(jacobian: np.ndarray, objective: Objective | TreeResidual | PriorResidual) -> np.ndarray:
    """The data rows of a fit's Jacobian: without a :class:`PriorResidual`'s prior rows."""
    return jacobian[: jacobian.shape[0] - objective.n_prior] if isinstance(objective, PriorResidual) else jacobian


def dominated(std: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Which parameters are determined mainly by the prior: posterior std > :data:`PRIOR_DOMINATED` σ_i."""
    return np.asarray(std) > PRIOR_DOMINATED * np.asarray(sigma)


def reestimated_scales(solution: Solution, n_prior: int, n_pos: int, sigma_pos: float,
                       sigma_rot: float | None) -> tuple[float, float | None]:
    """σ_pos [m] and σ_rot [rad] by eq P2 from a MAP fit whose data rows were divided by
    ``sigma_pos`` (the first ``n_pos``) and ``sigma_rot`` (the rest), prior rows last."""
    hat = hat_diagonal(solution.jacobian, n_prior)
    data = solution.residual[: hat.size]
    out_pos = max(effective_scale(data[:n_pos] * sigma_pos, hat[:n_pos]), SCALE_FLOOR)
    if sigma_rot is None:
        return out_pos, None
    return out_pos, max(effective_scale(data[n_pos:] * sigma_rot, hat[n_pos:]), SCALE_FLOOR)


@dataclass(frozen=True)
class ScaleChoice:
    """The prior scales a MAP fit was made with, and how they were chosen (:mod:`pincal.fit.prior_scales`).

    Attributes:
        used: the scales of the fit (``used.estimated``: the data's estimate, else the given or default ones).
        estimate: the empirical-Bayes estimate, also where it was not adopted (None: the scales were given).
        log_bayes_factor: ln of the estimate's evidence over the default scales' (eq P4), None without one.
        cv_ratio: the estimate's cross-validated mean squared error over the defaults' (None without one).
        cv_standard_error: its standard error (the estimate is adopted below 1 − it).
        reason: in words, why ``used``.
    """

    used: Prior
    estimate: Prior | None = None
    log_bayes_factor: float | None = None
    cv_ratio: float | None = None
    cv_standard_error: float | None = None
    reason: str = "given"


def _finite(value: float | None) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def prior_scale(choice: ScaleChoice) -> dict[str, Any]:
    """REPORT.json ``identifiability.selection.prior_scale``: the scales a fit was made with
    (``translation_mm``, ``rotation_deg``, ``joint_zero_deg``), whether they are the data's estimate
    (``estimated``), why (``reason``), and with an estimate its scales, Bayes factor and
    cross-validation against the default scales."""
    used = choice.used
    out: dict[str, Any] = {**used.as_dict(), "estimated": used.estimated, "reason": choice.reason}
    if choice.estimate is not None:
        out["estimate"] = choice.estimate.as_dict()
        out["log_bayes_factor"] = _finite(choice.log_bayes_factor)
        out["cv_ratio"] = _finite(choice.cv_ratio)
        out["cv_standard_error"] = _finite(choice.cv_standard_error)
    return out


def map_outcome(jacobian: np.ndarray, residual: np.ndarray, objective: PriorResidual, kept: np.ndarray,
                sigma: np.ndarray, selection: Selection | None, params: ChainParameters | DHParameterSet,
                choice: ScaleChoice) -> tuple[np.ndarray, np.ndarray, Selection]:
    """What a MAP fit reports: the posterior covariance of its unknowns, the kept parameters
    (indices of ``params``) determined mainly by the prior, and the selection with the
    effective number of kinematic parameters as its value and a note naming those parameters.
    ``choice``: the scales the fit was made with and how they were chosen.

    The effective number is n_kin − Σ_i [(WᵀW + Λ)⁻¹]_ii Λ_ii (the kinematic part of tr H,
    eq P2: tr H = n − tr((WᵀW + Λ)⁻¹Λ), and only penalised columns enter the second term).
    """
    covariance, _ = posterior(jacobian, residual, objective.n_prior, objective.noise)
    kin = objective.blocks["kinematic"]
    std = np.sqrt(np.diag(covariance))[kin]
    weak = np.asarray(kept)[dominated(std, sigma[kept])]
    inverse = np.diag(np.linalg.pinv(gram(jacobian)))[kin]
    effective = float(kept.size - np.sum(inverse * objective.weight**2))
    notes = list(selection.notes) if selection is not None else []
    if weak.size:
        names = ", ".join(params.info[i].name for i in weak)
        notes.append(f"{weak.size} of the {kept.size} identifiable parameters are determined mainly by the prior "
                     f"(posterior std > {PRIOR_DOMINATED:.2f} x prior std of {choice.used.describe()}): {names}; "
                     "the corrected model holds them near nominal, "
                     "and their values are not reported as measured")
    out = Selection(criterion=selection.criterion if selection is not None else "prior", sizes=(int(kept.size),),
                    scores=(effective,), chosen=int(kept.size), notes=tuple(notes), refitted=(int(kept.size),),
                    solution=None if selection is None else selection.solution, prior_scale=prior_scale(choice))
    return covariance, weak, out
