"""Ranking one step's fitted candidates, and the checks that keep a selection from being fooled.

The best candidate is adopted when the evidence is very strong (ΔBIC <
:data:`EVIDENCE`, Kass & Raftery 1995) and it is none of these cases, which are
reported instead:

* a value outside physical range (:data:`PLAUSIBLE`) — a stand-in for something else;
* a largest predicted change of the measurements below :data:`NEGLIGIBLE` of their noise,
  whatever its ΔBIC: too small to matter (a rounding-level "effect" on near noise-free data);
* a basis that barely varies (e.g. sign(tau_j) constant on most rows): it acts
  as a joint offset, which the model already has;
* a close competitor (within 6 of its ΔBIC, passing the checks above) with a strongly correlated basis
  corrects the same poses the same way: the data cannot tell them apart, and of them the one taken is the
  one that predicts the held-out rows best among those that pass the held-out test below (without held-out
  rows the simpler: fewer values, then the catalogue's order), the others named beside it
  (:func:`pincal.diagnosis.ambiguity.ambiguity_words`) — ambiguity never leaves the model without the
  correction one of them passes with (a drift and a step at a pause: the step is named,
  :mod:`pincal.model.thermal`);
* when held-out rows are given, an effect that does not make them better beyond their noise: a
  signed-rank test of the per-row change of their error, which a few wild rows cannot decide
  (:func:`pincal.diagnosis.held_out.held_out_verdict`).

:data:`CRITERION` says the rule in words (REPORT.json's ``diagnosis.criterion``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np

from pincal.diagnosis.ambiguity import alike_correlation, ambiguity_words
from pincal.diagnosis.effect_fits import CandidateFit, pose_errors_of
from pincal.diagnosis.held_out import (
    HELD_OUT_LEVEL,
    HELD_OUT_Z,
    MIN_PAIRED_ROWS,
    TELLING_CHANGE,
    fitted_scales,
    held_out_verdict,
)
from pincal.diagnosis.screening import FitObjective
from pincal.fit.metrics import PoseErrors
from pincal.fit.prior import standard_deviations
from pincal.fit.solver import Solution
from pincal.model.chain import KinematicChain
from pincal.model.effect_units import effect_unit
from pincal.model.effects import JOINT_EFFECTS, Effect, EffectInputs, joint_basis
from pincal.model.thermal import implausible

__all__ = [
    "EVIDENCE", "PLAUSIBLE", "NEGLIGIBLE", "NOISE_FLOOR", "CRITERION", "OFFSET_LIKE", "AMBIGUOUS", "SHOWN", "REJECTED",
    "Candidate", "effect_basis", "Judge", "READ_AGAINST", "coupling_advice", "torque_coupling_advice", "POSITION_ONLY",
    "TargetChange", "target_changes", "plausible", "offset_like",
]

#: ΔBIC below which the evidence for an effect is "very strong".
EVIDENCE = -10.0
#: Largest plausible magnitude of each effect's value(s), by type and unit: the unit follows the kinds of the
#: shifted joint and of its driver (:func:`pincal.model.effect_units.effect_unit`), so a compliance is bounded
#: by which joint shifts [rad or m] under which load [N·m or N], a coupling by which reading it follows.
#:
#: Compliance: the largest plausible deflection over the largest gravity load of an arm. The loads: 100 N·m of
#: torque on a revolute joint (a 5 kg-payload arm's shoulder: UR5's effort limit 150 N·m; TIAGo's shoulder
#: bears up to 30 N·m), 1 000 N of force along a prismatic joint (TIAGo's lift carries ~19 kg, 188 N, its effort
#: limit 2 000 N; a gantry's Z axis 50–100 kg; URDFs of example-robot-data). The deflections: 0.1 rad of a
#: revolute joint, 0.1 m of a prismatic one, each moving the tool ~100 mm at an arm's 1 m reach, far beyond an
#: arm that positions to a millimetre. Like joints give the stiffness floors 1 000 N·m/rad and 10 000 N/m; across kinds
#: 0.1 rad / 1 000 N and 0.1 m / 100 N·m (at TIAGo's ~200 N of lift load, 1e-4 rad/N is 0.02 rad).
#:
#: Coupling: a joint's reading includes at most 1.5 × its driver's (1 on parallelogram arms whose controller
#: reads J3 − J2, a differential wrist's ratio below it), so it moves the tool at most 1.5 × what its driver's
#: motion does. Across kinds a turn moves the tool by its lever, 0.1 m (a wrist) to 1 m (an arm's reach): a
#: revolute joint following a prismatic reading, 1.5 / 0.1 m = 15 rad/m; a prismatic joint following a revolute
#: reading, 1.5 × 1 m = 1.5 m/rad.
PLAUSIBLE: dict[str, dict[str, float]] = {
    "compliance": {"rad/(N·m)": 1e-3, "m/N": 1e-4, "rad/N": 1e-4, "m/(N·m)": 1e-3,  # 0.1 rad or m / 100 N·m, 1 kN
                   "rad": 0.1, "m": 0.1},  # unknown masses: g₀·moment/k, the same 0.1 rad or m of deflection
    "lateral": {"rad/(N·m)": 1e-3, "rad": 0.1},  # the compliance's bound: 0.1 rad of bending under 100 N·m
    "coupling": {"(relative)": 1.5, "rad/m": 15.0, "m/rad": 1.5},
    "encoder_scale": {"(relative)": 0.02},
    "cyclic": {"rad": 0.02, "m": 0.005},
    "backlash": {"rad": 0.1, "m": 0.01},
    "drift": {"m/s": 1e-5},  # 36 mm/h
    "sensor_scale": {"(relative)": 0.01},
    "thermal": {"1/K": np.inf},  # judged with its standard deviation (pincal.model.thermal.implausible)
    "pause_step": {"m": 1e-3},  # a larger step is a sensor that was moved, a new session
}
#: Largest change an effect must make to some measured coordinate, in units of that coordinate's
#: noise σ (the fit's whitened residual), to be adopted: σ/10 (the unseen-setups issue's bound on
#: "physically meaningful": below it no sensor sees it and no user needs it).
NEGLIGIBLE = 0.1
#: Noise no sensor of robot calibration goes below [m or rad]: 0.1 µm / 0.1 µrad (an interferometer
#: resolves ~0.5 µm). The noise a fit estimates on noise-free rows is rounding; this stands for it.
NOISE_FLOOR = 1e-7
#: |mean| / RMS of a basis above which it is "nearly constant" (acts as an offset).
OFFSET_LIKE = 0.95
#: |correlation| of two candidates' bases above which they are hard to tell apart.
AMBIGUOUS = 0.8
#: The adoption rule in words, from the constants above: REPORT.json's ``diagnosis.criterion``.
CRITERION = (f"ΔBIC on the calibration rows < {EVIDENCE:g} (very strong evidence), physically plausible, "
             f"changes some measured coordinate by at least {NEGLIGIBLE:g} × its noise, not offset-like; of "
             f"candidates within 6 of its ΔBIC with bases correlated above {AMBIGUOUS:g} (the same correction), "
             f"of those that pass the held-out test the one that predicts the held-out rows best (without them "
             f"the simpler), the others named; with held-out rows, better on them beyond their noise: a Wilcoxon "
             f"signed-rank test of the per-row change of error distance in noise units, of the rows it moves by "
             f"{TELLING_CHANGE:g} noise unit or more, below zero at the one-sided level {HELD_OUT_LEVEL:.3g} "
             f"(Φ(−{HELD_OUT_Z:g})), so that a few wild rows cannot decide (with fewer than {MIN_PAIRED_ROWS} such "
             f"rows, not worse in total; worse on all rows refuses)")
#: Candidates shown per step.
SHOWN = 8
#: How the note of a significant candidate that was not adopted ends (its verdict in the ranking).
REJECTED = "; reported, not adopted"


#: A candidate judged among those that correct the same poses alike: the effect, and its fit's objective and
#: solution (None: not fitted in full).
Member = tuple[Effect, "FitObjective | None", "Solution | None"]


def _fit_of(member: Member) -> tuple[FitObjective, Solution]:
    """A member's fit: every candidate the held-out rows judge was fitted in full."""
    _, objective, solution = member
    assert objective is not None and solution is not None
    return objective, solution


