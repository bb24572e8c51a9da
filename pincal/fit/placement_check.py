"""Whether a socket-fixture calibration predicts a placement it has not seen better than the nominal model.

A placement's pose is its own unknown, so no model predicts where a new placement's sockets are;
what it predicts is how *consistent* the ball positions of that placement's rows are with the
fixture once only the placement's own pose (c, R) is fitted to them, model and ball centre fixed:

    e_s = sqrt(mean_k ‖p_k − c − R f_i(k)‖²)   [mm]          (eq F1 over placement s's rows, (c, R) refitted)

the consistency and, through the socket means, the distortion in one number
(:func:`pincal.fit.level_choice.fixture_heldout_error`, the error ``--level auto`` chooses by).

**Leave-one-placement-out.** With two or more placements each is left out in turn and predicted
by two models fitted on the others' rows only:

* *calibrated* — the calibration at the level (and ``--select``) of the final fit;
* *nominal* — the URDF as given, with the ball centre fitted on the same placements
  (level ``registration``: the "before" of a calibration).

A placement whose calibrated e_s exceeds the nominal one by more than the noise of an RMS over
its K_s rows allows — the ratio above 1 + 2/sqrt(2 K_s), two standard errors of an RMS over K_s
rows (relative standard error 1/sqrt(2K) for Gaussian errors), the bound of the sensor path's
leave-one-row-out comparison (:mod:`pincal.fit.plausibility`) — is a finding
(``held_out_placement``): the calibration fits something that does not carry over to other
placements (too few sockets or postures per placement for the level's parameters, or an effect
the model lacks that differs between placements). Both e_s are computed on the same rows, which
makes their ratio's noise smaller than that bound assumes: it errs towards silence. The final
model is fitted on every placement, one more than each of these, so the check judges the level
on a little less data than the model it warns about.

With one placement nothing can be left out: a note says so and what to measure.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pincal.errors import CalibrationError
from pincal.fit.level_choice import LevelChoice, placement_error
from pincal.fit.plausibility import Finding
from pincal.fit.prior import Prior
from pincal.fit.selection import SelectionCriterion
from pincal.measurements.fixture import FixtureData
from pincal.model.chain import KinematicChain
from pincal.model.parameter_sets import ChainLevel

__all__ = [
    "PREDICTED_ERROR", "PlacementPrediction", "PlacementCheck", "worse_bound", "predictions", "check_placements",
    "placement_findings", "evaluation_findings", "one_placement_note",
]

#: What e_s is, in words (REPORT.json ``fixture.held_out_placements.error``).
PREDICTED_ERROR = ("RMS distance of the ball from its sockets on the left-out placement's rows [mm], only that "
                   "placement's own fixture pose fitted to them (model and ball centre fixed): consistency and "
                   "distortion in one number")


def worse_bound(rows: int) -> float:
    """The ratio calibrated / nominal e_s above which a placement of ``rows`` rows is predicted worse:
    1 + 2/sqrt(2 rows), two standard errors of an RMS over that many rows (module docstring)."""
    return 1.0 + 2.0 / np.sqrt(2.0 * max(int(rows), 1))


@dataclass(frozen=True)
class PlacementPrediction:
    """One placement predicted by models that have not seen it.

    Attributes:
        placement: its name.
        rows: its rows.
        calibrated_mm: e_s of the calibrated model [mm] (NaN: not fitted, see ``failure``).
        nominal_mm: e_s of the nominal model [mm].
        failure: why the calibrated model could not be fitted without this placement, else None.
    """

    placement: str
    rows: int
    calibrated_mm: float
    nominal_mm: float
    failure: str | None = None

    @property
    def ratio(self) -> float:
        """calibrated / nominal (NaN when either is missing)."""
        if not (np.isfinite(self.calibrated_mm) and np.isfinite(self.nominal_mm)) or self.nominal_mm <= 0.0:
            return float("nan")
        return self.calibrated_mm / self.nominal_mm

    @property
    def bound(self) -> float:
        return worse_bound(self.rows)

    @property
    def worse(self) -> bool:
        """Predicted worse than by the nominal model, beyond the noise of its rows (:func:`worse_bound`)."""
        return bool(np.isfinite(self.ratio) and self.ratio > self.bound)

    def as_dict(self) -> dict[str, Any]:
        finite = np.isfinite(self.ratio)
        return {"placement": self.placement, "rows": self.rows,
                "nominal_mm": float(self.nominal_mm) if np.isfinite(self.nominal_mm) else None,
                "calibrated_mm": float(self.calibrated_mm) if np.isfinite(self.calibrated_mm) else None,
                "ratio": float(self.ratio) if finite else None, "bound": self.bound, "worse": self.worse,
                "failure": self.failure}


@dataclass(frozen=True)
class PlacementCheck:
    """Leave-one-placement-out of a calibration at ``level`` (module docstring)."""

    level: ChainLevel
    placements: tuple[PlacementPrediction, ...]

    @property
    def worse(self) -> tuple[PlacementPrediction, ...]:
        return tuple(p for p in self.placements if p.worse)

    def as_dict(self) -> dict[str, Any]:
        """REPORT.json's ``fixture.held_out_placements``."""
        return {"scheme": "leave-one-placement-out", "level": self.level, "error": PREDICTED_ERROR,
                "rule": "warned when calibrated / nominal > 1 + 2/sqrt(2 rows) (two standard errors of an RMS)",
                "placements": [p.as_dict() for p in self.placements]}


