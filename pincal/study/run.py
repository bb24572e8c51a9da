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
  linearised noise limit (:func:`pincal.paper.noise_limit.predicted_errors`) predicts.

Means and standard deviations over repeats follow eq 25 (1/N_rep). The
restart test of Section 7 recalibrates a few trials from random starting DH
tables and counts how many reach the solution of the nominal start.

One task is one (deviation set, level, repeat); its seed is a pure function
of that key (:func:`task_seed`, through :class:`numpy.random.SeedSequence`),
so the results are identical seed for seed whatever runs the tasks: this
process, local worker processes or a Dask cluster. Only fit times differ.
:func:`run_study` runs a study, :func:`write_study` writes its files.

Modules: :mod:`pincal.study.estimators` (the estimators),
:mod:`pincal.study.protocol` (constants, :class:`StudyConfig`, seeds),
:mod:`pincal.study.tasks` (what a worker runs), :mod:`pincal.study.executors`
(who runs it), :mod:`pincal.study.tables` (eq 25 and the tables),
:mod:`pincal.study.findings` (the paper's findings),
:mod:`pincal.study.files` and :mod:`pincal.study.figures` (the output).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from pincal.study.checkpoints import TaskStore
from pincal.study.estimators import ESTIMATORS, RESTART_ESTIMATORS, Estimator
from pincal.study.executors import Progress, execute
from pincal.study.files import write_study
from pincal.study.findings import check_findings
from pincal.study.protocol import (
    FIGURE2_REPEAT,
    RESTART_SPREAD_DEG,
    RESTART_SPREAD_MM,
    StudyConfig,
    figure2_seed,
    task_seed,
)
from pincal.study.result import StudyResult
from pincal.study.tables import (
    STUDY_COLUMNS,
    SUMMARY_COLUMNS,
    summarize,
    summarize_restarts,
)
from pincal.study.tasks import (
    Figure2Task,
    LimitTask,
    RestartTask,
    TrialTask,
    noise_free_test_set,
    parameter_deviations,
    random_start,
)

__all__ = [
    "ESTIMATORS", "FIGURE2_REPEAT", "RESTART_SPREAD_DEG", "RESTART_SPREAD_MM", "STUDY_COLUMNS",
    "SUMMARY_COLUMNS", "Estimator", "StudyConfig", "StudyResult", "noise_free_test_set",
    "parameter_deviations", "random_start", "restart_cases", "run_study", "study_tasks", "task_seed",
    "write_study",
]

_RESTART_CHUNK = 50  # restarts per task

#: The default protocol of :func:`run_study`: the paper's (frozen, so one shared instance is safe).
DEFAULT_STUDY_CONFIG = StudyConfig()


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
    tasks.append(Figure2Task(config, figure2, figure2_seed(figure2, config.entropy)))
    return tasks


def run_study(
    config: StudyConfig = DEFAULT_STUDY_CONFIG,
    workers: int | None = None,
    scheduler: Any = None,
    progress: Progress | None = None,
    checkpoints: str | Path | None = None,
) -> StudyResult:
    """Run the simulation study of Section 7 and check the findings of Sections 8–9.

    Args:
        config: the protocol (defaults: the paper's).
        workers: local worker processes (default all cores; 1 = this process).
        scheduler: Dask scheduler address, ``"local"``, a ``distributed.Client``, or None.
        progress: ``progress(done, total)`` callback.
        checkpoints: folder keeping each finished task, reused by a rerun after a
            crash (:mod:`pincal.study.checkpoints`); None keeps nothing.
    """
    started = time.perf_counter()
    tasks = study_tasks(config)
    store = None if checkpoints is None else TaskStore(checkpoints)
    results, executor = execute(tasks, workers, scheduler, progress, store)
    by_kind: dict[type, list] = {TrialTask: [], RestartTask: [], Figure2Task: [], LimitTask: []}
    for task, rows in sorted(zip(tasks, results), key=lambda pair: pair[0].key):
        by_kind[type(task)].extend(rows)
    summary = summarize(by_kind[TrialTask], by_kind[LimitTask])
    restart_summary = summarize_restarts(by_kind[RestartTask])
    return StudyResult(
        config=config,
        rows=by_kind[TrialTask],
        limits=by_kind[LimitTask],
        restarts=by_kind[RestartTask],
        restart_summary=restart_summary,
        figure2=by_kind[Figure2Task],
        summary=summary,
        findings=check_findings(summary, by_kind[TrialTask], restart_summary, config),
        executor=executor,
        wall_s=time.perf_counter() - started,
    )