@dataclass(frozen=True)
class Candidate:
    """One effect tried at one step.

    Attributes:
        effect: the effect.
        values / std: fitted values and standard deviations.
        delta_bic: BIC change on the calibration rows against the current model.
        heldout_rms_mm: RMS point error on held-out rows, or None.
        verdict: ``adopted``, ``significant`` (not the best), ``not significant``,
            or why a significant one was not adopted.
    """

    effect: Effect
    values: np.ndarray
    std: np.ndarray
    delta_bic: float
    heldout_rms_mm: float | None
    verdict: str


def effect_basis(effect: Effect, inputs: EffectInputs, chain: KinematicChain) -> np.ndarray | None:
    """The basis of an effect over the rows (K, n_values): the joint shift's, drift's time, thermal's
    temperature, a pause step's a_kp, or None."""
    if effect.type not in JOINT_EFFECTS:
        # drift, thermal and pause steps are candidates only with their columns (pincal.diagnosis.conditions)
        if effect.type == "pause_step":
            return cast(np.ndarray, inputs.pauses)[:, int(cast(int, effect.pause)) - 1, None]
        series = {"drift": inputs.time, "thermal": inputs.temperature}.get(effect.type)
        return None if series is None else series[:, None]
    return joint_basis(effect, inputs, chain.joint_names.index(effect.joint))


