"""What a simulation study simulates: its constants, :class:`StudyConfig` and the seed rule.

Defaults are the protocol of Section 7 of Franaszek & Marvel (2022). Every
random number of a study comes from a seed that is a pure function of the
root entropy and a spawn key (through :class:`numpy.random.SeedSequence`):
the key of a trial (:func:`task_seed`), of a random start of the restart test
(:func:`restart_start_seed`) or of Figure 2's noise realisation
(:func:`figure2_seed`). Results are therefore identical whatever runs them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pincal.errors import PincalError
from pincal.model.dh.table import DEVIATION_SETS
from pincal.simulation.paper import SimulationSettings
from pincal.study.estimators import ESTIMATORS, Estimator

__all__ = [
    "STUDY_ENTROPY", "RESTART_SPREAD_DEG", "RESTART_SPREAD_MM", "SAME_SOLUTION_DEG", "SAME_SOLUTION_MM",
    "FIGURE2_SIGMA", "FIGURE2_REPEAT", "StudyConfig", "deviation_index", "task_seed", "restart_start_seed",
    "figure2_seed",
]

#: Root entropy of every seed of the study (the paper's article number).
STUDY_ENTROPY = 3680
#: Half-width of the uniform random starts of the restart test: eps [deg], r and d [mm].
RESTART_SPREAD_DEG = 5.0
RESTART_SPREAD_MM = 5.0
#: Two fits reach "the same solution" when every fitted eps agrees within
#: SAME_SOLUTION_DEG [deg] and every fitted r, d within SAME_SOLUTION_MM [mm].
SAME_SOLUTION_DEG = 1e-4
SAME_SOLUTION_MM = 1e-4
#: Figure 2: sigma_p = 0.055 mm, sigma_a = 0.055 deg and the paper's noise realisation i = 14.
FIGURE2_SIGMA = 0.055
FIGURE2_REPEAT = 14

# First entry of a seed's spawn key: what the seed is for.
_TRIAL, _RESTART_START, _FIGURE2 = 0, 1, 2


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


def deviation_index(deviations: str) -> int:
    """Position of a Table 2 deviation set among :data:`pincal.model.dh.table.DEVIATION_SETS`."""
    return list(DEVIATION_SETS).index(deviations)


def task_seed(deviations: str, level: int, repeat: int, entropy: int = STUDY_ENTROPY) -> int:
    """Seed of the trial (deviation set, level index, repeat): a pure function of the key."""
    return _seed(entropy, _TRIAL, deviation_index(deviations), level, repeat)


def restart_start_seed(entropy: int, case: int, estimator_index: int, start: int) -> int:
    """Seed of random start ``start`` of restart case ``case`` for restart estimator ``estimator_index``."""
    return _seed(entropy, _RESTART_START, case, estimator_index, start)


def figure2_seed(deviations: str, entropy: int = STUDY_ENTROPY) -> int:
    """Seed of Figure 2's experiment: deviation set ``deviations``, noise realisation FIGURE2_REPEAT."""
    return _seed(entropy, _FIGURE2, deviation_index(deviations), FIGURE2_REPEAT)