def predictions(data: FixtureData, calibrated_m: npt.ArrayLike, nominal_m: npt.ArrayLike,
                failures: Sequence[str | None] | None = None) -> tuple[PlacementPrediction, ...]:
    """One :class:`PlacementPrediction` per placement of ``data`` from e_s [m] of each model, (S,) each."""
    calibrated = np.asarray(calibrated_m, dtype=float) * 1000.0
    nominal = np.asarray(nominal_m, dtype=float) * 1000.0
    failures = failures or [None] * len(data.placements)
    return tuple(PlacementPrediction(name, int(np.sum(data.placement == s)), float(calibrated[s]),
                                     float(nominal[s]), failures[s]) for s, name in enumerate(data.placements))


def _from_choice(choice: LevelChoice | None, level: ChainLevel, data: FixtureData
                 ) -> tuple[list[float], list[float], list[str | None]] | None:
    """The fold errors [m] of ``level`` and of the nominal model (and the failures) that ``--level auto``
    already computed on these placements, or None when it did not."""
    if choice is None or [f.name for f in choice.folds] != list(data.placements):
        return None
    scores = {s.level: s for s in choice.scores}
    if level not in scores or "registration" not in scores:
        return None
    mine = scores[level]
    failures = [next((text for text in mine.failures if text.startswith(f"{name}: ")), None)
                if not np.isfinite(e) else None for name, e in zip(data.placements, mine.fold_errors_mm)]
    return ([e / 1000.0 for e in mine.fold_errors_mm], [e / 1000.0 for e in scores["registration"].fold_errors_mm],
            failures)


def check_placements(chain: KinematicChain, data: FixtureData, level: ChainLevel,
                     selection: SelectionCriterion | Prior = "aic",
                     choice: LevelChoice | None = None) -> PlacementCheck | None:
    """Leave-one-placement-out of a calibration of ``data`` at ``level`` with ``selection`` (module
    docstring); None with fewer than two placements or at level ``registration`` (the nominal model:
    nothing to compare). ``choice``: the ``--level auto`` choice made on the same rows and placements,
    whose fold errors are these (nothing is refitted). The chain's placements are the same on return.
    """
    if len(data.placements) < 2 or level == "registration":
        return None
    known = _from_choice(choice, level, data)
    if known is None:
        calibrated: list[float] = []
        nominal: list[float] = []
        failures: list[str | None] = []
        for name in data.placements:
            nominal.append(placement_error(chain, data, "registration", name, selection)[0])
            try:
                calibrated.append(placement_error(chain, data, level, name, selection)[0])
                failures.append(None)
            except CalibrationError as exc:
                calibrated.append(np.nan)
                failures.append(str(exc))
        known = (calibrated, nominal, failures)
    return PlacementCheck(level, predictions(data, *known))


