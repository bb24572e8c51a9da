"""The paper's simulation study (Franaszek & Marvel 2022, Sections 7–9), scaled out.

Protocol of Section 7 with the paper's defaults: the KUKA LWR 4+ of Table 1
with both deviation sets of Table 2 (``small``, ``large``); M_n = 16 noise
levels equally spaced from 0 to 0.15 (sigma_p in mm = sigma_a in degrees);
N_rep = 25 noise realisations per level; K_alpha = 40 CPA rows per joint
(eq 23), K = 100 calibration and J = 50 test poses. Every trial calibrates
with each estimator of :data:`ESTIMATORS` — Methods 1, 2, 3 (w = 1 and
w = :data:`SECOND_WEIGHT`) and the noise-weighted maximum-likelihood
estimator — and evaluates it on the test poses through Registration 1 and
Registration 2 (Method 1 has Registration 1 only):

* ``pos_mean_mm``, ``rot_mean_deg``: <q_j> and <eta_j> of eq 24 against the
  *noisy* test measurements, as in the paper;
* ``pos_truth_mean_mm``, ``rot_truth_mean_deg``: the same against the
  *noise-free* test poses (eq 20–21 without N_k and zeta_k), which is what the
  linearised noise limit (:func:`pincal.noise_limit.predicted_errors`) predicts.

Means and standard deviations over repeats follow eq 25 (1/N_rep). The
restart test of Section 7 recalibrates a few trials from random starting DH
tables and counts how many reach the solution of the nominal start.

One task is one (deviation set, level, repeat); its seed is a pure function
of that key (:func:`task_seed`, through :class:`numpy.random.SeedSequence`),
so the results are identical seed for seed whatever runs the tasks: this
process, local worker processes or a Dask cluster. Only fit times differ.
:func:`run_study` runs a study, :func:`write_study` writes its files.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence, TextIO

import numpy as np

from .chain import KinematicChain
from .dh import DEVIATION_SETS, KUKA_LWR4_DH, DHTable
from .errors import CalibrationError, PincalError
from .measurements import MeasurementSet
from .metrics import pose_errors
from .ml_estimator import calibrate_ml
from .noise_limit import PredictedErrors, predicted_errors
from .paper_methods import PaperCalibration, calibrate_paper
from .robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from .simulation import SimulatedExperiment, SimulationSettings, simulate_experiment

#: Root entropy of every seed of the study (the paper's article number).
STUDY_ENTROPY = 3680
#: Method 3's second weight w [mm²/deg²]: orientations dominate Err_full (eq 18).
SECOND_WEIGHT = 100.0
#: Half-width of the uniform random starts of the restart test: eps [deg], r and d [mm].
RESTART_SPREAD_DEG = 5.0
RESTART_SPREAD_MM = 5.0
#: Two fits reach "the same solution" when every fitted eps agrees within
#: SAME_SOLUTION_DEG [deg] and every fitted r, d within SAME_SOLUTION_MM [mm].
SAME_SOLUTION_DEG = 1e-4
SAME_SOLUTION_MM = 1e-4
#: Two mean errors are "comparable" when their ratio lies in this interval.
COMPARABLE = (0.67, 1.5)
#: Largest deviations from the ground truth reported in Section 8 [deg, deg, mm, mm].
PAPER_MAX_DEVIATIONS = {"max_dalpha_deg": 0.3, "max_deps_deg": 1.18, "max_dr_mm": 4.2, "max_dd_mm": 4.7}
#: Figure 2: sigma_p = 0.055 mm, sigma_a = 0.055 deg and the paper's noise realisation i = 14.
FIGURE2_SIGMA = 0.055
FIGURE2_REPEAT = 14

# First entry of a seed's spawn key: what the seed is for.
_TRIAL, _RESTART_START, _FIGURE2 = 0, 1, 2
# First entry of a task's sort key: its kind.
_TRIALS, _RESTARTS, _FIGURE2_ERRORS, _LIMITS = 0, 1, 2, 3
_RESTART_CHUNK = 50  # restarts per task


@dataclass(frozen=True)
class Estimator:
    """One estimator of the study.

    Attributes:
        method: 1, 2 or 3 (the paper's methods) or ``"ml"`` (noise-weighted
            maximum likelihood, :func:`pincal.ml_estimator.calibrate_ml`).
        weight: w of Method 3 [mm²/deg²] (eq 18); None for the others.
    """

    method: int | str
    weight: float | None = None

    @classmethod
    def of(cls, method: str, weight: float | None) -> "Estimator":
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

    def calibrate(
        self, chain: KinematicChain, data: MeasurementSet, sigma: float, start: DHTable | None = None
    ) -> PaperCalibration:
        """Calibrate from Table 1 on ``data``'s ``cpa`` and ``calibration`` rows.

        Args:
            chain: the KUKA chain with the TCP as its tool.
            data: the rows.
            sigma: the noise level, sigma_p [mm] = sigma_a [deg]; the ML estimator
                weighs with it (on noise-free data any equal weights give the truth).
            start: starting eps, r, d of a paper method (default Table 1).
        """
        chain.set_placements(KUKA_LWR4_DH.joint_origins())
        if self.method == "ml":
            scale = sigma if sigma > 0 else 1.0
            return calibrate_ml(chain, data, sigma_pos_mm=scale, sigma_rot_deg=scale, nominal=KUKA_LWR4_DH)
        weight = 1.0 if self.weight is None else self.weight
        return calibrate_paper(chain, data, int(self.method), weight, nominal=KUKA_LWR4_DH, start=start)

    def noise_limit(self, chain: KinematicChain, experiment: SimulatedExperiment, sigma: float) -> PredictedErrors:
        """Linearised (Cramér–Rao) prediction of the truth-referenced test errors at ``sigma``."""
        weight = 1.0 if self.weight is None else self.weight
        return predicted_errors(chain, experiment, self.method, sigma, sigma, weight=weight)


METHOD_1, METHOD_2, METHOD_3 = Estimator(1), Estimator(2), Estimator(3, 1.0)
ML_ESTIMATOR = Estimator("ml")
#: The estimators of the study, in report order.
ESTIMATORS = (METHOD_1, METHOD_2, METHOD_3, Estimator(3, SECOND_WEIGHT), ML_ESTIMATOR)
#: The paper's three error functions Err_pos, Err_rot, Err_full: the restart test's subjects.
RESTART_ESTIMATORS = (METHOD_1, METHOD_2, METHOD_3)


@dataclass(frozen=True)
class StudyConfig:
    """What to simulate (defaults: the paper's Section 7).

    Attributes:
        deviations: Table 2 deviation sets.
        levels: M_n, noise levels equally spaced from 0 to ``max_sigma``.
        max_sigma: largest sigma_p [mm] = sigma_a [deg].
        repeats: N_rep, noise realisations per level.
        restarts: random starting points per restart case (the paper: 300).
        restart_cases: trials (deviation set, level, repeat) of the restart test.
        limit_pose_sets: pose sets the noise limit is averaged over (0: no limit).
        estimators: the estimators compared.
        n_cpa: K_alpha, CPA rows per joint (eq 23).
        n_calibration: K, calibration poses.
        n_validation: J, test poses.
        entropy: root entropy of all seeds.
    """

    deviations: tuple[str, ...] = ("small", "large")
    levels: int = 16
    max_sigma: float = 0.15
    repeats: int = 25
    restarts: int = 300
    restart_cases: int = 3
    limit_pose_sets: int = 2
    estimators: tuple[Estimator, ...] = ESTIMATORS
    n_cpa: int = 40
    n_calibration: int = 100
    n_validation: int = 50
    entropy: int = STUDY_ENTROPY

    def __post_init__(self) -> None:
        unknown = [d for d in self.deviations if d not in DEVIATION_SETS]
        problems = [
            (not self.deviations or unknown, f"deviations must be among {', '.join(DEVIATION_SETS)}"),
            (self.levels < 1, f"levels must be >= 1, got {self.levels}"),
            (self.repeats < 1, f"repeats must be >= 1, got {self.repeats}"),
            (self.restarts < 0, f"restarts must be >= 0, got {self.restarts}"),
            (self.restart_cases < 0, f"restart_cases must be >= 0, got {self.restart_cases}"),
            (self.limit_pose_sets < 0, f"limit_pose_sets must be >= 0, got {self.limit_pose_sets}"),
            (not (self.max_sigma > 0 and math.isfinite(self.max_sigma)), "max_sigma must be > 0"),
        ]
        for failed, message in problems:
            if failed:
                raise PincalError(f"study: {message}")

    @property
    def sigmas(self) -> np.ndarray:
        """The M_n noise levels sigma_p [mm] = sigma_a [deg]."""
        return np.linspace(0.0, self.max_sigma, self.levels)

    def settings(self, sigma: float, seed: int) -> SimulationSettings:
        """Simulation settings of one experiment (noisy test poses, as for eq 24)."""
        return SimulationSettings(
            sigma_pos_mm=float(sigma),
            sigma_rot_deg=float(sigma),
            n_cpa=self.n_cpa,
            n_calibration=self.n_calibration,
            n_validation=self.n_validation,
            seed=seed,
        )


def _seed(entropy: int, *spawn_key: int) -> int:
    """A 32-bit seed from ``SeedSequence(entropy, spawn_key)``."""
    sequence = np.random.SeedSequence(entropy, spawn_key=tuple(int(k) for k in spawn_key))
    return int(sequence.generate_state(1, np.uint32)[0])


def _deviation_index(deviations: str) -> int:
    return list(DEVIATION_SETS).index(deviations)


def task_seed(deviations: str, level: int, repeat: int, entropy: int = STUDY_ENTROPY) -> int:
    """Seed of the trial (deviation set, level index, repeat): a pure function of the key."""
    return _seed(entropy, _TRIAL, _deviation_index(deviations), level, repeat)


# --- what a worker does ----------------------------------------------------------------

_LOCAL = threading.local()


def worker_chain() -> KinematicChain:
    """The packaged KUKA LWR 4+ chain, loaded once per worker process (and thread)."""
    chain = getattr(_LOCAL, "chain", None)
    if chain is None:
        chain = _LOCAL.chain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK)
    return chain


def _simulate(config: StudyConfig, deviations: str, sigma: float, seed: int):
    """The worker's chain (tool = the true TCP) and a simulated experiment."""
    chain = worker_chain()
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, DEVIATION_SETS[deviations], config.settings(sigma, seed))
    chain.set_tool(experiment.tool)
    return chain, experiment