def offset_like(basis: np.ndarray | None) -> bool:
    if basis is None:
        return False
    columns = basis.reshape(len(basis), -1)
    ratio = np.abs(columns.mean(axis=0)) / np.sqrt(np.mean(columns**2, axis=0) + 1e-300)
    return bool(np.all(ratio > OFFSET_LIKE))


def plausible(effect: Effect, values: np.ndarray, chain: KinematicChain) -> bool:
    limit = PLAUSIBLE[effect.type][effect_unit(effect, chain.joint_kinds)]
    magnitude = np.hypot(*values) if effect.type == "cyclic" else np.max(np.abs(values))
    return bool(magnitude <= limit)


def _largest_change(objective: FitObjective, x: np.ndarray) -> float:
    """The largest change the last effect of ``objective`` makes to a measured coordinate at ``x``,
    in units of that coordinate's noise (the whitened residual's columns times the effect's values),
    the noise taken as at least :data:`NOISE_FLOOR`."""
    data = getattr(objective, "objective", objective)  # a prior-wrapped objective's sensor residual
    sl = data.effect_slices[-1]
    change = np.abs(objective.jacobian(x)[:, sl] @ x[sl])
    k, n_points = data.g.shape[:2]
    noise = np.concatenate([np.repeat(1.0 / data.w, 3 * n_points)] + ([np.repeat(1.0 / data.v, 3)]
                                                                      if data.G is not None else []))
    change = change[: noise.size] * np.minimum(1.0, noise / NOISE_FLOOR)  # the data rows (a prior's below)
    return float(np.max(change, initial=0.0))


#: Effects that move the measured points but never turn the target: a drift and a pause step translate the
#: registration (eq T2 of :mod:`pincal.model.thermal`), a sensor scale and a thermal expansion scale lengths
#: (eq T1: orientations unchanged). Their text says how far they move the target only.
POSITION_ONLY = ("drift", "sensor_scale", "thermal", "pause_step")


