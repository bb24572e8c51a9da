"""Which level the data support: ``--level auto``, by cross-validation.

The levels ``registration`` ⊂ ``offsets`` ⊂ ``full`` of
:mod:`pincal.fit.chain_calibration` are nested: a richer level always fits the
calibration rows at least as well, and on new rows it may do worse (weakly
determined parameters fitted to noise and to what no level models). Which
level generalises is measured, not assumed:

1. **Folds.** With two or more sessions (sensor data) or placements (socket
   fixture), each is held out in turn (leave-one-session-out,
   leave-one-placement-out). With one, the rows are grouped by configuration
   (joint readings equal within :data:`SAME_CONFIGURATION_RAD`), so a repeated
   posture never predicts its twin, and the groups are dealt to
   :data:`DEFAULT_FOLDS` folds in a random order of fixed seed (:data:`SEED`;
   leave-one-configuration-out below that many); with a fixture, each
   socket's groups are dealt alike. Ten folds, not five: each training part
   then has 90 % of the rows, and near the number of rows a level needs its
   error falls steeply with the rows (simulated UR5, 12 rows, full level true:
   5 folds chose offsets in 4 of 4 seeds, 10 folds the full level in 4 of 4,
   whose held-out error was 2.5-3 times lower).
2. **Held-out error** e_f of fold f, for every level: the level is fitted on
   the other folds (selection, outliers, weights as the final fit), then on the
   held-out rows
   * sensor, held-out session: its own registration (6 parameters, model and
     target fixed, :func:`pincal.fit.sessions.register_session`) is fitted to
     its rows, as ``pincal evaluate`` does for a new session; e_f is the RMS
     distance between measured and predicted target points [mm];
   * sensor, held-out rows of the one session: through the fit's registration;
   * fixture, held-out placement: its own fixture pose (c, R) is fitted to its
     rows, with the model and the ball centre fixed; e_f is the RMS of eq F1,
     sqrt(mean_k ‖p_k − c − R f_i‖²) [mm] — the consistency and, through the
     socket means, the distortion (:func:`fixture_heldout_error`);
   * fixture, held-out rows of the one placement: distance from the fitted socket centres.
3. **The one-standard-error rule** (Breiman, Friedman, Olshen & Stone 1984, ch. 3; Hastie,
   Tibshirani & Friedman 2009, §7.10): CV = mean of e_f over the F folds,
   SE = sample std of e_f / sqrt(F). The chosen level is the simplest whose CV is
   within one SE of the lowest CV (:func:`one_standard_error`). With ``--select prior`` the
   richest such level (:data:`RULE_PRIOR`): each level then keeps every identifiable
   parameter under physical priors, so a simpler level is not a smaller fit but a
   narrower prior (zero width on the placements it leaves out), and is chosen only
   when its CV is lower by more than the SE.

From :data:`pincal.fit.fold_update.LINEARISED_FROM_ROWS` rows on (one session), each level is
fitted once on all rows and its folds are scored by one Gauss–Newton step (eq L1 there).

:func:`choose_level` (sensor data) and :func:`choose_fixture_level` return a
:class:`LevelChoice`; the caller then calibrates all rows at the chosen level.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from pincal.errors import CalibrationError, expect_value
from pincal.fit.chain_calibration import CHAIN_LEVELS, ChainFitOptions, calibrate_chain
from pincal.fit.fixture_calibration import calibrate_fixture
from pincal.fit.fold_update import LINEARISED_FROM_ROWS, linearised_levels
from pincal.fit.folds import DEFAULT_FOLDS, SAME_CONFIGURATION_RAD, SEED, configuration_keys, row_folds
from pincal.fit.metrics import pose_errors
from pincal.fit.prior import Prior
from pincal.fit.selection import SelectionCriterion
from pincal.fit.sessions import register_session, where
from pincal.measurements.data import MeasurementSet
from pincal.measurements.fixture import MIN_ROWS_PER_SOCKET, FixtureData
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import ChainLevel
from pincal.progress import Counter, Progress

__all__ = [
    "DEFAULT_FOLDS", "SEED", "SAME_CONFIGURATION_RAD", "MIN_TRAINING_ROWS", "MIN_CONFIGURATIONS",
    "MIN_HELD_OUT_COORDINATES", "RULE", "RULE_PRIOR", "Fold", "LevelScore", "LevelChoice", "one_standard_error",
    "row_folds", "configuration_keys", "sensor_folds", "choose_level", "fixture_heldout_error", "fixture_rows",
    "fixture_folds", "choose_fixture_level", "placement_error", "cross_validate", "rule_choice",
    "sensor_setup",
]

#: Fewest rows a fold may calibrate on (a calibration needs 3: pincal.fit.chain_calibration).
MIN_TRAINING_ROWS = 3
#: Fewest configurations of one session to cross-validate over (one held out leaves 4 to fit).
MIN_CONFIGURATIONS = 5
#: A held-out session must leave at least as many coordinates as its registration has
#: unknowns (6) after re-estimating it: 12 measured coordinates (4 point rows, 2 pose rows).
MIN_HELD_OUT_COORDINATES = 12

RULE = ("the simplest level whose mean held-out error over the folds is within one standard error "
        "(std over folds / sqrt(folds)) of the lowest (one-standard-error rule)")
#: With --select prior (pincal.fit.prior) every level keeps all its identifiable parameters under
#: physical priors, and a simpler level is the richer one with those priors shrunk to zero width
#: (its placements claimed exact): the richest level is the model, and a simpler one is chosen
#: only when its CV is lower by more than the lowest CV's standard error.
RULE_PRIOR = ("with --select prior, the richest level whose mean held-out error over the folds is within one "
              "standard error (std over folds / sqrt(folds)) of the lowest (one-standard-error rule, richest "
              "first: the priors already shrink what the data do not support)")


@dataclass(frozen=True)
class Fold:
    """One split: ``train`` and ``test`` index the rows given to the chooser."""

    name: str
    train: np.ndarray
    test: np.ndarray


@dataclass(frozen=True)
class LevelScore:
    """One level's cross-validated error.

    Attributes:
        level: ``registration``, ``offsets`` or ``full``.
        fold_errors_mm: e_f per fold [mm] (NaN where the fit failed).
        kept: kinematic parameters kept per fold (-1 where the fit failed).
        cv_error_mm: mean of e_f [mm] (inf if a fold failed: not a candidate).
        standard_error_mm: std of e_f (ddof 1) / sqrt(F) [mm].
        failures: why a fold's fit failed, one text per failure.
    """

    level: ChainLevel
    fold_errors_mm: tuple[float, ...]
    kept: tuple[int, ...]
    cv_error_mm: float
    standard_error_mm: float
    failures: tuple[str, ...] = ()

    def as_dict(self) -> dict[str, Any]:
        finite = np.isfinite(self.cv_error_mm)
        return {
            "level": self.level,
            "cv_error_mm": float(self.cv_error_mm) if finite else None,
            "standard_error_mm": float(self.standard_error_mm) if finite else None,
            "fold_errors_mm": [float(e) if np.isfinite(e) else None for e in self.fold_errors_mm],
            "kept_parameters": [int(k) if k >= 0 else None for k in self.kept],
            "failures": list(self.failures),
        }


@dataclass(frozen=True)
class LevelChoice:
    """Outcome of :func:`choose_level` / :func:`choose_fixture_level`.

    Attributes:
        scheme: how the folds were made (``leave-one-session-out``, ``leave-one-placement-out``,
            ``leave-one-configuration-out``, ``10-fold over configurations (seed 0)``).
        error: what e_f measures, in words.
        folds: the folds (names and row indices).
        scores: one per level, simplest first.
        lowest: the level of lowest CV error.
        chosen: the level the rule picks.
        threshold_mm: lowest CV + its SE [mm].
        selection: the criterion choosing the kept parameters within each level.
        seconds: wall time [s].
        rule: how ``chosen`` follows from the scores (:data:`RULE`, or :data:`RULE_PRIOR` with ``prior``).
    """

    scheme: str
    error: str
    folds: tuple[Fold, ...]
    scores: tuple[LevelScore, ...]
    lowest: ChainLevel
    chosen: ChainLevel
    threshold_mm: float
    selection: SelectionCriterion | Prior
    seconds: float
    rule: str = RULE

    def as_dict(self) -> dict[str, Any]:
        """REPORT.json's ``level_choice``."""
        return {
            "rule": self.rule,
            "scheme": self.scheme,
            "error": self.error,
            "selection": self.selection,
            "folds": [{"name": f.name, "held_out_rows": int(f.test.size), "training_rows": int(f.train.size)}
                      for f in self.folds],
            "levels": [s.as_dict() for s in self.scores],
            "lowest": self.lowest,
            "threshold_mm": self.threshold_mm,
            "chosen": self.chosen,
            "seconds": self.seconds,
        }


