"""The tasks of a simulation study: what a worker runs for one piece of the protocol.

A task is a small picklable object whose ``run()`` returns a list of row
dicts; its ``key`` orders the rows of a study whatever executor ran them
(:mod:`pincal.study.executors`). Four kinds:

* :class:`TrialTask`: one (deviation set, level, repeat), every estimator (and,
  on the trials of :func:`ablation_trial`, the ML estimator with the CPA rows'
  orientations withheld, :func:`pincal.study.estimators.ml_without_cpa_orientations`);
* :class:`RestartTask`: a chunk of the restart test's random starts (Section 7);
* :class:`Figure2Task`: Figure 2's per-pose errors;
* :class:`LimitTask`: the linearised noise limit of one estimator on one pose set.

Each worker process loads the KUKA chain once (:func:`worker_chain`) and keeps
the Pinocchio sensitivity models its fits build (:func:`worker_models`).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any, cast

import numpy as np

from pincal.errors import CalibrationError
from pincal.fit.metrics import ErrorSummary, pose_errors
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import KinematicChain
from pincal.model.dh.table import DEVIATION_SETS, KUKA_LWR4_DH, DHTable
from pincal.paper.methods import PaperCalibration, estimate_twists
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.simulation.paper import SimulatedExperiment, simulate_experiment
from pincal.simulation.sensor import perfect_measurements
from pincal.study.estimators import (
    METHOD_1,
    METHOD_2,
    ML_ESTIMATOR,
    RESTART_ESTIMATORS,
    ml_without_cpa_orientations,
)
from pincal.study.protocol import (
    FIGURE2_REPEAT,
    FIGURE2_SIGMA,
    RESTART_SPREAD_DEG,
    RESTART_SPREAD_MM,
    SAME_SOLUTION_DEG,
    SAME_SOLUTION_MM,
    StudyConfig,
    deviation_index,
    restart_start_seed,
)

__all__ = [
    "worker_chain", "worker_models", "ABLATION_REPEATS", "ABLATION_SUFFIX", "ablation_levels", "ablation_trial",
    "noise_free_test_set", "parameter_deviations", "random_start", "TrialTask", "RestartTask", "Figure2Task",
    "LimitTask",
]

# First entry of a task's sort key: its kind.
_TRIALS, _RESTARTS, _FIGURE2_ERRORS, _LIMITS = 0, 1, 2, 3

_LOCAL = threading.local()


def worker_chain() -> KinematicChain:
    """The packaged KUKA LWR 4+ chain, loaded once per worker process (and thread)."""
    chain = getattr(_LOCAL, "chain", None)
    if chain is None:
        chain = _LOCAL.chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    return chain


def worker_models() -> dict:
    """The sensitivity models of :func:`worker_chain` by their slots, shared by every fit of
    this worker process (and thread): each estimator builds its one or two once, not per fit
    (:class:`pincal.residuals.base.KinematicsCache`; a model keeps no state between evaluations)."""
    models = getattr(_LOCAL, "models", None)
    if models is None:
        models = _LOCAL.models = {}
    return models


#: The CPA-orientation ablation runs on the first ABLATION_REPEATS repeats of :func:`ablation_levels`.
ABLATION_REPEATS = 5
#: Suffix of the ablation's eq 24 columns on the ML estimator's rows of those trials (in
#: study.json, not in study.csv): e.g. ``rot_truth_mean_deg_cpa_positions_only``.
ABLATION_SUFFIX = "_cpa_positions_only"


def ablation_levels(config: StudyConfig) -> tuple[int, ...]:
    """Levels of the CPA-orientation ablation: the middle and the highest non-zero level."""
    nonzero = [level for level, sigma in enumerate(config.sigmas) if sigma > 0]
    return tuple(sorted({nonzero[len(nonzero) // 2], nonzero[-1]})) if nonzero else ()


def ablation_trial(config: StudyConfig, level: int, repeat: int) -> bool:
    """Whether the trial (level, repeat) also runs the CPA-orientation ablation (needs the ML estimator)."""
    return ML_ESTIMATOR in config.estimators and level in ablation_levels(config) and repeat < ABLATION_REPEATS


@contextmanager
def _simulated(
    config: StudyConfig, deviations: str, sigma: float, seed: int
) -> Iterator[tuple[KinematicChain, SimulatedExperiment]]:
    """A simulated experiment and the worker's chain with its true TCP as the tool inside the block."""
    chain = worker_chain()
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, DEVIATION_SETS[deviations], config.settings(sigma, seed))
    with chain.placed(tool=experiment.tool):
        yield chain, experiment