@dataclass(frozen=True)
class TargetChange:
    """How far an effect moves the measured target over the rows it was fitted on: per row, the
    distance each target point moves [m] and the angle the target turns [rad] (6D rows; None
    otherwise), as RMS and maximum over the rows (and points)."""

    rms_m: float
    max_m: float
    rms_rad: float | None
    max_rad: float | None

    def describe(self, effect: Effect | None = None) -> str:
        """``moves the target 0.41 mm RMS (1.2 mm at most), turns it 0.12 mrad RMS (0.3 at most)``; the turn
        left out for an ``effect`` that cannot turn the target (:data:`POSITION_ONLY`)."""
        text = f"moves the target {1e3 * self.rms_m:.3g} mm RMS ({1e3 * self.max_m:.3g} mm at most)"
        turns = effect is None or effect.type not in POSITION_ONLY
        if turns and self.rms_rad is not None and self.max_rad is not None:
            text += f", turns it {1e3 * self.rms_rad:.3g} mrad RMS ({1e3 * self.max_rad:.3g} at most)"
        return text

    def as_dict(self) -> dict[str, float]:
        """REPORT.json ``target_change`` of an effect: mm and mrad."""
        mrad = ({} if self.rms_rad is None or self.max_rad is None
                else {"rms_mrad": 1e3 * self.rms_rad, "max_mrad": 1e3 * self.max_rad})
        return {"rms_mm": 1e3 * self.rms_m, "max_mm": 1e3 * self.max_m, **mrad}


def target_changes(objective: FitObjective, x: np.ndarray) -> list[TargetChange]:
    """The :class:`TargetChange` of each effect of ``objective`` at ``x``: the measured rows' residual at ``x``
    against the residual with that effect's values zeroed, the rows' weights undone (metres; the
    orientation residuals' difference [rad])."""
    data = getattr(objective, "objective", objective)  # a prior-wrapped objective's sensor residual
    k, n_points = data.g.shape[:2]
    n_pos = 3 * k * n_points
    with_all = objective.residual(x)
    out = []
    for sl in data.effect_slices:
        without = x.copy()
        without[sl] = 0.0
        change = with_all - objective.residual(without)
        moved = np.linalg.norm(change[:n_pos].reshape(k, n_points, 3), axis=2) / data.w[:, None]
        turned = None
        if data.G is not None:
            turned = np.linalg.norm(change[n_pos : n_pos + 3 * k].reshape(k, 3), axis=1) / data.v
        out.append(TargetChange(float(np.sqrt(np.mean(moved**2))), float(moved.max(initial=0.0)),
                                None if turned is None else float(np.sqrt(np.mean(turned**2))),
                                None if turned is None else float(turned.max(initial=0.0))))
    return out