def one_standard_error(errors: npt.ArrayLike, standard_errors: npt.ArrayLike,
                       richest: bool = False) -> tuple[int, int, float]:
    """The one-standard-error rule over candidates ordered simplest first.

    Args:
        errors: mean held-out error of each candidate (inf or NaN: not a candidate).
        standard_errors: the standard error of each mean.
        richest: choose the richest candidate within the threshold instead of the simplest
            (:data:`RULE_PRIOR`).

    Returns:
        (index of the lowest error, index chosen, threshold = lowest + its SE).

    Raises:
        CalibrationError: no candidate has a finite error.
    """
    errors = np.asarray(errors, dtype=float)
    spreads = np.nan_to_num(np.asarray(standard_errors, dtype=float), nan=0.0)
    finite = np.isfinite(errors)
    if not finite.any():
        raise CalibrationError("no level could be fitted on every fold of the cross-validation")
    lowest = int(np.argmin(np.where(finite, errors, np.inf)))
    threshold = float(errors[lowest] + spreads[lowest])
    chosen = int(np.flatnonzero(finite & (errors <= threshold))[-1 if richest else 0])
    return lowest, chosen, threshold


def _score(level: ChainLevel, errors: list[float], kept: list[int], failures: list[str]) -> LevelScore:
    values = np.array(errors, dtype=float)
    ok = np.all(np.isfinite(values))
    mean = float(values.mean()) if ok else np.inf
    se = float(values.std(ddof=1) / np.sqrt(values.size)) if ok and values.size > 1 else (0.0 if ok else np.inf)
    return LevelScore(level, tuple(values.tolist()), tuple(kept), mean, se, tuple(failures))


