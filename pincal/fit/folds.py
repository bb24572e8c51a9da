"""Folds over a calibration's rows: configurations dealt at random, whole, to K folds.

A repeated posture must never predict its twin, so rows are grouped by configuration (joint
readings equal within :data:`SAME_CONFIGURATION_RAD`) and the groups are dealt to the folds in a
random order of fixed seed. ``--level auto`` cross-validates the levels over them
(:mod:`pincal.fit.level_choice`), and the prior's estimated scales are checked against the
default scales over them (:mod:`pincal.fit.prior_scales`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["DEFAULT_FOLDS", "SEED", "SAME_CONFIGURATION_RAD", "row_folds", "configuration_keys"]

#: Folds over rows when there is one session or placement (Hastie et al. 2009, §7.10: K = 5 or 10).
DEFAULT_FOLDS = 10
#: Seed of the random order in which configurations are dealt to the folds (fixed: a rerun
#: chooses the same level).
SEED = 0
#: Joint readings that agree to this in every joint are one configuration [rad or m]
#: (0.06°: far below any two postures a calibration plans, above encoder noise).
SAME_CONFIGURATION_RAD = 1e-3


def row_folds(keys: np.ndarray, strata: np.ndarray | None = None, folds: int = DEFAULT_FOLDS,
              seed: int = SEED) -> list[np.ndarray]:
    """Held-out rows of ``folds`` folds: the groups of rows with equal ``keys`` (K, d)
    are dealt to the folds in a random order (``seed``), whole; with ``strata`` (K,),
    each stratum's groups are dealt alike and fold f joins their shares f."""
    rng = np.random.default_rng(seed)
    strata = np.zeros(len(keys), dtype=int) if strata is None else np.asarray(strata)
    group = np.ravel(np.unique(keys, axis=0, return_inverse=True)[1])
    out: list[list[np.ndarray]] = [[] for _ in range(folds)]
    for stratum in dict.fromkeys(strata.tolist()):
        mine = rng.permutation(np.unique(group[strata == stratum]))
        for f, block in enumerate(np.array_split(mine, folds)):
            out[f].append(np.flatnonzero((strata == stratum) & np.isin(group, block)))
    return [np.sort(np.concatenate(parts)) for parts in out]


def configuration_keys(q: np.ndarray) -> np.ndarray:
    """Each row's joint readings on a :data:`SAME_CONFIGURATION_RAD` grid (K, N): repeats of one posture
    share a key unless a reading straddles a grid line (then the twins may land in different folds)."""
    return np.round(np.asarray(q, dtype=float) / SAME_CONFIGURATION_RAD).astype(np.int64)
