"""``--level auto`` for several targets on a tree: the level the rows support, by cross-validation.

The rule and the folds are those of one chain (:mod:`pincal.fit.level_choice`): each session held out in
turn with two or more, else the configurations dealt to ten folds of fixed seed; every level
(``registration`` ⊂ ``offsets`` ⊂ ``full`` of the whole tree, :class:`pincal.model.tree_parameters.TreeParameters`)
fitted on the other folds exactly as the final fit (:func:`pincal.fit.tree_calibration.calibrate_tree`, the same
options); the simplest level whose mean held-out error is within one standard error of the lowest (the richest
with ``--select prior``). The held-out error e_f of a fold is the RMS distance of every seen (row, point) pair of
its rows from the model's point [mm] — each target's points through its own chain, occluded points left out —

    e_f = sqrt( mean over seen (k, p) of ‖Ω_s (t_k,t(p) + R_k,t(p) m_p) + τ_s − g_kp‖² )          (T1)

through the training fit's registration (one session), or with two or more through the held-out session's own
registration re-estimated from its seen points with the model and points fixed (Arun et al. 1987: the
least-squares rigid registration of equally weighted points, as ``evaluate --new-session`` does for a tree).
Every fold is refitted (one chain's linearised scoring from 500 rows on, eq L1 of :mod:`pincal.fit.fold_update`,
is not used on a tree).
"""

from __future__ import annotations

import time

import numpy as np

from pincal.errors import CalibrationError
from pincal.fit.chain_calibration import CHAIN_LEVELS, ChainFitOptions
from pincal.fit.folds import DEFAULT_FOLDS, SEED
from pincal.fit.level_choice import Fold, LevelChoice, cross_validate, rule_choice, sensor_setup
from pincal.fit.registration import register_points
from pincal.fit.sessions import where
from pincal.fit.tree_calibration import calibrate_tree, tree_rows
from pincal.measurements.data import MeasurementSet
from pincal.model.parameter_sets import ChainLevel
from pincal.model.tree import KinematicTree
from pincal.progress import Counter, Progress

__all__ = ["choose_tree_level"]


def choose_tree_level(tree: KinematicTree, data: MeasurementSet, options: ChainFitOptions | None = None,  # noqa: PLR0913
                      levels: tuple[ChainLevel, ...] = CHAIN_LEVELS, folds: int = DEFAULT_FOLDS, seed: int = SEED,
                      progress: Progress | None = None) -> LevelChoice:
    """Choose the level of a calibration of ``tree``'s targets on ``data`` (its rows without role ``validation``)
    by cross-validation (module docstring); ``progress`` ticks once per fit (levels × folds). The tree is the same
    on return as on entry.

    Raises:
        CalibrationError: folds that cannot be formed, a held-out session with fewer than 3 seen points, a fold
            that cannot be calibrated even at the simplest level (one line saying what to do).
    """
    started = time.perf_counter()
    options, rows, scheme, fold_list = sensor_setup(data, options, folds, seed, "choose_tree_level")
    several = len(rows.session_names) > 1

    def fit_and_score(level: ChainLevel, fold: Fold) -> tuple[float, int]:
        result = calibrate_tree(tree, rows.select(fold.train), level, options)
        test = rows.select(fold.test)
        measured = tree_rows(tree, test)
        points = result.target.points
        with tree.placed(result.tree_placements):
            world = tree.target_points(test.q, [points[np.array(t.spec.points) - 1] for t in tree.targets])
        seen = measured.seen
        if several:  # a session the fit has not seen: its own registration from its own seen points (T1)
            if int(seen.sum()) < 3:
                raise CalibrationError(f"{where(rows, fold.name)}: {int(seen.sum())} seen point(s); --level auto "
                                       "re-estimates a held-out session's registration from at least 3")
            registration = register_points(world[seen], measured.points[seen])
        else:
            registration = result.target.registrations[0]
        sensed = world @ registration.rotation.T + registration.translation
        distances = np.linalg.norm(sensed - measured.points, axis=2)[seen]
        return float(np.sqrt(np.mean(distances**2))), len(result.kept)

    scores = cross_validate(fold_list, levels, fit_and_score, Counter(progress))
    error = ("RMS distance of the held-out rows' seen target points from the model's [mm] (eq T1), "
             + ("each held-out session through its own registration re-estimated from its seen points (Arun et al. "
                "1987)" if several else "through the training fit's registration (one session)"))
    return rule_choice(scheme, error, fold_list, scores, options.selection, started)