def rule_choice(scheme: str, error: str, folds: Sequence[Fold], scores: Sequence[LevelScore],
                selection: SelectionCriterion | Prior, started: float) -> LevelChoice:
    """The :class:`LevelChoice` of ``scores`` by :func:`one_standard_error` (the richest within it with ``prior``)."""
    richest = selection == "prior"
    lowest, chosen, threshold = one_standard_error([s.cv_error_mm for s in scores],
                                                   [s.standard_error_mm for s in scores], richest)
    return LevelChoice(scheme, error, tuple(folds), tuple(scores), scores[lowest].level, scores[chosen].level,
                       threshold, selection, time.perf_counter() - started, RULE_PRIOR if richest else RULE)


def cross_validate(folds: Sequence[Fold], levels: Sequence[ChainLevel],
                   fit_and_score: Callable[[ChainLevel, Fold], tuple[float, int]], counter: Counter
                   ) -> list[LevelScore]:
    """e_f of every level on every fold; ``fit_and_score(level, fold)`` → (e_f [m], kept)."""
    counter.expect(len(folds) * len(levels))
    scores = []
    for level in levels:
        errors, kept, failures = [], [], []
        for fold in folds:
            try:
                error, n_kept = fit_and_score(level, fold)
            except CalibrationError as exc:
                if level == levels[0]:
                    raise CalibrationError(f"--level auto: fold '{fold.name}' ({fold.train.size} training rows) "
                                           f"cannot be calibrated even at level {level}: {exc}") from None
                error, n_kept = np.nan, -1
                failures.append(f"{fold.name}: {exc}")
            finally:
                counter.tick()
            errors.append(error * 1000.0)
            kept.append(n_kept)
        scores.append(_score(level, errors, kept, failures))
    return scores


# --- sensor data -------------------------------------------------------------------------------