def noise_free_test_set(chain: KinematicChain, experiment: SimulatedExperiment) -> MeasurementSet:
    """The J test poses as a perfect sensor sees them: eq 20–21 without N_k and zeta_k.

    The chain's placements and tool are restored afterwards.
    """
    validation = experiment.validation
    saved_placements, saved_tool = chain.placements(), chain.tool
    chain.set_placements(experiment.truth.joint_origins())
    chain.set_tool(experiment.tool)
    try:
        poses = chain.poses(validation.q)
    finally:
        chain.set_placements(saved_placements)
        chain.set_tool(saved_tool)
    sensor_T_base = experiment.registration
    return MeasurementSet(
        joint_names=validation.joint_names,
        q=validation.q,
        points=sensor_T_base.apply_points(poses.tool_positions)[:, None, :],
        rotations=sensor_T_base.apply_rotations(poses.tool_rotations),
        roles=validation.roles,
        lines=validation.lines,
        source="<noise-free truth>",
    )


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
        return (_TRIALS, _deviation_index(self.deviations), self.level, self.repeat)

    def run(self) -> list[dict[str, Any]]:
        chain, experiment = _simulate(self.config, self.deviations, self.sigma, self.seed)
        test_sets = {"": experiment.validation, "_truth": noise_free_test_set(chain, experiment)}
        rows = []
        for estimator in self.config.estimators:
            started = time.perf_counter()
            result = estimator.calibrate(chain, experiment.calibration, self.sigma)
            fit_ms = (time.perf_counter() - started) * 1000.0
            chain.set_placements(result.table.joint_origins())
            deviations = parameter_deviations(result.table, experiment.truth)
            registrations = {1: result.registration_position, 2: result.registration_orientation}
            for index in estimator.registrations:
                row = {
                    "deviations": self.deviations, "level": self.level, "sigma_pos_mm": self.sigma,
                    "sigma_rot_deg": self.sigma, "repeat": self.repeat, "seed": self.seed,
                    "method": str(estimator.method), "weight": estimator.weight, "registration": index,
                }
                for suffix, data in test_sets.items():  # eq 24 through this registration
                    errors = pose_errors(chain, data, registrations[index], registrations[index])
                    row[f"pos{suffix}_mean_mm"] = errors.position.mean
                    row[f"rot{suffix}_mean_deg"] = errors.rotation.mean
                rows.append({**row, "fit_ms": fit_ms, **deviations})
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
        estimator = RESTART_ESTIMATORS[self.estimator_index]
        chain, experiment = _simulate(self.config, self.deviations, self.sigma, self.seed)
        reference = estimator.calibrate(chain, experiment.calibration, self.sigma).table
        rows = []
        for start_index in range(self.first, self.first + self.count):
            spawn_key = (_RESTART_START, self.case, self.estimator_index, start_index)
            start = random_start(np.random.default_rng(_seed(self.config.entropy, *spawn_key)))
            row = {
                "case": self.case, "deviations": self.deviations, "level": self.level,
                "sigma_pos_mm": self.sigma, "sigma_rot_deg": self.sigma, "repeat": self.repeat,
                "seed": self.seed, "method": str(estimator.method), "weight": estimator.weight,
                "start": start_index,
            }
            try:
                table = estimator.calibrate(chain, experiment.calibration, self.sigma, start=start).table
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
        chain, experiment = _simulate(self.config, self.deviations, FIGURE2_SIGMA, self.seed)
        out = []
        for estimator in (METHOD_1, METHOD_2):
            result = estimator.calibrate(chain, experiment.calibration, FIGURE2_SIGMA)
            chain.set_placements(result.table.joint_origins())
            errors = pose_errors(
                chain, experiment.validation, result.registration_position, result.registration_orientation
            )
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
        return (_LIMITS, _deviation_index(self.deviations), self.estimator_index, self.pose_set)

    def run(self) -> list[dict[str, Any]]:
        estimator = self.config.estimators[self.estimator_index]
        chain, experiment = _simulate(self.config, self.deviations, 1.0, self.seed)
        limit = estimator.noise_limit(chain, experiment, 1.0)
        return [{
            "deviations": self.deviations, "method": str(estimator.method), "weight": estimator.weight,
            "pose_set": self.pose_set, "seed": self.seed,
            "pos_mm_per_unit_sigma": float(limit.position_mm),
            "rot_deg_per_unit_sigma": float(limit.rotation_deg),
        }]