class Judge:
    """Ranks a step's fitted candidates, gives their verdicts and picks the one to adopt.

    Args:
        inputs / chain: the effect inputs of the calibration rows and the chain.
        held_rms: held-out RMS point error [mm] of an objective at x, or None
            without held-out rows.
        current_objective / current_x: the fit the candidates would extend.
        noise: the current model's noise scales of positions [m] and orientations [rad] (None: positions
            only), of which :meth:`judged_noise` takes the held-out test's (:func:`held_out_verdict`).
        stated_pos: the sensor's position noise per axis [m] when stated (``--sigma-pos``), or None.
        catalogue: the candidates in the catalogue's order (the simpler of two that correct alike: the first).
    """

    def __init__(self, inputs: EffectInputs, chain: KinematicChain,
                 held_errors: Callable[[FitObjective, np.ndarray], PoseErrors] | None,
                 current_objective: FitObjective, current_x: np.ndarray,
                 noise: tuple[float, float | None] = (1.0, None), stated_pos: float | None = None,
                 catalogue: Sequence[Effect] = ()) -> None:
        self.inputs, self.chain, self._held_errors, self.noise = inputs, chain, held_errors, noise
        self.stated_pos, self.catalogue = stated_pos, list(catalogue)
        # the alternatives of a candidate taken among those that correct alike: words, effects, why it is taken
        self._ambiguous: dict[Effect, tuple[str, list[Effect], str]] = {}
        # each group of candidates that correct alike decided once: the one taken (or none), why, the others
        self._decided: dict[frozenset[Effect], tuple[Effect | None, str, list[Effect]]] = {}
        self._verdicts: dict[Effect, str] = {}  # each candidate's held-out verdict
        self.current_objective, self.current_x = current_objective, current_x
        self._held: dict[Effect, PoseErrors] = {}
        self._before: PoseErrors | None = None

    def held(self, effect: Effect, objective: FitObjective, x: np.ndarray) -> float | None:
        """Held-out RMS [mm] of a candidate's fit (its errors computed once per candidate)."""
        if self._held_errors is None:
            return None
        if effect not in self._held:
            self._held[effect] = self._held_errors(objective, x)
        return self._held[effect].position.rms

    def judged_noise(self, *fitted: tuple[float, float | None]) -> tuple[float, float | None]:
        """The noise scales (σ_pos [m], σ_rot [rad] or None) a held-out test judges in: σ_pos the sensor's when
        stated; otherwise, per kind, the smallest of the current model's and of the ``fitted`` models' compared
        — the one that fits: a model a hundred times off the data puts its noise estimate a hundred times too
        high —, at least :data:`NOISE_FLOOR`."""
        pos = max(min([self.noise[0], *(f[0] for f in fitted)]), NOISE_FLOOR)
        rotations = [r for r in (self.noise[1], *(f[1] for f in fitted)) if r is not None]
        return self.stated_pos or pos, max(min(rotations), NOISE_FLOOR) if rotations else None

    def held_before(self) -> PoseErrors:
        assert self._held_errors is not None  # called only with held-out rows (rejection)
        if self._before is None:
            self._before = self._held_errors(self.current_objective, self.current_x)
        return self._before

    def rank(self, tried: Sequence[CandidateFit]
             ) -> tuple[list[Candidate], CandidateFit | None, dict[str, str], float]:
        """(ranking, chosen, rejected notes, cut): ``tried`` holds (ΔBIC, effect,
        objective, solution) best first; the ranking covers the candidates shown
        and judged. Any candidate whose ΔBIC is above ``cut`` would change none of it."""
        ranking: list[Candidate] = []
        chosen: CandidateFit | None = None
        rejected: dict[str, str] = {}
        compared: list[float] = []
        fits = {t[1]: t for t in tried}
        for rank, (delta, effect, obj, sol) in enumerate(tried):
            if rank >= SHOWN and (chosen is not None or delta >= EVIDENCE):
                break
            sl = obj.effect_slices[-1]
            value, std = sol.x[sl], standard_deviations(obj, sol)[sl]
            held = self.held(effect, obj, sol.x)
            verdict = "not significant"
            if delta < EVIDENCE:
                verdict = "significant"
                if chosen is not None and effect == chosen[1]:  # taken for a better-ranked one that corrects alike
                    verdict = "adopted"
                elif chosen is not None and effect in self._ambiguous.get(chosen[1], ("", [], ""))[1]:
                    verdict = self._alike(effect, chosen[1], self._alikeness((effect, obj, sol), chosen[1:]))
                elif chosen is None:
                    verdict, taken = self.judged(effect, value, delta, tried, compared, obj, sol, std)
                    if taken is not None:
                        chosen = fits[taken]
                        if taken in self._ambiguous:  # its alternatives named (not adopted: a note)
                            rejected[f"{taken.label}:alternatives"] = self._ambiguous[taken][0]
                    if verdict != "adopted":
                        rejected[effect.label] = (
                            f"{effect.label}: ΔBIC {delta:.1f} but {verdict}{REJECTED}")
            ranking.append(Candidate(effect, value, std, float(delta), held, verdict))
        if chosen is not None and all(c.effect is not chosen[1] for c in ranking):
            # taken for a better-ranked candidate that corrects alike, from below the ones shown: listed too
            delta, effect, obj, sol = chosen
            sl = obj.effect_slices[-1]
            ranking.append(Candidate(effect, sol.x[sl], standard_deviations(obj, sol)[sl], float(delta),
                                     self.held(effect, obj, sol.x), "adopted"))
        # what is shown (the first eight), the competitors a check compared (within 6 of
        # the candidate checked) and, when nothing is adopted, every significant candidate
        cut = tried[SHOWN - 1][0] if len(tried) >= SHOWN else np.inf
        if compared:
            cut = max(cut, max(compared) + 6.0)
        if chosen is None:
            cut = max(cut, EVIDENCE)
        else:
            cut = max(cut, chosen[0])
        return ranking, chosen, rejected, cut

    def judged(self, effect: Effect, value: np.ndarray, delta: float, tried: Sequence[CandidateFit],
               compared: list[float], objective: FitObjective | None = None, solution: Solution | None = None,
               std: np.ndarray | None = None) -> tuple[str, Effect | None]:
        """(verdict, the candidate to adopt): 'adopted' and ``effect``, or why the best significant candidate is
        not adopted and the one that corrects the same poses alike adopted instead, or None (``compared`` gains
        ``delta`` when the candidate was compared with its competitors; ``objective`` and ``solution``: the
        candidate's fit, for the size of what it changes; ``std`` its values').

        Competitors within 6 of its ΔBIC whose basis is correlated with its own above :data:`AMBIGUOUS` correct
        the same poses the same way: with those that pass the other checks they form a group, decided once
        (:meth:`_decision`): the one taken is the most preferred (:meth:`_preference`) that the held-out test
        adopts, the others named beside it (:func:`pincal.diagnosis.ambiguity.ambiguity_words`); none only when
        none passes — a drift the data cannot tell from a step at a pause excepted: the step."""
        reason = self._unphysical(effect, value, std, objective, solution)
        if reason:
            return reason, None
        compared.append(delta)
        members, correlations = [(effect, objective, solution)], {}
        for other_delta, other, obj, sol in tried:
            if other is effect or other_delta - delta > 6.0 or (effect.type, other.type) == ("pause_step", "drift"):
                continue  # a drift the data cannot tell from a step at a pause: the step is named
            correlation = correlations[other] = self._alikeness((effect, objective, solution), (other, obj, sol))
            if abs(correlation) <= AMBIGUOUS:
                continue
            if (effect.type, other.type) == ("drift", "pause_step"):
                return (f"{other.label} fits almost as well (ΔBIC {other_delta:.1f}) with a basis correlated "
                        f"{correlation:+.2f}: the data cannot tell a drift from a step at a pause; the step is "
                        "named"), None
            sl = obj.effect_slices[-1]
            if not self._unphysical(other, sol.x[sl], standard_deviations(obj, sol)[sl], obj, sol):
                members.append((other, obj, sol))
        taken, _ = self._decision(members)
        if taken == effect:
            return "adopted", taken
        if taken is not None:
            return self._alike(effect, taken, correlations.get(taken, 0.0)), taken
        others = ", ".join(other.label for other, _, _ in members[1:])
        return self._verdicts[effect] + (f"; the held-out test refuses {others} too (the same correction)"
                                         if others else ""), None

    def _held_out(self, effect: Effect, objective: FitObjective | None, solution: Solution | None) -> str:
        """The held-out test's verdict of a candidate's fit (:func:`held_out_verdict`, judged in the noise of the
        current model and of its own fit, :meth:`judged_noise`), once per candidate; 'adopted' without held-out
        rows."""
        if self._held_errors is None:
            return "adopted"
        assert objective is not None and solution is not None  # a candidate the held-out rows judge was fitted
        if effect not in self._verdicts:
            self.held(effect, objective, solution.x)
            fitted = () if objective is None else (fitted_scales(pose_errors_of(objective, solution.x)),)
            self._verdicts[effect] = held_out_verdict(self.held_before(), self._held[effect],
                                                      *self.judged_noise(*fitted))
        return self._verdicts[effect]

    def _decision(self, members: Sequence[Member]) -> tuple[Effect | None, str]:
        """The candidate taken of a group that corrects the same poses alike ((effect, objective, solution) each)
        and why: the most preferred (:meth:`_preference`) that the held-out test adopts (:meth:`_held_out`), else
        None; the others are the taken's alternatives. The first candidate judged of a group decides it, and the
        one taken is adopted then (:meth:`rank`): judged again from another member, whose group (rivals within 6
        of the candidate judged) and so whose noise scales may differ, a group could prefer back the one that
        preferred it, and neither be adopted. Decided once per set of members: a step ranks its candidates again
        as more are fitted, and meets the same group with the same answer."""
        key = frozenset(effect for effect, _, _ in members)
        if key not in self._decided:
            order, why = self._preference(members)
            passing = [m for m in order if self._held_out(*m) == "adopted"]
            taken = passing[0][0] if passing else None
            if passing and passing[0] is not order[0]:  # the preferred ones fail the held-out test
                why = "of those the held-out test adopts, it predicts the held-out rows best"
            self._decided[key] = taken, why, [effect for effect, _, _ in order if effect != taken]
        taken, why, others = self._decided[key]
        if taken is not None and others:
            self._ambiguous[taken] = ambiguity_words(taken, others, why), others, why
        return taken, why

    def _alikeness(self, first: Member, second: Member) -> float:
        """How alike two candidates correct the poses (:func:`pincal.diagnosis.ambiguity.alike_correlation`)."""
        fits = tuple(None if m[1] is None or m[2] is None else (m[1], m[2]) for m in (first, second))
        return alike_correlation((first[0], second[0]), (effect_basis(first[0], self.inputs, self.chain),
                                                         effect_basis(second[0], self.inputs, self.chain)), fits)

    def _alike(self, effect: Effect, taken: Effect, correlation: float) -> str:
        """The verdict of a candidate that corrects the same poses as the one ``taken`` instead (with its own
        held-out verdict when it fails the test; ``correlation``: how alike, :func:`alike_correlation`)."""
        own = self._verdicts.get(effect, "adopted")
        return (f"{taken.label} corrects the same poses the same way (bases correlated {correlation:+.2f}): these "
                f"poses cannot tell them apart, and {taken.label} is preferred ({self._ambiguous[taken][2]})"
                + ("" if own == "adopted" else f"; this one: {own}"))

    def _unphysical(self, effect: Effect, value: np.ndarray, std: np.ndarray | None, objective: FitObjective | None,
                    solution: Solution | None) -> str | None:
        """Why a candidate cannot be adopted whatever its competitors (out of physical range, too small to matter,
        acting as an offset), or None."""
        reason = None if std is None else implausible(effect, value, std)
        if reason:
            return reason
        if not plausible(effect, value, self.chain):
            return (f"its value {np.round(value, 6).tolist()} is outside the physical range "
                    "(a stand-in for something else)")
        if objective is not None and solution is not None:  # fitted in full (given together)
            largest = _largest_change(objective, solution.x)
            if largest < NEGLIGIBLE:
                return (f"it changes no measured coordinate by more than {largest:.2g} of its noise (below "
                        f"{NEGLIGIBLE:g}): too small to matter, whatever its ΔBIC")
        # a coupling's mean part is the joint offset the geometry has: its ΔBIC and change (above) are its variation's
        if effect.type != "coupling" and offset_like(effect_basis(effect, self.inputs, self.chain)):
            return "its basis barely changes over the rows, so it acts as a joint offset"
        return None

    def _preference(self, members: Sequence[Member]) -> tuple[list[Member], str]:
        """Candidates that correct the same poses alike, (effect, objective, solution) each, in the order they are
        preferred, and why the first: with held-out rows by the sum of their errors there in noise units
        (:func:`row_changes`' units, the noise of the group's fits, :meth:`judged_noise`), else the simpler first:
        fewer values, then the catalogue's order."""
        if self._held_errors is not None:
            fits = [_fit_of(member) for member in members]
            sigma_pos, sigma_rot = self.judged_noise(*(fitted_scales(pose_errors_of(o, x.x)) for o, x in fits))
            scores = []
            for (effect, _, _), (objective, solution) in zip(members, fits):
                self.held(effect, objective, solution.x)
                errors = self._held[effect]
                scores.append(float(np.sum(errors.position_m)) / sigma_pos + (
                    float(np.sum(errors.rotation_rad)) / sigma_rot if errors.rotation_rad is not None and sigma_rot
                    else 0.0))
            return [members[i] for i in np.argsort(scores, kind="stable")], "it predicts the held-out rows best"
        order = [(e.n_values, self.catalogue.index(e) if e in self.catalogue else len(self.catalogue))
                 for e, _, _ in members]
        return ([members[i] for i in sorted(range(len(members)), key=order.__getitem__)],
                "the simpler: fewest values, then the catalogue's order")