def sensor_folds(data: MeasurementSet, folds: int = DEFAULT_FOLDS, seed: int = SEED) -> tuple[str, list[Fold]]:
    """The folds of ``data`` (its calibration rows): one per session with two or more,
    else ``folds`` random deals of its configurations (fewer: one per configuration).

    Raises:
        CalibrationError: a session with too few coordinates to be held out, or
            one session with fewer than :data:`MIN_CONFIGURATIONS` configurations.
    """
    everything = np.arange(data.n_rows)
    names = data.session_names
    per_row = 3 * data.n_points + (3 if data.has_orientation else 0)
    if len(names) > 1:
        out = []
        for s, name in enumerate(names):
            test = np.flatnonzero(data.session_index == s)
            if test.size * per_row < MIN_HELD_OUT_COORDINATES:
                raise CalibrationError(
                    f"{where(data, name)}: {test.size} row(s); --level auto holds out each session in turn and "
                    f"re-estimates its registration (6 parameters) from its own rows, which needs at least "
                    f"{MIN_HELD_OUT_COORDINATES} measured coordinates ({-(-MIN_HELD_OUT_COORDINATES // per_row)} rows "
                    f"here) to leave any for the error; add rows, give the rows the session of others if the "
                    "sensor did not move, or choose the level (--level offsets)")
            train = np.setdiff1d(everything, test)
            if train.size < MIN_TRAINING_ROWS:
                raise CalibrationError(
                    f"{where(data, name)}: holding this session out leaves {train.size} row(s) to calibrate on "
                    f"(--level auto needs at least {MIN_TRAINING_ROWS}); add rows to the other sessions, merge "
                    "sessions whose sensor did not move, or choose the level (--level offsets)")
            out.append(Fold(name, train, test))
        return "leave-one-session-out", out
    keys = configuration_keys(data.q)
    n_configurations = len(np.unique(keys, axis=0))
    if n_configurations < MIN_CONFIGURATIONS:
        raise CalibrationError(
            f"{data.source}: {n_configurations} distinct configuration(s) in one session; --level auto holds "
            f"configurations out in turn and needs at least {MIN_CONFIGURATIONS} (or two sessions); add rows "
            "or choose the level (--level offsets)")
    folds = min(folds, n_configurations)
    blocks = row_folds(keys, folds=folds, seed=seed)
    out = [Fold(f"fold {f + 1}", np.setdiff1d(everything, b), b) for f, b in enumerate(blocks)]
    if folds == n_configurations:
        return "leave-one-configuration-out", out
    return f"{folds}-fold over configurations (seed {seed})", out


def sensor_setup(data: MeasurementSet, options: ChainFitOptions | None, folds: int, seed: int, caller: str
                 ) -> tuple[ChainFitOptions, MeasurementSet, str, list[Fold]]:
    """What a sensor calibration's level choice starts from: its options (the default's when None, checked), the
    rows of ``data`` without role ``validation`` and their folds (:func:`sensor_folds`)."""
    options = ChainFitOptions() if options is None else options
    expect_value(options, ChainFitOptions, caller)
    rows = data.select(np.flatnonzero(data.roles != "validation"))
    return (options, rows, *sensor_folds(rows, folds, seed))


def choose_level(
    chain: KinematicChain,
    data: MeasurementSet,
    options: ChainFitOptions | None = None,
    levels: tuple[ChainLevel, ...] = CHAIN_LEVELS,
    folds: int = DEFAULT_FOLDS,
    seed: int = SEED,
    progress: Progress | None = None,
) -> LevelChoice:
    """Choose the level of a sensor calibration by cross-validation (module docstring).

    ``options``: how each level is fitted (:func:`pincal.fit.chain_calibration.calibrate_chain`'s; default
    :class:`pincal.fit.chain_calibration.ChainFitOptions`'s);
    rows with role ``validation`` are not used. The chain's placements are the
    same on return as on entry. ``progress`` ticks once per fit (levels × folds).

    Raises:
        CalibrationError: folds that cannot be formed or fitted (one line saying what to do).
    """
    started = time.perf_counter()
    options, rows, scheme, fold_list = sensor_setup(data, options, folds, seed, "choose_level")
    several = len(rows.session_names) > 1

    def fit_and_score(level: ChainLevel, fold: Fold) -> tuple[float, int]:
        result = calibrate_chain(chain, rows.select(fold.train), level, options)
        test = rows.select(fold.test)
        target = result.target
        registration = target.registrations[0]
        with chain.placed(result.chain_placements):
            if several:  # a session the fit has not seen: its own registration from its own rows
                registration = register_session(chain, test, target.points, target.rotation,
                                                sigma_pos_m=result.sigma_pos_m,
                                                sigma_rot_rad=result.sigma_rot_rad or 1e-3)
            errors = pose_errors(chain, test, registration, registration, points=target.points,
                                 target_rotation=target.rotation)
        return float(np.sqrt(np.mean(errors.position_m**2))), len(result.kept)

    if several or options.reject_outliers or rows.n_rows < LINEARISED_FROM_ROWS:
        scores = cross_validate(fold_list, levels, fit_and_score, Counter(progress))
    else:  # many rows: one fit per level, each fold by one Gauss–Newton step (pincal.fit.fold_update, eq L1)
        scores = _linearised(chain, rows, fold_list, levels, Counter(progress), options)
        scheme += f", scored from the fit of all {rows.n_rows} rows by one Gauss–Newton step per fold (eq L1)"
    error = ("RMS distance of the held-out rows' target points from the model's [mm], "
             + ("each held-out session through its own registration re-estimated from its rows (6 parameters)"
                if several else "through the training fit's registration (one session)"))
    return rule_choice(scheme, error, fold_list, scores, options.selection, started)