def restart_cases(config: StudyConfig) -> list[tuple[str, int, int]]:
    """The (deviation set, level index, repeat) trials of the restart test.

    In turn: large deviations at the sigma nearest 0.05, small at 0.10, large
    at the largest sigma; repeats 0, 1, 2, ... (modulo N_rep).
    """
    preferences = (("large", 0.05), ("small", 0.10), ("large", config.max_sigma))
    cases = []
    for case in range(config.restart_cases):
        wanted, sigma = preferences[case % len(preferences)]
        deviations = wanted if wanted in config.deviations else config.deviations[case % len(config.deviations)]
        cases.append((deviations, int(np.argmin(np.abs(config.sigmas - sigma))), case % config.repeats))
    return cases


def study_tasks(config: StudyConfig) -> list:
    """All tasks of a study, the longest first: noise limits, restarts, trials, Figure 2.

    The noise limit is computed on the pose sets of the trials (deviation set,
    highest level, repeat r) for r < ``limit_pose_sets``.
    """
    sigmas = config.sigmas
    tasks: list = []
    for deviations in config.deviations:
        for pose_set in range(min(config.limit_pose_sets, config.repeats)):
            seed = task_seed(deviations, config.levels - 1, pose_set, config.entropy)
            tasks += [LimitTask(config, deviations, pose_set, seed, i) for i in range(len(config.estimators))]
    for case, (deviations, level, repeat) in enumerate(restart_cases(config) if config.restarts else []):
        seed = task_seed(deviations, level, repeat, config.entropy)
        for index in range(len(RESTART_ESTIMATORS)):
            for first in range(0, config.restarts, _RESTART_CHUNK):
                count = min(_RESTART_CHUNK, config.restarts - first)
                tasks.append(RestartTask(config, case, deviations, level, float(sigmas[level]), repeat, seed,
                                         index, first, count))
    for deviations in config.deviations:
        for level, sigma in enumerate(sigmas):
            for repeat in range(config.repeats):
                seed = task_seed(deviations, level, repeat, config.entropy)
                tasks.append(TrialTask(config, deviations, level, float(sigma), repeat, seed))
    figure2 = "large" if "large" in config.deviations else config.deviations[0]
    seed = _seed(config.entropy, _FIGURE2, _deviation_index(figure2), FIGURE2_REPEAT)
    tasks.append(Figure2Task(config, figure2, seed))
    return tasks


def _run_task(task) -> list[dict[str, Any]]:
    """Entry point of every executor (module level, hence picklable)."""
    return task.run()


# --- executors -----------------------------------------------------------------------------

Progress = Callable[[int, int], None]


class ProgressBar:
    """A one-line text progress bar, e.g. ``study   412/909 [#####.....]   31 s``.

    Args:
        stream: where to draw; the CLI passes stderr, and only if it is a terminal.
        label: text before the counts.
        width: characters of the bar.
    """

    def __init__(self, stream: TextIO, label: str = "study", width: int = 30) -> None:
        self.stream, self.label, self.width = stream, label, width
        self.started = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        filled = self.width * done // max(total, 1)
        elapsed = time.perf_counter() - self.started
        self.stream.write(f"\r{self.label} {done:>5d}/{total} [{'#' * filled}{'.' * (self.width - filled)}] "
                          f"{elapsed:4.0f} s" + ("\n" if done >= total else ""))
        self.stream.flush()