def _twists(chain: KinematicChain, experiment: SimulatedExperiment) -> tuple:
    """The CPA link twists of the experiment's ``cpa`` rows from Table 1 (Section 3, eq 9): the
    same for every estimator and start on these rows, so a task computes them once."""
    return estimate_twists(chain, KUKA_LWR4_DH, experiment.calibration.with_role("cpa"))


def noise_free_test_set(chain: KinematicChain, experiment: SimulatedExperiment) -> MeasurementSet:
    """The J test poses as a perfect sensor sees them: eq 20–21 without N_k and zeta_k.

    The truth is evaluated inside ``chain.placed``: the chain is left as it was.
    """
    with chain.placed(experiment.truth.joint_origins(), tool=experiment.tool):
        test_set = perfect_measurements(chain, experiment.validation, experiment.registration)
    return replace(test_set, extra={}, source="<noise-free truth>")


def parameter_deviations(table: DHTable, truth: DHTable) -> dict[str, float]:
    """Largest |fitted − true| of each DH row over the identifiable parameters (Section 8).

    eps_1 and d_1 are absorbed by the registration and alpha_N is not seen by
    CPA (Section 6); they are left out.

    Returns:
        ``max_dalpha_deg``, ``max_deps_deg`` [deg], ``max_dr_mm``, ``max_dd_mm`` [mm].
    """
    delta = np.abs(table.to_vector() - truth.to_vector()).reshape(4, -1)
    return {
        "max_dalpha_deg": float(np.degrees(delta[0, :-1].max())),
        "max_deps_deg": float(np.degrees(delta[1, 1:].max())),
        "max_dr_mm": float(delta[2].max() * 1000.0),
        "max_dd_mm": float(delta[3, 1:].max() * 1000.0),
    }


def random_start(rng: np.random.Generator, nominal: DHTable = KUKA_LWR4_DH) -> DHTable:
    """A starting table: eps ± RESTART_SPREAD_DEG, r and d ± RESTART_SPREAD_MM around ``nominal`` (uniform)."""
    n = nominal.n_joints
    return DHTable(
        alpha=nominal.alpha,
        epsilon=nominal.epsilon + np.radians(rng.uniform(-RESTART_SPREAD_DEG, RESTART_SPREAD_DEG, n)),
        r=nominal.r + rng.uniform(-RESTART_SPREAD_MM, RESTART_SPREAD_MM, n) / 1000.0,
        d=nominal.d + rng.uniform(-RESTART_SPREAD_MM, RESTART_SPREAD_MM, n) / 1000.0,
    )


def _fitted_difference(a: DHTable, b: DHTable) -> tuple[float, float]:
    """Largest difference of the fitted eps_2..N [deg] and of r_1..N, d_2..N [mm]."""
    delta = np.abs(a.to_vector() - b.to_vector()).reshape(4, -1)
    return float(np.degrees(delta[1, 1:].max())), float(max(delta[2].max(), delta[3, 1:].max()) * 1000.0)