def _linearised(chain: KinematicChain, rows: MeasurementSet, folds: Sequence[Fold], levels: Sequence[ChainLevel],
                counter: Counter, options: ChainFitOptions) -> list[LevelScore]:
    """Eq L1 of :mod:`pincal.fit.fold_update` for every level (its fit of all rows, then each fold)."""
    return [_score(*entry) for entry in linearised_levels(chain, rows, [fold.test for fold in folds], levels,
                                                          counter, options)]


# --- socket fixture ----------------------------------------------------------------------------


def fixture_heldout_error(chain: KinematicChain, data: FixtureData, ball: npt.ArrayLike) -> np.ndarray:
    """RMS of eq F1 of each placement of ``data`` [m], (S,), with the chain as it is, the
    ball centre ``ball`` (3,) [m] in its tool frame, and the placement's own fixture pose
    fitted to its rows.

    With p_k the ball centre of row k, p̄_i the mean of socket i's n_i rows,
    min over (c, R) of Σ_k ‖p_k − c − R f_i‖² = Σ_k ‖p_k − p̄_i‖² + min Σ_i n_i ‖p̄_i − c − R f_i‖²:
    the within-socket spread (the consistency) plus a weighted Procrustes fit of the
    socket means to the fixture (the distortion); c is the weighted centroid and R
    solves Wahba's problem (scipy's ``Rotation.align_vectors``; for collinear
    sockets the turn about their line is arbitrary and changes nothing).
    """
    poses = chain.poses(data.q)
    p = poses.tool_positions + poses.tool_rotations @ np.asarray(ball, dtype=float)
    out = []
    for s in range(len(data.placements)):
        mine = data.placement == s
        sockets, counts = np.unique(data.socket[mine], return_counts=True)
        means = np.array([p[mine & (data.socket == i)].mean(axis=0) for i in sockets])
        spread = sum(float(np.sum((p[mine & (data.socket == i)] - m) ** 2)) for i, m in zip(sockets, means))
        f = data.fixture.points[sockets]
        w = counts / counts.sum()
        a, b = means - w @ means, f - w @ f
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # collinear sockets: the turn about the line is free
            rotation, _ = Rotation.align_vectors(a, b, weights=counts)
        misfit = float(np.sum(counts * np.sum((a - rotation.apply(b)) ** 2, axis=1)))
        out.append(np.sqrt((spread + misfit) / counts.sum()))
    return np.array(out)


def placement_error(chain: KinematicChain, data: FixtureData, level: ChainLevel, placement: str,
                    selection: SelectionCriterion | Prior = "aic") -> tuple[float, int]:
    """Placement ``placement`` of ``data`` predicted by the calibration (``level``, ``selection``) of the
    others: (its :func:`fixture_heldout_error` [m], the kinematic parameters kept). Level
    ``registration`` is the nominal model with the ball centre fitted on the others.

    Raises:
        CalibrationError: the other placements cannot be calibrated at ``level``.
    """
    train = data.select_placements([name for name in data.placements if name != placement])
    result = calibrate_fixture(chain, train, level, selection=selection)
    test = data.select_placements([placement])
    with chain.placed(result.chain_placements):
        return float(fixture_heldout_error(chain, test, result.ball)[0]), len(result.kept)


def fixture_rows(data: FixtureData, index: np.ndarray) -> FixtureData:
    """The rows ``index`` of ``data`` (every placement kept)."""
    index = np.asarray(index, dtype=np.intp)
    return FixtureData(data.joint_names, data.q[index], data.socket[index], data.placement[index], data.placements,
                       data.fixture, data.lines[index], data.files[index], data.sources)