def placement_findings(check: PlacementCheck | None) -> tuple[list[Finding], list[str]]:
    """(warnings, notes) of a check: one ``held_out_placement`` finding naming every placement the
    calibrated model predicts worse than the nominal one; a note per placement it could not be fitted without."""
    if check is None:
        return [], []
    notes = [f"placement {p.placement}: the other placements alone cannot be calibrated at level {check.level} "
             f"({p.failure}), so how the model predicts a placement it has not seen is not checked there"
             for p in check.placements if p.failure is not None]
    worse = check.worse
    if not worse:
        return [], notes
    few = (" (with two placements each of these fits had one only: a third placement makes the check, and the "
           "calibration, firmer)") if len(check.placements) == 2 else ""
    return [Finding("held_out_placement", (
        f"left out in turn and predicted by the calibration (level {check.level}) of the other placements, "
        f"{_listed(worse)} came out worse than with the nominal URDF (its ball centre fitted on the same "
        f"placements){few}. What the calibration fits does not carry over to a placement it has not seen: too few "
        "sockets or postures per placement for the level's parameters, or an effect the model lacks that differs "
        "between placements. Try a lower --level (or --level auto), --select prior, three sockets not in a line "
        "and more postures per socket, or more placements"))], notes


def _listed(worse: Sequence[PlacementPrediction]) -> str:
    """The placements predicted worse, with their numbers."""
    return "placement(s) " + "; ".join(
        f"{p.placement}: {p.calibrated_mm:.3f} against {p.nominal_mm:.3f} mm RMS distance of the ball from its "
        f"sockets with only that placement's pose fitted (×{p.ratio:.2f}; its {p.rows} rows' noise allows "
        f"×{p.bound:.2f})" for p in worse)


def evaluation_findings(evaluated: Sequence[PlacementPrediction], nominal_missing: str | None = None
                        ) -> list[Finding]:
    """The finding of ``pincal evaluate --fixture`` on placements the calibration has not seen: those the
    corrected URDF (with the reported ball centre) predicts worse than the nominal URDF (with the ball centre
    fitted to it on the calibration placements), beyond the noise of their rows (:func:`worse_bound`).
    ``nominal_missing``: why there is no nominal URDF to compare with (then no placement can be judged,
    and that is the finding: ``unchecked_placement``)."""
    if nominal_missing is not None and evaluated:
        return [Finding("unchecked_placement", (
            f"evaluated placement(s) {', '.join(p.placement for p in evaluated)} not checked against the nominal "
            f"URDF ({nominal_missing}): "
            "whether the calibration carries over to it is unknown; pass --nominal URDF"))]
    worse = [p for p in evaluated if p.worse]
    if not worse:
        return []
    return [Finding("held_out_placement", (
        f"the calibrated model predicts evaluated {_listed(worse)} worse than the nominal URDF does (its ball "
        "centre fitted on the calibration placements). The calibration does not carry over to this placement: "
        "calibrate again on more placements (this one among them), with more sockets and postures per "
        "placement, at a lower --level or with --select prior"))]


def one_placement_note(data: FixtureData) -> str | None:
    """The note of a calibration on one placement (None with more): nothing is left to check it on."""
    if len(data.placements) != 1:
        return None
    return (f"one placement ({data.placements[0]}): a placement's pose is fitted to its own rows, so the "
            "calibrated model cannot be checked against a placement it has not seen, nor compared there with the "
            "nominal URDF. Put the fixture at two or more other places (across the workspace, turned, at other "
            "heights), seat the ball in its sockets there in varied postures and calibrate on all of them: each "
            "placement is then predicted from the others, and a model that predicts one worse than the nominal "
            "URDF is warned")