@dataclass(frozen=True)
class TrialTask:
    """One (deviation set, level, repeat): simulate, run every estimator, return its rows."""

    config: StudyConfig
    deviations: str
    level: int
    sigma: float
    repeat: int
    seed: int

    @property
    def key(self) -> tuple:
        return (_TRIALS, deviation_index(self.deviations), self.level, self.repeat)

    def run(self) -> list[dict[str, Any]]:
        with _simulated(self.config, self.deviations, self.sigma, self.seed) as (chain, experiment):
            return self._rows(chain, experiment)

    def _rows(self, chain: KinematicChain, experiment: SimulatedExperiment) -> list[dict[str, Any]]:
        test_sets = {"": experiment.validation, "_truth": noise_free_test_set(chain, experiment)}
        rows: list[dict[str, Any]] = []
        results: dict[Any, PaperCalibration] = {}
        twists = _twists(chain, experiment)  # CPA once; ML starts from this trial's Method 2
        for estimator in self.config.estimators:
            started = time.perf_counter()
            result = results[estimator] = estimator.calibrate(
                chain, experiment.calibration, self.sigma, twists=twists, method2=results.get(METHOD_2),
                models=worker_models())
            fit_ms = (time.perf_counter() - started) * 1000.0
            deviations = parameter_deviations(result.table, experiment.truth)
            registrations = {1: result.registration_position, 2: result.registration_orientation}
            with chain.placed(result.table.joint_origins()):  # the fitted model
                tool = {suffix: chain.tool_poses(data.q) for suffix, data in test_sets.items()}  # both registrations'
                for index in estimator.registrations:
                    row = {
                        "deviations": self.deviations, "level": self.level, "sigma_pos_mm": self.sigma,
                        "sigma_rot_deg": self.sigma, "repeat": self.repeat, "seed": self.seed,
                        "method": str(estimator.method), "weight": estimator.weight, "registration": index,
                    }
                    for suffix, data in test_sets.items():  # eq 24 through this registration
                        errors = pose_errors(chain, data, registrations[index], registrations[index],
                                             tool_poses=tool[suffix])
                        row[f"pos{suffix}_mean_mm"] = errors.position.mean
                        # the study's rows have orientations
                        row[f"rot{suffix}_mean_deg"] = cast(ErrorSummary, errors.rotation).mean
                    rows.append({**row, "fit_ms": fit_ms, **deviations})
        if ablation_trial(self.config, self.level, self.repeat):
            # same data, the CPA rows as positions only (the paper's CPA); on the ML rows, kept out of study.csv
            table, registration = ml_without_cpa_orientations(
                chain, experiment.calibration, self.sigma, self.sigma, start=results.get(METHOD_2),
                models=worker_models())
            ablation = {}
            with chain.placed(table.joint_origins()):
                for suffix, data in test_sets.items():
                    errors = pose_errors(chain, data, registration, registration)
                    ablation[f"pos{suffix}_mean_mm{ABLATION_SUFFIX}"] = errors.position.mean
                    # the study's rows have orientations
                    ablation[f"rot{suffix}_mean_deg{ABLATION_SUFFIX}"] = cast(ErrorSummary, errors.rotation).mean
            for row in rows:
                if row["method"] == str(ML_ESTIMATOR.method):
                    row.update(ablation)
        return rows