def fixture_folds(data: FixtureData, folds: int = DEFAULT_FOLDS, seed: int = SEED) -> tuple[str, list[Fold]]:
    """One fold per placement with two or more, else ``folds`` deals of each socket's configurations.

    Raises:
        CalibrationError: one placement with a socket of fewer than 2 × :data:`MIN_ROWS_PER_SOCKET`
            rows (each training part must keep that many of every socket).
    """
    everything = np.arange(data.n_rows)
    if len(data.placements) > 1:
        return "leave-one-placement-out", [
            Fold(name, np.flatnonzero(data.placement != s), np.flatnonzero(data.placement == s))
            for s, name in enumerate(data.placements)]
    sockets, counts = np.unique(data.socket, return_counts=True)
    least = 2 * MIN_ROWS_PER_SOCKET  # n - ceil(n / K) >= MIN_ROWS_PER_SOCKET for any K >= 2
    if counts.min() < least:
        socket = data.fixture.names[sockets[np.argmin(counts)]]
        raise CalibrationError(
            f"{', '.join(data.sources)}: one placement, and socket '{socket}' has {counts.min()} row(s); "
            "--level auto then holds out a share of each socket's rows in turn and needs at least "
            f"{least} per socket (or two placements); add rows or choose the level (--level offsets)")
    keys = configuration_keys(data.q)
    folds = min(folds, max(len(np.unique(keys[data.socket == i], axis=0)) for i in sockets))
    blocks = row_folds(keys, data.socket, folds, seed)
    for block in blocks:  # repeated postures are dealt whole, so a share can exceed n / K
        kept = np.bincount(data.socket[np.setdiff1d(everything, block)], minlength=len(data.fixture.names))
        short = [i for i in sockets if kept[i] < MIN_ROWS_PER_SOCKET]
        if short:
            socket = data.fixture.names[short[0]]
            n_distinct = len(np.unique(keys[data.socket == short[0]], axis=0))
            raise CalibrationError(
                f"{', '.join(data.sources)}: one placement, and socket '{socket}' has only {n_distinct} distinct "
                f"configuration(s); holding a share out leaves {kept[short[0]]} of its rows, and --level auto "
                f"needs {MIN_ROWS_PER_SOCKET}; seat the ball in more postures, add a placement, or choose the "
                "level (--level offsets)")
    return f"{folds}-fold over each socket's configurations (seed {seed})", [
        Fold(f"fold {f + 1}", np.setdiff1d(everything, b), b) for f, b in enumerate(blocks)]


def choose_fixture_level(
    chain: KinematicChain,
    data: FixtureData,
    selection: SelectionCriterion | Prior = "aic",
    levels: tuple[ChainLevel, ...] = CHAIN_LEVELS,
    folds: int = DEFAULT_FOLDS,
    seed: int = SEED,
    progress: Progress | None = None,
) -> LevelChoice:
    """Choose the level of a socket-fixture calibration by cross-validation (module docstring).

    The chain's placements are the same on return as on entry.
    """
    started = time.perf_counter()
    scheme, fold_list = fixture_folds(data, folds, seed)
    several = len(data.placements) > 1

    def fit_and_score(level: ChainLevel, fold: Fold) -> tuple[float, int]:
        if several:
            return placement_error(chain, data, level, fold.name, selection)
        result = calibrate_fixture(chain, fixture_rows(data, fold.train), level, selection=selection)
        test = fixture_rows(data, fold.test)
        placement = result.placements[0]
        centres = dict(zip(placement.sockets, placement.socket_positions))
        with chain.placed(result.chain_placements):
            poses = chain.poses(test.q)
        p = poses.tool_positions + poses.tool_rotations @ result.ball
        c = np.array([centres[data.fixture.names[i]] for i in test.socket])
        return float(np.sqrt(np.mean(np.sum((p - c) ** 2, axis=1)))), len(result.kept)

    scores = cross_validate(fold_list, levels, fit_and_score, Counter(progress))
    error = ("RMS of eq F1 on the held-out placement [mm], its own fixture pose fitted to its rows with the "
             "model and the ball centre fixed (consistency and distortion in one number)" if several else
             "RMS distance of the held-out rows' ball centre from its socket's fitted centre [mm]")
    return rule_choice(scheme, error, fold_list, scores, selection, started)