def default_workers() -> int:
    """All cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


#: Worker processes use one BLAS thread each: the parallelism is across tasks, and
#: several multi-threaded BLAS pools on the same cores slow every task down (Dask's
#: nanny sets the same variables for its worker processes).
_SINGLE_THREADED_BLAS = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


@contextmanager
def _single_threaded_blas():
    """Set :data:`_SINGLE_THREADED_BLAS` (unless the user set them) for the processes
    spawned inside the block; restore the environment afterwards."""
    unset = [name for name in _SINGLE_THREADED_BLAS if name not in os.environ]
    os.environ.update({name: _SINGLE_THREADED_BLAS[name] for name in unset})
    try:
        yield
    finally:
        for name in unset:
            os.environ.pop(name, None)


def execute(
    tasks: Sequence, workers: int | None = None, scheduler: Any = None, progress: Progress | None = None
) -> tuple[list, str]:
    """Run ``task.run()`` for every task; results in task order, whatever the executor.

    Args:
        tasks: picklable objects with a ``run()`` method.
        workers: local worker processes (default: all cores; 1 runs in this
            process); with ``scheduler="local"``, the LocalCluster's processes.
        scheduler: None (local processes), a Dask scheduler address, ``"local"``
            (start a Dask LocalCluster) or a ``distributed.Client``.
        progress: called as ``progress(done, total)`` after each task.

    Returns:
        The results and a description of the executor.
    """
    report = progress or (lambda done, total: None)
    if scheduler is not None:
        return _execute_dask(tasks, workers, scheduler, report)
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise PincalError(f"workers must be >= 1, got {workers}")
    results: list = [None] * len(tasks)
    if workers == 1:
        for index, task in enumerate(tasks):
            results[index] = _run_task(task)
            report(index + 1, len(tasks))
        return results, "in-process"
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"))
    try:
        with _single_threaded_blas():  # the workers start while the tasks are submitted
            futures = {pool.submit(_run_task, task): index for index, task in enumerate(tasks)}
        for done, future in enumerate(as_completed(futures), start=1):
            results[futures[future]] = future.result()
            report(done, len(tasks))
    finally:
        pool.shutdown(cancel_futures=True)
    return results, f"{workers} local processes"


def _execute_dask(tasks: Sequence, workers: int | None, scheduler: Any, report: Progress) -> tuple[list, str]:
    try:
        import distributed
    except ImportError:
        raise PincalError("--scheduler needs Dask: pip install 'dask[distributed]' (or 'pincal[dask]')") from None
    owned: list = []  # what this function started and must close, client first
    if scheduler == "local":
        n = default_workers() if workers is None else workers
        cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, dashboard_address=None)
        client = distributed.Client(cluster)
        owned += [client, cluster]
        description = f"Dask LocalCluster ({n} processes)"
    elif isinstance(scheduler, str):
        try:
            client = distributed.Client(scheduler)
        except (OSError, TimeoutError, ValueError) as exc:
            raise PincalError(f"cannot reach the Dask scheduler at {scheduler}: {exc}") from None
        owned.append(client)
        description = f"Dask cluster at {scheduler}"
    else:
        client = scheduler
        description = f"Dask client of {client.scheduler.address}"
    try:
        futures = client.map(_run_task, list(tasks), pure=False)
        for done, _ in enumerate(distributed.as_completed(futures), start=1):
            report(done, len(futures))
        return list(client.gather(futures)), description
    finally:
        for resource in owned:
            resource.close()


# --- the study -------------------------------------------------------------------------------


@dataclass(frozen=True)
class StudyResult:
    """Everything a study produced.

    Attributes:
        config: what was run.
        rows: one dict per (deviations, level, repeat, method, weight, registration), sorted.
        limits: the noise limit at unit sigma, one dict per (deviations, estimator, pose set).
        restarts: one dict per restart, sorted by (case, estimator, start).
        restart_summary: per restart case and estimator, the starts reaching the same solution.
        figure2: per-pose errors of Methods 1 and 2 (Figure 2).
        summary: eq 25 per (deviations, level, method, weight, registration), with the noise limit.
        findings: the paper's findings checked on this run.
        executor: what ran the tasks.
        wall_s: wall time of the study [s].
    """

    config: StudyConfig
    rows: list[dict[str, Any]]
    limits: list[dict[str, Any]]
    restarts: list[dict[str, Any]]
    restart_summary: list[dict[str, Any]]
    figure2: list[dict[str, Any]]
    summary: list[dict[str, Any]]
    findings: list[dict[str, Any]]
    executor: str
    wall_s: float


def run_study(
    config: StudyConfig = StudyConfig(),
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
) -> StudyResult:
    """Run the simulation study of Section 7 and check the findings of Sections 8–9.

    Args:
        config: the protocol (defaults: the paper's).
        workers: local worker processes (default all cores; 1 = this process).
        scheduler: Dask scheduler address, ``"local"``, a ``distributed.Client``, or None.
        progress: ``progress(done, total)`` callback.
    """
    started = time.perf_counter()
    tasks = study_tasks(config)
    results, executor = execute(tasks, workers, scheduler, progress)
    by_kind: dict[int, list] = {_TRIALS: [], _RESTARTS: [], _FIGURE2_ERRORS: [], _LIMITS: []}
    for task, rows in sorted(zip(tasks, results), key=lambda pair: pair[0].key):
        by_kind[task.key[0]].extend(rows)
    summary = summarize(by_kind[_TRIALS], by_kind[_LIMITS])
    restart_summary = summarize_restarts(by_kind[_RESTARTS])
    return StudyResult(
        config=config,
        rows=by_kind[_TRIALS],
        limits=by_kind[_LIMITS],
        restarts=by_kind[_RESTARTS],
        restart_summary=restart_summary,
        figure2=by_kind[_FIGURE2_ERRORS],
        summary=summary,
        findings=check_findings(summary, by_kind[_TRIALS], restart_summary, config),
        executor=executor,
        wall_s=time.perf_counter() - started,
    )


# --- eq 25 and the estimator-vs-limit table -------------------------------------------------

_GROUP = ("deviations", "level", "sigma_pos_mm", "sigma_rot_deg", "method", "weight", "registration")
_AVERAGED = ("pos_mean_mm", "rot_mean_deg", "pos_truth_mean_mm", "rot_truth_mean_deg")


def _ratio(a: float, b: float) -> float:
    return float(a / b) if b > 0 else math.nan


def summarize(rows: Sequence[dict[str, Any]], limits: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Eq 25 over repeats, per (deviations, level, method, weight, registration).

    For each error column c: ``c`` (mean) and ``c_sd`` (standard deviation with
    1/N_rep). ``limit_pos_mm`` (on Registration 1 rows) and ``limit_rot_deg``
    (on Registration 2 rows; Method 1: Registration 1) are the noise limit,
    sigma times its mean over the pose sets, ``limit_*_sd`` its spread over
    them (1/L), and ``*_truth_over_limit`` how far the estimator is from it
    (1 = at the limit); NaN where the limit does not apply.
    """
    unit: dict[tuple, list] = {}
    for limit in limits:
        key = (limit["deviations"], limit["method"], limit["weight"])
        unit.setdefault(key, []).append((limit["pos_mm_per_unit_sigma"], limit["rot_deg_per_unit_sigma"]))
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(tuple(row[k] for k in _GROUP), []).append(row)
    summary = []
    for key, members in groups.items():
        out = dict(zip(_GROUP, key))
        out["n_repeats"] = len(members)
        for column in _AVERAGED:
            values = np.array([m[column] for m in members])
            out[column], out[column + "_sd"] = float(values.mean()), float(values.std())
        per_set = np.array(unit.get((out["deviations"], out["method"], out["weight"]), [(math.nan, math.nan)]))
        sigma = out["sigma_pos_mm"]
        orientation = Estimator.of(out["method"], out["weight"]).orientation_registration
        for i, limit, measured, ratio, applies in (
            (0, "limit_pos_mm", "pos_truth_mean_mm", "pos_truth_over_limit", out["registration"] == 1),
            (1, "limit_rot_deg", "rot_truth_mean_deg", "rot_truth_over_limit", out["registration"] == orientation),
        ):
            out[limit] = float(sigma * per_set[:, i].mean()) if applies else math.nan
            out[limit + "_sd"] = float(sigma * per_set[:, i].std()) if applies else math.nan
            out[ratio] = _ratio(out[measured], out[limit])
        out["fit_ms_median"] = float(np.median([m["fit_ms"] for m in members]))
        for column in PAPER_MAX_DEVIATIONS:
            out[column] = float(max(m[column] for m in members))
        summary.append(out)
    return summary


def limit_table(summary: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """The estimator-vs-limit table: Monte Carlo (against the noise-free truth) beside the prediction.

    One row per (deviations, level, estimator): position through Registration 1,
    orientation through Registration 2 (Method 1: Registration 1).
    """
    index = {tuple(s[k] for k in _GROUP): s for s in summary}
    table = []
    for key, position in index.items():
        if position["registration"] != 1:
            continue
        estimator = Estimator.of(position["method"], position["weight"])
        orientation = index[key[:-1] + (estimator.orientation_registration,)]
        table.append({
            **{k: position[k] for k in _GROUP[:-1]},
            **{c: position[c] for c in ("pos_truth_mean_mm", "pos_truth_mean_mm_sd", "limit_pos_mm",
                                        "limit_pos_mm_sd", "pos_truth_over_limit")},
            **{c: orientation[c] for c in ("rot_truth_mean_deg", "rot_truth_mean_deg_sd", "limit_rot_deg",
                                           "limit_rot_deg_sd", "rot_truth_over_limit")},
        })
    return table


def summarize_restarts(restarts: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per restart case and estimator: how many starts reached the nominal start's solution."""
    fields = ("case", "deviations", "level", "sigma_pos_mm", "repeat", "seed", "method", "weight")
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for row in restarts:
        groups.setdefault(tuple(row[k] for k in fields), []).append(row)
    table = []
    for key, members in groups.items():
        converged = [m for m in members if not m["error"]]
        table.append({
            **dict(zip(fields, key)),
            "starts": len(members),
            "same_solution": sum(m["same_solution"] for m in members),
            "failed": len(members) - len(converged),
            "max_deps_deg": max((m["max_deps_deg"] for m in converged), default=math.nan),
            "max_dlength_mm": max((m["max_dlength_mm"] for m in converged), default=math.nan),
        })
    return table


# --- the paper's findings ----------------------------------------------------------------------


class _Curves:
    """Eq 25 means over the non-zero noise levels, by deviation set, estimator and registration."""

    def __init__(self, summary: Sequence[dict[str, Any]], deviations: Sequence[str]) -> None:
        self.deviations = tuple(deviations)
        self.rows: dict[tuple, list[dict[str, Any]]] = {}
        for s in sorted(summary, key=lambda s: s["level"]):
            if s["sigma_pos_mm"] > 0:
                self.rows.setdefault((s["deviations"], s["method"], s["weight"], s["registration"]), []).append(s)

    def get(self, deviations: str, estimator: Estimator, registration: int, column: str) -> np.ndarray:
        rows = self.rows.get((deviations, str(estimator.method), estimator.weight, registration), [])
        return np.array([s[column] for s in rows])

    def ratio(self, a: tuple[Estimator, int], b: tuple[Estimator, int], column: str) -> dict[str, np.ndarray]:
        """Per deviation set, over the levels: column of (estimator, registration) a / b."""
        return {d: self.get(d, *a, column) / self.get(d, *b, column) for d in self.deviations}


def _stats(ratios: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Mean, min and max of each set's ratios."""
    return {d: {"mean": float(v.mean()), "min": float(v.min()), "max": float(v.max())} if v.size
            else {"mean": math.nan, "min": math.nan, "max": math.nan} for d, v in ratios.items()}


def _describe(ratios: dict[str, np.ndarray]) -> str:
    return "; ".join(f"{d}: mean {v.mean():.3f} (range {v.min():.3f}–{v.max():.3f})" if v.size else f"{d}: –"
                     for d, v in ratios.items())


def _overall(ratios: dict[str, np.ndarray]) -> float:
    """Mean over the deviation sets of the mean over the levels."""
    return float(np.mean([v.mean() for v in ratios.values()])) if ratios else math.nan


def _finding(name: str, claim: str, holds: bool, evidence: str, **values: Any) -> dict[str, Any]:
    return {"finding": name, "paper": claim, "holds": bool(holds), "evidence": evidence, "values": values}


def check_findings(
    summary: Sequence[dict[str, Any]],
    rows: Sequence[dict[str, Any]],
    restart_summary: Sequence[dict[str, Any]],
    config: StudyConfig,
) -> list[dict[str, Any]]:
    """Check the findings of Sections 8–9 on this run, with the numbers.

    Comparisons use the eq 25 means at the non-zero noise levels on the noisy
    test measurements (eq 24, the paper's metric); ratios against the
    noise-free truth are given beside them. "At every level" is strict. A
    finding is checked only when the study ran the estimators it needs.
    """
    curves = _Curves(summary, config.deviations)
    ran = set(config.estimators)
    found = []
    if {METHOD_1, METHOD_2} <= ran:
        rot = curves.ratio((METHOD_2, 2), (METHOD_1, 1), "rot_mean_deg")
        rot_truth = curves.ratio((METHOD_2, 2), (METHOD_1, 1), "rot_truth_mean_deg")
        found.append(_finding(
            "method2_orientation_below_method1",
            "Method 2's orientation error (Registration 2) is below Method 1's at every level (Fig 5b)",
            all(v.size and np.all(v < 1) for v in rot.values()),
            f"rot(M2, Reg 2) / rot(M1): {_describe(rot)}; against the noise-free truth: {_describe(rot_truth)}",
            ratio=_stats(rot), ratio_truth=_stats(rot_truth),
        ))
        pos = curves.ratio((METHOD_2, 1), (METHOD_1, 1), "pos_mean_mm")
        pos_truth = curves.ratio((METHOD_2, 1), (METHOD_1, 1), "pos_truth_mean_mm")
        low, high = COMPARABLE
        found.append(_finding(
            "position_errors_comparable",
            f"Position errors of Methods 1 and 2 are comparable: ratio within {low}–{high} at every level "
            "(Fig 5a)",
            all(v.size and np.all((v >= low) & (v <= high)) for v in pos.values()),
            f"pos(M2, Reg 1) / pos(M1): {_describe(pos)}; against the noise-free truth: {_describe(pos_truth)}",
            ratio=_stats(pos), ratio_truth=_stats(pos_truth), interval=list(COMPARABLE),
        ))
    for estimator in (METHOD_2, METHOD_3):
        if estimator not in ran:
            continue
        rot = curves.ratio((estimator, 2), (estimator, 1), "rot_mean_deg")
        pos = curves.ratio((estimator, 1), (estimator, 2), "pos_mean_mm")
        rot_truth = curves.ratio((estimator, 2), (estimator, 1), "rot_truth_mean_deg")
        pos_truth = curves.ratio((estimator, 1), (estimator, 2), "pos_truth_mean_mm")
        found.append(_finding(
            f"registrations_method{estimator.method}",
            f"{estimator.label}: Registration 2 is better for orientation and Registration 1 for position, "
            "at every level (Fig 3, 4)",
            all(v.size and np.all(v < 1) for v in [*rot.values(), *pos.values()]),
            f"rot(Reg 2)/rot(Reg 1): {_describe(rot)}; pos(Reg 1)/pos(Reg 2): {_describe(pos)}; against the "
            f"noise-free truth: rot {_describe(rot_truth)}; pos {_describe(pos_truth)}",
            rot_reg2_over_reg1=_stats(rot), pos_reg1_over_reg2=_stats(pos),
            rot_reg2_over_reg1_truth=_stats(rot_truth), pos_reg1_over_reg2_truth=_stats(pos_truth),
        ))
    if {METHOD_2, METHOD_3} <= ran:
        pos = curves.ratio((METHOD_3, 1), (METHOD_2, 1), "pos_mean_mm")
        rot = curves.ratio((METHOD_3, 2), (METHOD_2, 2), "rot_mean_deg")
        found.append(_finding(
            "method3_worse_than_method2",
            "Method 3 (w=1) is worse than Method 2: its mean errors are at least Method 2's in position "
            "(Registration 1) and orientation (Registration 2), averaged over the levels (Fig 5c,d)",
            _overall(pos) >= 1 and _overall(rot) >= 1,
            f"pos(M3)/pos(M2): {_describe(pos)}; rot(M3)/rot(M2): {_describe(rot)}",
            pos_ratio=_stats(pos), rot_ratio=_stats(rot),
        ))
    second = next((e for e in config.estimators if e.method == 3 and e != METHOD_3), None)
    if second is not None and METHOD_3 in ran:
        pos = curves.ratio((second, 1), (METHOD_3, 1), "pos_mean_mm")
        rot = curves.ratio((second, 2), (METHOD_3, 2), "rot_mean_deg")
        pos_change = float(np.mean([np.abs(v - 1).mean() for v in pos.values()]))
        rot_change = float(np.mean([np.abs(v - 1).mean() for v in rot.values()]))
        found.append(_finding(
            "method3_sensitive_to_w",
            f"Method 3 depends on w: position errors differ substantially between w=1 and w={second.weight:g} "
            "(mean |change| > 10 %), orientation errors are almost equal (less change than positions) (Fig 6)",
            pos_change > 0.10 and rot_change < pos_change,
            f"pos(w={second.weight:g})/pos(w=1): {_describe(pos)}; rot(w={second.weight:g})/rot(w=1): "
            f"{_describe(rot)}; mean |change|: position {100 * pos_change:.1f} %, "
            f"orientation {100 * rot_change:.1f} %",
            pos_ratio=_stats(pos), rot_ratio=_stats(rot), pos_change=pos_change, rot_change=rot_change,
            weight=second.weight,
        ))
    found.append(_parameter_finding(rows))
    if restart_summary:
        total = sum(r["starts"] for r in restart_summary)
        same = sum(r["same_solution"] for r in restart_summary)
        failed = sum(r["failed"] for r in restart_summary)
        cases = sorted({(r["case"], r["deviations"], r["sigma_pos_mm"], r["repeat"]) for r in restart_summary})
        found.append(_finding(
            "restarts_same_solution",
            f"From {config.restarts} random starts, every fit of Methods 1-3 reaches the same solution "
            "(Section 8)",
            same == total,
            f"{same}/{total} restarts reached the solution from Table 1 ({failed} failed; eps within "
            f"{SAME_SOLUTION_DEG:g} deg, r and d within {SAME_SOLUTION_MM:g} mm; starts uniform "
            f"±{RESTART_SPREAD_DEG:g} deg, ±{RESTART_SPREAD_MM:g} mm around Table 1) in "
            + ", ".join(f"case {c} ({d}, sigma {s:.3g}, repeat {r})" for c, d, s, r in cases),
            same=same, total=total, failed=failed,
        ))
    if {METHOD_2, ML_ESTIMATOR} <= ran:
        change = {
            column: 100.0 * (_overall(curves.ratio((ML_ESTIMATOR, reg), (METHOD_2, reg), column)) - 1.0)
            for column, reg in (("pos_mean_mm", 1), ("rot_mean_deg", 2),
                                ("pos_truth_mean_mm", 1), ("rot_truth_mean_deg", 2))
        }
        found.append(_finding(
            "ml_vs_method2",
            "(new) The ML estimator is at least as accurate as Method 2 in position and orientation, "
            "against the noise-free truth",
            change["pos_truth_mean_mm"] <= 0 and change["rot_truth_mean_deg"] <= 0,
            f"ML vs Method 2, mean change over the levels and sets: against the noise-free truth position "
            f"{change['pos_truth_mean_mm']:+.1f} %, orientation {change['rot_truth_mean_deg']:+.1f} %; on the "
            f"noisy test measurements (eq 24) position {change['pos_mean_mm']:+.1f} %, orientation "
            f"{change['rot_mean_deg']:+.1f} %",
            percent_change=change,
        ))
    if METHOD_2 in ran:
        found.append(_four_sigma_finding(curves))
    if METHOD_2 in ran and {"small", "large"} <= set(config.deviations):
        pos = curves.get("large", METHOD_2, 1, "pos_mean_mm") / curves.get("small", METHOD_2, 1, "pos_mean_mm")
        rot = curves.get("large", METHOD_2, 2, "rot_mean_deg") / curves.get("small", METHOD_2, 2, "rot_mean_deg")
        ratios = {"position": pos, "orientation": rot}
        found.append(_finding(
            "deviation_size_irrelevant",
            "Method 2's errors are almost the same for small and large deviations (Fig 3): the mean ratio "
            "over the levels is within 10 % (single levels scatter by the Monte Carlo error)",
            bool(pos.size) and all(abs(v.mean() - 1) <= 0.10 for v in ratios.values()),
            f"large/small: {_describe(ratios)}",
            ratio=_stats(ratios),
        ))
    return found


def _parameter_finding(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Section 8: largest parameter deviations from the ground truth, Methods 1–3."""
    by_estimator: dict[str, dict[str, float]] = {}
    for row in rows:
        entry = by_estimator.setdefault(Estimator.of(row["method"], row["weight"]).label,
                                        dict.fromkeys(PAPER_MAX_DEVIATIONS, 0.0))
        for column in PAPER_MAX_DEVIATIONS:
            entry[column] = max(entry[column], row[column])
    paper_methods = [v for label, v in by_estimator.items() if label.startswith("Method")]
    ours = {c: max((v[c] for v in paper_methods), default=math.nan) for c in PAPER_MAX_DEVIATIONS}
    return _finding(
        "largest_parameter_deviations",
        "Largest deviations from the ground truth over all conditions, Methods 1-3: δα 0.3°, δε 1.18°, "
        "δr 4.2 mm, δd 4.7 mm (holds when each of ours is within a factor 2)",
        all(0.5 <= ours[c] / paper <= 2.0 for c, paper in PAPER_MAX_DEVIATIONS.items()),
        ", ".join(f"{c.removeprefix('max_')} {ours[c]:.3g} (paper {paper:g})"
                  for c, paper in PAPER_MAX_DEVIATIONS.items()),
        ours=ours, paper=dict(PAPER_MAX_DEVIATIONS), by_estimator=by_estimator,
    )


def _four_sigma_finding(curves: _Curves) -> dict[str, Any]:
    """Section 9: for Method 2, v ≈ 4 sigma_p and rho ≈ 4 sigma_a (least-squares slopes through 0)."""
    slopes = {}
    for d in curves.deviations:
        sigma = curves.get(d, METHOD_2, 1, "sigma_pos_mm")
        slope = (lambda y: float(sigma @ y / (sigma @ sigma)) if sigma.size else math.nan)
        slopes[d] = {"pos_mm_per_mm": slope(curves.get(d, METHOD_2, 1, "pos_mean_mm")),
                     "rot_deg_per_deg": slope(curves.get(d, METHOD_2, 2, "rot_mean_deg"))}
    values = [v for s in slopes.values() for v in s.values()]
    return _finding(
        "method2_four_sigma",
        "Method 2's mean errors are about 4x the sensor noise, v ≈ 4 sigma_p and rho ≈ 4 sigma_a "
        "(Section 9; holds when each slope is within 3-5)",
        bool(values) and all(3.0 <= v <= 5.0 for v in values),
        "; ".join(f"{d}: v/sigma_p {s['pos_mm_per_mm']:.2f}, rho/sigma_a {s['rot_deg_per_deg']:.2f}"
                  for d, s in slopes.items()),
        slopes=slopes,
    )


# --- files ------------------------------------------------------------------------------------------

#: Columns of study.csv, one row per (deviations, level, repeat, method, weight, registration).
STUDY_COLUMNS = (
    *_GROUP[:4], "repeat", "seed", *_GROUP[4:], *_AVERAGED, "fit_ms", *PAPER_MAX_DEVIATIONS,
)
#: Columns of summary.csv: eq 25 and the noise limit.
SUMMARY_COLUMNS = (
    *_GROUP, "n_repeats", *(c for column in _AVERAGED for c in (column, column + "_sd")),
    "limit_pos_mm", "limit_pos_mm_sd", "pos_truth_over_limit",
    "limit_rot_deg", "limit_rot_deg_sd", "rot_truth_over_limit", "fit_ms_median", *PAPER_MAX_DEVIATIONS,
)
#: Columns of restarts.csv, one row per restart.
RESTART_COLUMNS = (
    "case", "deviations", "level", "sigma_pos_mm", "sigma_rot_deg", "repeat", "seed", "method", "weight",
    "start", "same_solution", "max_deps_deg", "max_dlength_mm", "error",
)


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)  # full precision; nan as nan
    return str(value)


def write_csv(path: Path, rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> None:
    """Write ``rows`` with ``columns`` in order (None as an empty cell, floats at full precision)."""
    lines = [",".join(columns)] + [",".join(_cell(row[c]) for c in columns) for row in rows]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _json_ready(value: Any) -> Any:
    """Strict JSON: NaN and infinities → None, numpy scalars → Python, recursively."""
    if isinstance(value, dict):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return bool(value) if isinstance(value, np.bool_) else value


def study_json(result: StudyResult) -> dict[str, Any]:
    """Everything of ``result``, ready for :func:`json.dumps`."""
    config = result.config
    return _json_ready({
        "protocol": {
            "paper": "Franaszek & Marvel 2022, Sections 7-9",
            "deviations": list(config.deviations),
            "sigmas_mm_deg": config.sigmas.tolist(),
            "repeats": config.repeats,
            "estimators": [{"method": str(e.method), "weight": e.weight, "label": e.label}
                           for e in config.estimators],
            "n_cpa": config.n_cpa,
            "n_calibration": config.n_calibration,
            "n_validation": config.n_validation,
            "restarts": config.restarts,
            "restart_cases": config.restart_cases,
            "restart_spread": {"epsilon_deg": RESTART_SPREAD_DEG, "r_d_mm": RESTART_SPREAD_MM},
            "same_solution_tolerance": {"epsilon_deg": SAME_SOLUTION_DEG, "r_d_mm": SAME_SOLUTION_MM},
            "limit_pose_sets": config.limit_pose_sets,
            "entropy": config.entropy,
            "seed_rule": "SeedSequence(entropy, spawn_key=(0, deviation index, level, repeat)) -> uint32",
            "columns": {
                "pos_mean_mm, rot_mean_deg": "eq 24 means against the noisy test measurements (the paper's)",
                "pos_truth_mean_mm, rot_truth_mean_deg": "eq 24 means against the noise-free test poses",
                "limit_pos_mm, limit_rot_deg": "linearised (Cramer-Rao) noise limit against the noise-free "
                                               "truth, positions through Registration 1, orientations through "
                                               "Registration 2 (Method 1: 1); sigma times its mean over the "
                                               "pose sets, _sd its spread over them",
            },
        },
        "executor": result.executor,
        "wall_s": result.wall_s,
        "findings": result.findings,
        "summary": result.summary,
        "noise_limit_table": limit_table(result.summary),
        "noise_limit_per_pose_set": result.limits,
        "restart_summary": result.restart_summary,
        "figure2": result.figure2,
        "rows": result.rows,
        "restarts": result.restarts,
    })


def write_study(result: StudyResult, out_dir: str | Path, figures: bool = True) -> dict[str, Any]:
    """Write study.csv, summary.csv, restarts.csv, findings.md, study.json and the figures.

    Returns:
        {name: path} of the files written; ``figures`` is the list of PNG paths.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths: dict[str, Any] = {name: out / file for name, file in (
        ("study", "study.csv"), ("summary", "summary.csv"), ("restarts", "restarts.csv"),
        ("findings", "findings.md"), ("json", "study.json"))}
    write_csv(paths["study"], result.rows, STUDY_COLUMNS)
    write_csv(paths["summary"], result.summary, SUMMARY_COLUMNS)
    write_csv(paths["restarts"], result.restarts, RESTART_COLUMNS)
    paths["findings"].write_text(findings_markdown(result), encoding="utf-8")
    paths["json"].write_text(json.dumps(study_json(result), indent=1, allow_nan=False) + "\n", encoding="utf-8")
    if figures:
        from .study_figures import write_figures  # matplotlib only when drawing

        paths["figures"] = write_figures(result, out)
    return paths


def _fmt(value: float | None, digits: int = 4) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:.{digits}g}"


def findings_markdown(result: StudyResult) -> str:
    """findings.md: the paper's findings on this run, the estimator-vs-limit and restart tables."""
    config = result.config
    lines = [
        "# Simulation study of Franaszek & Marvel (2022), Sections 7-9",
        "",
        f"KUKA LWR 4+ (Table 1), deviation sets {', '.join(config.deviations)} (Table 2); {config.levels} noise "
        f"levels sigma_p [mm] = sigma_a [deg] from 0 to {config.max_sigma:g}; {config.repeats} repeats; "
        f"K_alpha = {config.n_cpa}, K = {config.n_calibration}, J = {config.n_validation}; "
        f"{len(result.rows)} result rows; {result.executor}, {result.wall_s:.1f} s.",
        "",
        "Estimators: " + ", ".join(e.label for e in config.estimators) + " (w in mm²/deg², eq 18). Errors "
        "are eq 24 means over the J test poses, averaged over the repeats (eq 25). *Noisy*: against the noisy "
        "test measurements (`pos_mean_mm`, `rot_mean_deg`; the paper's metric). *Truth*: against the "
        "noise-free test poses (`pos_truth_mean_mm`, `rot_truth_mean_deg`; what the noise limit predicts). "
        "The findings compare the noisy means at the non-zero levels.",
        "",
        "## Findings",
        "",
        "| finding | paper | holds here | evidence |",
        "|---|---|---|---|",
        *(f"| `{f['finding']}` | {f['paper']} | {'yes' if f['holds'] else '**no**'} | {f['evidence']} |"
          for f in result.findings),
        "",
        "## Estimators vs the noise limit",
        "",
        "Error against the noise-free truth (mean ± sd over the repeats, eq 25) beside the linearised "
        "(Cramér–Rao) prediction; positions through Registration 1, orientations through Registration 2 "
        "(Method 1: Registration 1). Ratio 1 = at the limit.",
        "",
        "| deviations | sigma | estimator | pos [mm] | limit [mm] | ratio | rot [deg] | limit [deg] | ratio |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    table = limit_table(result.summary)
    nonzero = [level for level in range(config.levels) if config.sigmas[level] > 0]
    shown = {nonzero[0], nonzero[len(nonzero) // 2], nonzero[-1]} if nonzero else set()
    for row in table:
        if row["level"] in shown:
            label = Estimator.of(row["method"], row["weight"]).label
            lines.append(
                f"| {row['deviations']} | {row['sigma_pos_mm']:.3g} | {label} "
                f"| {_fmt(row['pos_truth_mean_mm'])} ± {_fmt(row['pos_truth_mean_mm_sd'], 2)} "
                f"| {_fmt(row['limit_pos_mm'])} | {_fmt(row['pos_truth_over_limit'], 3)} "
                f"| {_fmt(row['rot_truth_mean_deg'])} ± {_fmt(row['rot_truth_mean_deg_sd'], 2)} "
                f"| {_fmt(row['limit_rot_deg'])} | {_fmt(row['rot_truth_over_limit'], 3)} |"
            )
    lines += ["", "Mean ratio to the limit over the non-zero levels:", "",
              "| deviations | estimator | position | orientation |", "|---|---|---|---|"]
    for deviations in config.deviations:
        for estimator in config.estimators:
            picked = [r for r in table if r["deviations"] == deviations and r["sigma_pos_mm"] > 0
                      and Estimator.of(r["method"], r["weight"]) == estimator]
            pos = np.mean([r["pos_truth_over_limit"] for r in picked]) if picked else math.nan
            rot = np.mean([r["rot_truth_over_limit"] for r in picked]) if picked else math.nan
            lines.append(f"| {deviations} | {estimator.label} | {_fmt(pos, 3)} | {_fmt(rot, 3)} |")
    if result.restart_summary:
        lines += [
            "", "## Restart test", "",
            f"Starts uniform ±{RESTART_SPREAD_DEG:g} deg (eps) and ±{RESTART_SPREAD_MM:g} mm (r, d) around "
            f"Table 1, seeded; same solution = eps within {SAME_SOLUTION_DEG:g} deg and r, d within "
            f"{SAME_SOLUTION_MM:g} mm of the fit from Table 1.", "",
            "| case | deviations | sigma | repeat | seed | estimator | same / starts | failed | "
            "largest eps diff [deg] | largest r,d diff [mm] |",
            "|---|---|---|---|---|---|---|---|---|---|",
            *(f"| {r['case']} | {r['deviations']} | {r['sigma_pos_mm']:.3g} | {r['repeat']} | {r['seed']} | "
              f"{Estimator.of(r['method'], r['weight']).label} | {r['same_solution']} / {r['starts']} | "
              f"{r['failed']} | {_fmt(r['max_deps_deg'], 2)} | {_fmt(r['max_dlength_mm'], 2)} |"
              for r in result.restart_summary),
        ]
    deviations = next(f for f in result.findings if f["finding"] == "largest_parameter_deviations")
    lines += [
        "", "## Largest parameter deviations from the ground truth", "",
        "| estimator | δα [deg] | δε [deg] | δr [mm] | δd [mm] |", "|---|---|---|---|---|",
        "| paper (Section 8) | " + " | ".join(f"{v:g}" for v in PAPER_MAX_DEVIATIONS.values()) + " |",
        *(f"| {label} | " + " | ".join(_fmt(values[c], 3) for c in PAPER_MAX_DEVIATIONS) + " |"
          for label, values in deviations["values"]["by_estimator"].items()),
        "",
    ]
    return "\n".join(lines)