#: |c| within this of 1: a joint read against its driver (J3 from the horizontal), not a transmission's ratio.
READ_AGAINST = 0.01


def coupling_advice(effect: Effect, value: float, given: float | None = None) -> str:
    """What an adopted coupling means and what to do: a reading taken against another joint (±1) is
    corrected in the data, so that the geometry is selected on the corrected readings; a small value
    (a transmission's) stays in the model. ``given``: the factor F of a ``--coupling`` already given for
    the same joint and driver (the readings were corrected by it): the one that fits is F − value."""
    if given is not None:
        # a convention given with the wrong sign leaves 2 x the driver: too far for the fit to find it, so
        # the opposite sign is named; any other factor is corrected by what remains (F − value)
        factor = f"{-given:g}" if abs(abs(given) - 1.0) < READ_AGAINST else f"{given - value:.4g}"
        return (f"{effect.joint}'s readings, corrected by --coupling {effect.joint}={given:g}*{effect.driver}, "
                f"still include {-value:+.3f} x {effect.driver}'s: that factor looks wrong; run again with "
                f"--coupling {effect.joint}={factor}*{effect.driver}, or without it to see what diagnose finds")
    if abs(abs(value) - 1.0) >= READ_AGAINST:
        return (f"{effect.joint}'s reading includes {-value:+.4g} x {effect.driver}'s (a transmission coupling): "
                "it stays in the model, and evaluate applies it")
    return (f"{effect.joint}'s reading includes {-value:+.3f} x {effect.driver}'s (the controller measures it from "
            f"{effect.driver}, as parallelogram arms read J3 from the horizontal): run again with --coupling "
            f"{effect.joint}={-np.sign(value):.0f}*{effect.driver} (a convention is exact), so that the geometry is "
            "chosen on the corrected readings; evaluate then corrects its rows the same way")


def torque_coupling_advice(effect: Effect, value: float, unit: str) -> str:
    """What an adopted gravity-torque coupling (a ``compliance`` with a ``driver``) means: joint j deflects
    under joint i's load, which a parallelogram or a counterbalance carries to it; it stays in the model.
    ``unit``: the value's (:func:`pincal.model.effect_units.effect_unit`; rad/(N·m) between revolute joints)."""
    load = "gravity force" if unit.endswith("/N") else "gravity torque"
    return (f"{effect.joint} deflects by {value:.4g} {unit} x {effect.driver}'s {load} (a "
            f"parallelogram or a counterbalance links their loads): it stays in the model; evaluate applies it, "
            "and the effects file beside the corrected URDF gives it to a controller")
