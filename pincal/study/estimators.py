"""The estimators a simulation study compares: the paper's Methods 1–3 and maximum likelihood.

Methods 1, 2 and 3 minimise Err_pos, Err_rot and Err_full (eq 16–18) of
Franaszek & Marvel (2022); Method 3 is run with w = 1 and w =
:data:`SECOND_WEIGHT`. The noise-weighted maximum-likelihood estimator
(:func:`pincal.paper.ml_estimator.calibrate_ml`) is this package's addition.

:func:`ml_without_cpa_orientations` is an ablation of the ML estimator, not one
of the study's estimators: the simulator gives the CPA rows orientations too,
while the paper's CPA measures positions only (Section 3), so the ML
estimator sees more data than Method 2 does. The ablation withholds those
orientations and measures how much of the ML estimator's gain they account for.
"""

from __future__ import annotations

from dataclasses import dataclass

from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import KUKA_LWR4_DH, DHTable
from pincal.model.sensor import Registration
from pincal.paper.methods import PaperCalibration, calibrate_paper
from pincal.paper.ml_estimator import MLSettings, calibrate_ml
from pincal.paper.noise_limit import PredictedErrors, predicted_errors
from pincal.simulation.paper import SimulatedExperiment

__all__ = [
    "SECOND_WEIGHT", "Estimator", "METHOD_1", "METHOD_2", "METHOD_3", "ML_ESTIMATOR", "ESTIMATORS",
    "RESTART_ESTIMATORS", "ml_without_cpa_orientations",
]

#: Method 3's second weight w [mm²/deg²]: orientations dominate Err_full (eq 18).
SECOND_WEIGHT = 100.0


@dataclass(frozen=True)
class Estimator:
    """One estimator of the study.

    Attributes:
        method: 1, 2 or 3 (the paper's methods) or ``"ml"`` (noise-weighted
            maximum likelihood, :func:`pincal.paper.ml_estimator.calibrate_ml`).
        weight: w of Method 3 [mm²/deg²] (eq 18); None for the others.
    """

    method: int | str
    weight: float | None = None

    @classmethod
    def of(cls, method: str, weight: float | None) -> Estimator:
        """The estimator of a table row's ``method`` and ``weight`` columns."""
        return cls(method if method == "ml" else int(method), weight)

    @property
    def label(self) -> str:
        """Human-readable name, e.g. ``Method 3 (w=100)``."""
        if self.method == "ml":
            return "ML estimator"
        return f"Method {self.method}" + ("" if self.weight is None else f" (w={self.weight:g})")

    @property
    def registrations(self) -> tuple[int, ...]:
        """Registrations it provides: Method 1 has positions only, hence Registration 1."""
        return (1,) if self.method == 1 else (1, 2)

    @property
    def orientation_registration(self) -> int:
        """The registration for orientations (the noise limit's): 2, or 1 for Method 1."""
        return self.registrations[-1]

    @property
    def fit_weight(self) -> float:
        """The w the fit is given [mm²/deg²] (eq 18): :attr:`weight`, or 1 when it is None."""
        return 1.0 if self.weight is None else self.weight

    def calibrate(
        self,
        chain: KinematicChain,
        data: MeasurementSet,
        sigma: float,
        start: DHTable | None = None,
        twists: tuple | None = None,
        method2: PaperCalibration | None = None,
        models: dict | None = None,
    ) -> PaperCalibration:
        """Calibrate from Table 1 on ``data``'s ``cpa`` and ``calibration`` rows.

        Args:
            chain: the KUKA chain with the TCP as its tool.
            data: the rows.
            sigma: the noise level, sigma_p [mm] = sigma_a [deg]; the ML estimator
                weighs with it (on noise-free data any equal weights give the truth).
            start: starting eps, r, d of a paper method (default Table 1).
            twists: the CPA of ``data`` from Table 1
                (:func:`pincal.paper.methods.estimate_twists`), shared by the
                estimators of one trial; computed if None.
            method2: Method 2's result on ``data`` (from :data:`METHOD_2`), the ML
                estimator's start; computed if None. Either way the numbers are the same.
            models: Pinocchio sensitivity models of ``chain`` by their slots, shared
                by the fits of one worker (:func:`pincal.study.tasks.worker_models`).
        """
        if self.method == "ml":
            scale = sigma if sigma > 0 else 1.0
            return calibrate_ml(chain, data, sigma_pos_mm=scale, sigma_rot_deg=scale, nominal=KUKA_LWR4_DH,
                                start=method2, models=models)
        return calibrate_paper(chain, data, int(self.method), self.fit_weight, nominal=KUKA_LWR4_DH, start=start,
                               twists=twists, models=models)

    def noise_limit(self, chain: KinematicChain, experiment: SimulatedExperiment, sigma: float) -> PredictedErrors:
        """Linearised (Cramér–Rao) prediction of the truth-referenced test errors at ``sigma``."""
        return predicted_errors(chain, experiment, self.method, sigma, sigma, weight=self.fit_weight)


METHOD_1, METHOD_2, METHOD_3 = Estimator(1), Estimator(2), Estimator(3, 1.0)
ML_ESTIMATOR = Estimator("ml")
#: The estimators of the study, in report order.
ESTIMATORS = (METHOD_1, METHOD_2, METHOD_3, Estimator(3, SECOND_WEIGHT), ML_ESTIMATOR)
#: The paper's three error functions Err_pos, Err_rot, Err_full: the restart test's subjects.
RESTART_ESTIMATORS = (METHOD_1, METHOD_2, METHOD_3)


def ml_without_cpa_orientations(
    chain: KinematicChain,
    data: MeasurementSet,
    sigma_pos_mm: float,
    sigma_rot_deg: float,
    nominal: DHTable = KUKA_LWR4_DH,
    withhold: tuple[str, ...] = ("cpa",),
    start: PaperCalibration | None = None,
    models: dict | None = None,
) -> tuple[DHTable, Registration]:
    """The ML estimator with the orientations of the ``withhold`` rows left out (an ablation).

    :func:`pincal.paper.ml_estimator.calibrate_ml` with known noise and
    ``MLSettings(withhold_orientations=withhold)``: with the default, the CPA rows are
    positions only, as in the paper. ``withhold=()`` is the ML estimator itself.

    Args:
        chain: the chain with the TCP as its tool; left as it was (the calibrated table is
            returned; the fit starts from ``nominal``, not from the chain's placements).
        data: the rows (full poses).
        sigma_pos_mm, sigma_rot_deg: σ_p [mm] and σ_a [deg], both positive.
        nominal: the default table; eps_1 and d_1 keep its values.
        withhold: roles whose orientations are left out.
        start: Method 2's result on ``data`` from ``nominal`` if the caller has
            it (the fit's start; computed if None).
        models: Pinocchio sensitivity models of ``chain`` by their slots, shared by many fits.

    Returns:
        The calibrated table and the registration sensor_T_base (one for
        positions and orientations).
    """
    result = calibrate_ml(
        chain, data, sigma_pos_mm, sigma_rot_deg, nominal, settings=MLSettings(withhold_orientations=withhold),
        start=start, models=models
    )
    return result.table, result.registration_position