@dataclass(frozen=True)
class RestartTask:
    """Restarts ``first .. first + count − 1`` of one restart case and one estimator (Section 7)."""

    config: StudyConfig
    case: int
    deviations: str
    level: int
    sigma: float
    repeat: int
    seed: int
    estimator_index: int
    first: int
    count: int

    @property
    def key(self) -> tuple:
        return (_RESTARTS, self.case, self.estimator_index, self.first)

    def run(self) -> list[dict[str, Any]]:
        with _simulated(self.config, self.deviations, self.sigma, self.seed) as (chain, experiment):
            return self._rows(chain, experiment)

    def _rows(self, chain: KinematicChain, experiment: SimulatedExperiment) -> list[dict[str, Any]]:
        estimator = RESTART_ESTIMATORS[self.estimator_index]
        twists = _twists(chain, experiment)  # the same CPA for the reference and every start
        models = worker_models()
        reference = estimator.calibrate(chain, experiment.calibration, self.sigma, twists=twists,
                                        models=models).table
        rows = []
        for start_index in range(self.first, self.first + self.count):
            seed = restart_start_seed(self.config.entropy, self.case, self.estimator_index, start_index)
            start = random_start(np.random.default_rng(seed))
            row = {
                "case": self.case, "deviations": self.deviations, "level": self.level,
                "sigma_pos_mm": self.sigma, "sigma_rot_deg": self.sigma, "repeat": self.repeat,
                "seed": self.seed, "method": str(estimator.method), "weight": estimator.weight,
                "start": start_index,
            }
            try:
                table = estimator.calibrate(chain, experiment.calibration, self.sigma, start=start,
                                            twists=twists, models=models).table
            except CalibrationError as exc:
                rows.append({**row, "same_solution": False, "max_deps_deg": math.nan,
                             "max_dlength_mm": math.nan, "error": str(exc)})
                continue
            angles, lengths = _fitted_difference(table, reference)
            same = angles <= SAME_SOLUTION_DEG and lengths <= SAME_SOLUTION_MM
            rows.append({**row, "same_solution": bool(same), "max_deps_deg": angles,
                         "max_dlength_mm": lengths, "error": ""})
        return rows


@dataclass(frozen=True)
class Figure2Task:
    """Figure 2: per-pose errors q_j, eta_j (eq 24) of Methods 1 and 2, one noise realisation."""

    config: StudyConfig
    deviations: str
    seed: int

    @property
    def key(self) -> tuple:
        return (_FIGURE2_ERRORS,)

    def run(self) -> list[dict[str, Any]]:
        with _simulated(self.config, self.deviations, FIGURE2_SIGMA, self.seed) as (chain, experiment):
            return self._rows(chain, experiment)

    def _rows(self, chain: KinematicChain, experiment: SimulatedExperiment) -> list[dict[str, Any]]:
        out, twists = [], _twists(chain, experiment)
        for estimator in (METHOD_1, METHOD_2):
            result = estimator.calibrate(chain, experiment.calibration, FIGURE2_SIGMA, twists=twists,
                                         models=worker_models())
            with chain.placed(result.table.joint_origins()):
                errors = pose_errors(
                    chain, experiment.validation, result.registration_position, result.registration_orientation
                )
            assert errors.rotation_rad is not None  # the study's rows have orientations
            out.append({
                "method": str(estimator.method), "deviations": self.deviations,
                "sigma_pos_mm": FIGURE2_SIGMA, "sigma_rot_deg": FIGURE2_SIGMA,
                "repeat": FIGURE2_REPEAT, "seed": self.seed,
                "q_mm": (errors.position_m[:, 0] * 1000.0).tolist(),
                "eta_deg": np.degrees(errors.rotation_rad).tolist(),
            })
        return out


@dataclass(frozen=True)
class LimitTask:
    """The noise limit of one estimator on one pose set, at sigma_p = 1 mm, sigma_a = 1 deg.

    The linearised prediction is proportional to sigma when sigma_p [mm] =
    sigma_a [deg], so the limit at any level is sigma times this value.
    """

    config: StudyConfig
    deviations: str
    pose_set: int
    seed: int
    estimator_index: int

    @property
    def key(self) -> tuple:
        return (_LIMITS, deviation_index(self.deviations), self.estimator_index, self.pose_set)

    def run(self) -> list[dict[str, Any]]:
        estimator = self.config.estimators[self.estimator_index]
        with _simulated(self.config, self.deviations, 1.0, self.seed) as (chain, experiment):
            limit = estimator.noise_limit(chain, experiment, 1.0)
        return [{
            "deviations": self.deviations, "method": str(estimator.method), "weight": estimator.weight,
            "pose_set": self.pose_set, "seed": self.seed,
            "pos_mm_per_unit_sigma": float(limit.position_mm),
            "rot_deg_per_unit_sigma": float(limit.rotation_deg),
        }]
