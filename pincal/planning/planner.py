"""``pincal plan``: choose the N configurations worth measuring, predict what they give, order them.

1. The information of each candidate follows from what the sensor sees
   (:mod:`pincal.planning.information`), linearised at the URDF as loaded — or,
   with data already recorded, at their calibration (its noise level and
   target too, unless given).
2. N candidates are chosen for the criterion (:mod:`pincal.planning.design`).
3. The plan's predicted errors (the linearised noise limit of the calibrated
   model over the workspace sample) are set beside those of N random
   candidates (median of :data:`RANDOM_DRAWS` seeded draws).
4. The chosen configurations are ordered (:mod:`pincal.planning.ordering`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pinocchio as pin

from pincal.errors import PincalError, did_you_mean
from pincal.fit.chain_calibration import ChainFitOptions, calibrate_chain
from pincal.fit.prior import Prior, prior_of
from pincal.fit.selection import SELECTION_CRITERIA, SelectionCriterion
from pincal.fit.sessions import initial_target
from pincal.measurements.data import MeasurementSet
from pincal.model.chain import ChainJoint, KinematicChain
from pincal.model.parameter_sets import CHAIN_LEVELS
from pincal.planning.candidates import WORKSPACE_SIZE
from pincal.planning.design import DesignProblem, Prediction, TargetPrediction, select
from pincal.planning.information import (
    MeasurementModel,
    SensorModel,
    default_target_points,
)
from pincal.planning.ordering import Balance, alternating_order, approach_balance, move_times, short_tour
from pincal.progress import Counter, Progress
from pincal.residuals.sensor import REGISTRATION_NAMES

__all__ = [
    "DEFAULT_SIGMA_POS_MM", "DEFAULT_SIGMA_ROT_DEG", "RANDOM_DRAWS", "PlanSettings", "Addition", "Plan",
    "plan_measurements", "Joints", "PlanContext", "usable_pool", "workspace_sample", "choose", "joint_columns",
    "velocity_limits",
]

#: Default sensor noise: the ``pincal simulate`` defaults (σ_p = 0.055 mm per axis,
#: σ_a = 0.055° per angle; Franaszek & Marvel 2022, Section 7). Predicted errors scale with it.
DEFAULT_SIGMA_POS_MM = 0.055
DEFAULT_SIGMA_ROT_DEG = 0.055
#: Random N-subsets of the candidates the plan is compared with.
RANDOM_DRAWS = 20


@dataclass(frozen=True)
class PlanSettings:
    """What to plan for.

    Attributes:
        count: N, configurations to choose.
        level: ``registration``, ``offsets``, ``full`` or ``dh``.
        sensor: what is measured at each configuration; None: what the recorded
            data hold, else one point.
        criterion: ``accuracy``, ``d`` or ``a``.
        sigma_pos_mm / sigma_rot_deg: sensor noise [mm, deg]; None: estimated from
            the recorded data if any, else :data:`DEFAULT_SIGMA_POS_MM` / ``_ROT_DEG``.
        target_points: target points in the tool frame [m], (P, 3); None: the
            recorded data's estimate, or :func:`default_target_points`.
        tool_known: the chain's tool is the measured point (not estimated).
        alternate: joints whose approach direction the order balances.
        seed: seed of the workspace subsample, the exchange's random starts, the random comparison
            and the order.
        workspace_size: candidates the accuracy is averaged over (when no workspace is given).
        random_draws: random N-subsets the plan is compared with.
        selection: the selection of the calibration the plan is for, as ``calibrate --select``
            (``aic``, ``bic``, ``press``, ``all``, or ``prior`` — a :class:`pincal.fit.prior.Prior`
            with its scales —, the command's default at ``offsets`` and ``full``). With a prior the
            plan's information and predictions include it (eq P1); recorded rows (``existing``) are
            calibrated with it.
    """

    count: int
    level: str = "full"
    sensor: SensorModel | None = None
    criterion: str = "accuracy"
    sigma_pos_mm: float | None = None
    sigma_rot_deg: float | None = None
    target_points: np.ndarray | None = None
    tool_known: bool = False
    alternate: tuple[str, ...] = ()
    seed: int = 0
    workspace_size: int = WORKSPACE_SIZE
    random_draws: int = RANDOM_DRAWS
    selection: SelectionCriterion | Prior = "aic"

    @property
    def prior(self) -> Prior | None:
        """The selection's prior, or None (:func:`pincal.fit.prior.prior_of`)."""
        return prior_of(self.selection)

    def __post_init__(self) -> None:
        if self.selection not in SELECTION_CRITERIA:
            raise PincalError(f"selection must be one of {', '.join(SELECTION_CRITERIA)}, got '{self.selection}'")
        if self.prior is not None and self.level not in ("offsets", "full"):
            raise PincalError(f"a prior applies to the kinematic parameters of level offsets or full, "
                              f"not {self.level}")
        if self.target_points is not None:
            points = np.atleast_2d(np.asarray(self.target_points, dtype=float))
            if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
                raise PincalError(f"target points must be finite (P, 3) [m], got shape {points.shape}")
            object.__setattr__(self, "target_points", points)
        object.__setattr__(self, "alternate", tuple(self.alternate))


@dataclass(frozen=True)
class Addition:
    """One chosen configuration in priority order (the best first).

    Attributes:
        candidate: index into the candidates.
        predicted_mean_mm: predicted mean position error after measuring it and
            every configuration before it (None while the parameters are not all determined) [mm].
        gain_mm: how much it lowers that prediction [mm] (None likewise).
    """

    candidate: int
    predicted_mean_mm: float | None
    gain_mm: float | None


@dataclass(frozen=True)
class Plan:
    """The planned measurements and what they are predicted to give.

    Attributes:
        q: chosen configurations in visiting order [rad or m], (N, n_joints).
        candidates: their indices into the candidates, (N,).
        priority: each visited row's rank in :attr:`additions` (1 = best), (N,).
        additions: the chosen configurations in priority order.
        criterion / criterion_value: see :data:`pincal.planning.design.CRITERIA`.
        prediction: the plan's predicted errors (with the recorded rows).
        random: the median of the same over random N-subsets of the candidates.
        random_singular: random subsets that do not determine the parameters.
        recorded: predicted errors of the recorded rows alone (``--existing``).
        identifiable / not_identifiable: kinematic parameters the candidates can / cannot determine.
        estimated: every parameter the calibration estimates (with registration and target).
        balance: approach balance of each joint in the visiting order.
        travel_s: time of the moves at the URDF's velocity limits [s].
        sigma_pos_mm / sigma_rot_deg / sigma_source: the noise assumed and where it comes from.
        target_points: target points in the tool frame [m], (P, 3).
        workspace_size: configurations the accuracy is averaged over.
        swaps: configurations the exchange passes replaced, from the start that won
            (:func:`pincal.planning.design.select`).
        seconds: planning time [s].
        settings: the settings, with the sensor resolved.
        notes: what the user should know.
        targets: with several targets (a tree), each one's predicted errors, plan and random.
    """

    settings: PlanSettings
    q: np.ndarray
    candidates: np.ndarray
    priority: np.ndarray
    additions: tuple[Addition, ...]
    criterion: str
    criterion_value: float
    prediction: Prediction | None
    random: Prediction | None
    random_singular: int
    recorded: Prediction | None
    identifiable: tuple[str, ...]
    not_identifiable: tuple[str, ...]
    estimated: tuple[str, ...]
    balance: tuple[Balance, ...]
    travel_s: float
    sigma_pos_mm: float
    sigma_rot_deg: float | None
    sigma_source: str
    target_points: np.ndarray
    workspace_size: int
    swaps: int
    seconds: float
    notes: tuple[str, ...] = field(default=())
    targets: tuple[TargetPrediction, ...] = ()


def plan_measurements(
    chain: KinematicChain,
    candidates: np.ndarray,
    settings: PlanSettings,
    existing: MeasurementSet | None = None,
    workspace: np.ndarray | None = None,
    allowed: np.ndarray | None = None,
    progress: Progress | None = None,
) -> Plan:
    """Choose ``settings.count`` of the ``candidates`` (K, n_joints) and order them.

    Args:
        chain: the chain, its tool set when ``settings.tool_known`` (not changed).
        existing: measurements already recorded (their calibration is the linearisation point).
        workspace: configurations where accuracy matters (default: a subsample of the candidates).
        allowed: candidates that may be chosen (default all; e.g. collision-free ones).
        progress: ``progress(done, total)`` (:mod:`pincal.progress`) over the search's steps
            (:func:`pincal.planning.design.select`), the random draws and the predictions
            of each prefix of the priority order.

    Raises:
        PincalError: unknown joint in ``alternate``, a count the candidates cannot meet,
            or recorded data that do not match the sensor.
    """
    started = time.perf_counter()
    if settings.sensor is None:
        sensor = SensorModel("point", 1)
        if existing is not None:
            sensor = (SensorModel("pose", 1) if existing.has_orientation
                      else SensorModel("points", existing.n_points) if existing.n_points > 1 else sensor)
        settings = replace(settings, sensor=sensor)
    assert settings.sensor is not None  # set above when not given
    candidates, allowed = usable_pool(candidates, allowed, settings.count)
    joint_columns(chain.joint_names, settings.alternate)  # an unknown joint refused before the work
    rng = np.random.default_rng(settings.seed)
    model, sigma_source, recorded_q, recorded_sessions = _measurement_model(chain, settings, existing)
    workspace = workspace_sample(candidates, allowed, workspace, settings, rng)
    blocks, recorded, errors, names = _session_columns(
        model, model.jacobian(candidates), model.jacobian(recorded_q), recorded_sessions,
        model.error_jacobian(workspace))
    precision = None
    if settings.prior is not None:
        precision = np.zeros(blocks.shape[2])
        precision[: len(model.names)] = model.prior_precision(settings.prior)
    problem = DesignProblem(blocks, model.kinematic, recorded, *errors, prior_precision=precision)
    sigma_rot = float(np.degrees(model.sigma_rot_rad)) if settings.sensor.has_rotation else None
    context = PlanContext(settings, candidates, allowed, recorded_q, names, Joints(chain.joints, _velocities(chain)),
                          (model.sigma_pos_m * 1000.0, sigma_rot, sigma_source), model.points, started)
    return choose(problem, context, rng, progress)[0]


@dataclass(frozen=True)
class Joints:
    """The joints a plan moves (limits: the visiting order's start) and their velocity limits [rad/s or m/s]."""

    joints: tuple[ChainJoint, ...]
    velocities: np.ndarray

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)


@dataclass(frozen=True)
class PlanContext:
    """What :func:`choose` needs beside the design problem: the settings (the sensor resolved), the candidates
    (K, N) [rad or m] and which may be chosen (K,), the recorded rows' configurations (K0, N), the problem's
    column names, the joints, the noise (σ_p [mm], σ_a [deg] or None, where it comes from), the target points
    (P, 3) [m] and when planning started (``time.perf_counter()``)."""

    settings: PlanSettings
    candidates: np.ndarray
    allowed: np.ndarray
    recorded_q: np.ndarray
    names: tuple[str, ...]
    joints: Joints
    noise: tuple[float, float | None, str]
    target_points: np.ndarray
    started: float


def usable_pool(candidates: np.ndarray, allowed: np.ndarray | None, count: int) -> tuple[np.ndarray, np.ndarray]:
    """The candidates (K, N) and which may be chosen (K,; default all); refuses a ``count`` they cannot meet."""
    candidates = np.atleast_2d(np.asarray(candidates, dtype=float))
    allowed = np.ones(len(candidates), dtype=bool) if allowed is None else np.asarray(allowed, dtype=bool)
    if count < 1:
        raise PincalError(f"--count {count}: choose at least one configuration")
    if count > int(allowed.sum()):
        refused = len(candidates) - int(allowed.sum())
        raise PincalError(f"--count {count} is more than the {int(allowed.sum())} usable candidates"
                          + (f" ({refused} refused)" if refused else "") + "; lower --count or give more candidates")
    return candidates, allowed


def workspace_sample(candidates: np.ndarray, allowed: np.ndarray, workspace: np.ndarray | None,
                     settings: PlanSettings, rng: np.random.Generator) -> np.ndarray:
    """The configurations accuracy is averaged over: ``workspace``, else ``settings.workspace_size`` of the
    allowed candidates drawn with ``rng``."""
    if workspace is not None:
        return workspace
    pool = np.flatnonzero(allowed)
    return candidates[rng.choice(pool, min(len(pool), settings.workspace_size), replace=False)]


def choose(problem: DesignProblem, context: PlanContext, rng: np.random.Generator,
           progress: Progress | None = None) -> tuple[Plan, list[np.ndarray]]:
    """Choose ``context.settings.count`` candidates for the criterion, predict, compare with random choices and
    order them: the plan, and the random subsets it was compared with (indices into the candidates).

    Raises:
        PincalError: a count too small to determine the parameters.
    """
    settings, candidates, allowed, names = context.settings, context.candidates, context.allowed, context.names
    assert settings.sensor is not None  # resolved by the caller
    rows = settings.sensor.rows
    needed = int(np.ceil((problem.n - rows * len(problem.existing)) / rows))
    if settings.count < needed:
        raise PincalError(
            f"--count {settings.count} cannot determine the {problem.n} parameters estimated at level "
            f"{settings.level} ({rows} measurements per configuration): plan at least {needed}"
        )
    counter = Counter(progress)
    counter.expect(settings.random_draws + settings.count)  # the random draws, the additions
    selection = select(problem, settings.count, settings.criterion, allowed, counter, seed=settings.seed)
    prediction = problem.predict(selection.chosen)
    random, singular, draws = _random_baseline(problem, settings, allowed, rng, counter)
    recorded_prediction = problem.predict([]) if len(problem.existing) else None
    additions = _additions(problem, selection.priority, recorded_prediction, counter)
    counter.settle()
    order = _visiting_order(context.joints, candidates[selection.chosen], context.recorded_q,
                            joint_columns(context.joints.names, settings.alternate), settings.seed)
    chosen = selection.chosen[order]
    q = candidates[chosen]
    rank = {int(c): i + 1 for i, c in enumerate(selection.priority)}
    notes = []
    if prediction is None:
        notes.append("the chosen configurations do not determine every identifiable parameter; plan more")
    sigma_pos_mm, sigma_rot_deg, sigma_source = context.noise
    plan = Plan(
        settings=settings,
        q=q,
        candidates=chosen,
        priority=np.array([rank[int(c)] for c in chosen]),
        additions=additions,
        criterion=settings.criterion,
        criterion_value=problem.criterion(selection.chosen, settings.criterion),
        prediction=prediction,
        random=random,
        random_singular=singular,
        recorded=recorded_prediction,
        identifiable=tuple(names[i] for i in problem.identifiable),
        not_identifiable=tuple(names[i] for i in problem.not_identifiable),
        estimated=tuple(names[i] for i in problem.columns),
        balance=tuple(approach_balance(q, context.joints.names)),
        travel_s=float(move_times(q, context.joints.velocities).sum()),
        sigma_pos_mm=sigma_pos_mm,
        sigma_rot_deg=sigma_rot_deg,
        sigma_source=sigma_source,
        target_points=context.target_points,
        workspace_size=len(problem.position),
        swaps=selection.swaps,
        seconds=time.perf_counter() - context.started,
        notes=tuple(notes),
    )
    return plan, draws


def joint_columns(joint_names: Sequence[str], names: Sequence[str]) -> np.ndarray:
    """The columns of the ``--alternate`` joints ``names`` among ``joint_names``; an unknown one is refused."""
    unknown = [n for n in names if n not in joint_names]
    if unknown:
        raise PincalError(f"--alternate: no joint {', '.join(repr(n) for n in unknown)} on the chain; "
                          f"{did_you_mean(unknown[0], list(joint_names), 'its joints')}")
    return np.array([list(joint_names).index(n) for n in names], dtype=int)


def _measurement_model(chain: KinematicChain, settings: PlanSettings, existing: MeasurementSet | None):
    """The measurement model — linearised at the recorded rows' calibration, else at the chain as it
    is —, where its noise comes from, and the recorded rows' configurations and sessions."""
    sensor = settings.sensor
    assert sensor is not None  # plan() sets it
    if settings.tool_known and sensor.n_points != 1:
        raise PincalError(f"--measure {sensor.label} with --tool: a known tool is one point; "
                          "leave out --tool to estimate the target's points")
    points = settings.target_points
    sigma_pos = None if settings.sigma_pos_mm is None else settings.sigma_pos_mm / 1000.0
    sigma_rot = None if settings.sigma_rot_deg is None else np.radians(settings.sigma_rot_deg)
    pos_source = "given" if sigma_pos is not None else "default"
    rot_source = "given" if sigma_rot is not None else "default"
    recorded_q = np.zeros((0, chain.n_joints))
    recorded_sessions = np.zeros(0, dtype=object)
    linearised = tuple(chain.placements())
    if existing is not None:
        rows = existing.select(existing.roles != "validation")
        if rows.n_points != sensor.n_points or rows.has_orientation != sensor.has_rotation:
            seen = ("pose" if rows.has_orientation else f"{rows.n_points} point(s)")
            raise PincalError(f"{existing.source}: the recorded rows measure {seen} per configuration, "
                              f"but --measure is {sensor.label}; plan for what the sensor sees")
        recorded_q, recorded_sessions = rows.q, rows.sessions
        if settings.level in CHAIN_LEVELS:
            result = calibrate_chain(chain, rows, settings.level,
                                     ChainFitOptions(tool_known=settings.tool_known, selection=settings.selection))
            target, linearised = result.target, result.chain_placements
            if sigma_pos is None:  # each sigma not given is estimated from the recorded rows
                sigma_pos, pos_source = result.sigma_pos_m, f"estimated from {existing.source}"
            if sigma_rot is None and result.sigma_rot_rad is not None:
                sigma_rot, rot_source = result.sigma_rot_rad, f"estimated from {existing.source}"
        else:
            target = initial_target(chain, rows, fit_points=not settings.tool_known)
        if points is None and not settings.tool_known:
            points = target.points
    if settings.tool_known:
        points = np.zeros((1, 3))
    elif points is None:
        points = default_target_points(sensor.n_points)
    sigma_pos = DEFAULT_SIGMA_POS_MM / 1000.0 if sigma_pos is None else sigma_pos
    sigma_rot = np.radians(DEFAULT_SIGMA_ROT_DEG) if sigma_rot is None else sigma_rot
    with chain.placed(linearised):  # its parameters are errors about these placements
        model = MeasurementModel(chain, settings.level, sensor, points, tool_known=settings.tool_known,
                                 sigma_pos_m=sigma_pos, sigma_rot_rad=sigma_rot)
    source = pos_source if pos_source == rot_source or not sensor.has_rotation else (
        f"position {pos_source}, orientation {rot_source}")
    return model, source, recorded_q, recorded_sessions


def _session_columns(
    model: MeasurementModel, blocks, recorded, sessions, errors
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray | None], tuple[str, ...]]:
    """Registration columns of several recorded sessions.

    The planned rows continue the session of the last recorded row (the sensor
    stays where it is) and share its registration, the model's columns; rows of
    each other session get 6 registration columns of their own, appended (zero
    for the candidates and the workspace). Returns the candidates' and recorded
    blocks, the workspace error rows and the column names.
    """
    names = list(model.names)
    others = [name for name in dict.fromkeys(sessions.tolist()) if len(sessions) and name != sessions[-1]]
    if not others:
        return blocks, recorded, errors, tuple(names)
    reg = len(model.kinematic) + np.arange(6)  # the registration follows the kinematic columns
    extra = 6 * len(others)
    recorded = np.concatenate([recorded, np.zeros(recorded.shape[:2] + (extra,))], axis=2)
    for s, name in enumerate(others):
        rows = sessions == name
        block = recorded[rows]  # (k_s, m, n): its registration moves to its own columns
        block[:, :, recorded.shape[2] - extra + 6 * s + np.arange(6)] = block[:, :, reg]
        block[:, :, reg] = 0.0
        recorded[rows] = block
        names += [f"registration[{name}].{axis}" for axis in REGISTRATION_NAMES]
    position, rotation = errors

    def pad(a):
        return None if a is None else np.concatenate([a, np.zeros(a.shape[:-1] + (extra,))], axis=-1)

    return pad(blocks), recorded, (pad(position), pad(rotation)), tuple(names)


def _random_baseline(problem: DesignProblem, settings: PlanSettings, allowed: np.ndarray, rng, counter: Counter):
    """Median predicted errors of random N-subsets of the allowed candidates, how many were singular, and the
    subsets drawn."""
    pool = np.flatnonzero(allowed)
    draws, subsets = [], []
    for _ in range(settings.random_draws):
        subsets.append(rng.choice(pool, settings.count, replace=False))
        draws.append(problem.predict(subsets[-1]))
        counter.tick()
    good = [d for d in draws if d is not None]
    singular = len(draws) - len(good)
    if len(good) <= len(draws) // 2:
        return None, singular, subsets
    median: dict[str, Any] = {}  # float, or None for orientation errors without orientations
    for key in ("mean_position_mm", "max_position_mm", "mean_rotation_deg", "max_rotation_deg", "condition"):
        values = [getattr(d, key) for d in good]
        # the singular draws count as infinitely bad
        median[key] = None if values[0] is None else float(np.median(values + [np.inf] * singular))
    return Prediction(**median), singular, subsets


def _additions(problem: DesignProblem, priority: np.ndarray, recorded: Prediction | None,
               counter: Counter) -> tuple[Addition, ...]:
    """Predicted mean error after each prefix of the priority order, and each one's gain."""
    out, previous = [], None if recorded is None else recorded.mean_position_mm
    rows, n_recorded = problem.blocks.shape[1], len(problem.existing)
    for k in range(1, len(priority) + 1):
        enough = (k + n_recorded) * rows >= problem.n
        prediction = problem.predict(priority[:k], condition=False) if enough else None
        value = None if prediction is None else prediction.mean_position_mm
        gain = None if value is None or previous is None else previous - value
        out.append(Addition(int(priority[k - 1]), value, gain))
        previous = value
        counter.tick()
    return tuple(out)


def _velocities(chain: KinematicChain) -> np.ndarray:
    """Velocity limit of each chain joint [rad/s or m/s]; 1 where the URDF gives none."""
    return velocity_limits(chain.model, chain.joint_ids)


def velocity_limits(model: pin.Model, joint_ids: Sequence[int]) -> np.ndarray:
    """Velocity limit of each of the joints ``joint_ids`` of ``model`` [rad/s or m/s]; 1 where the URDF gives none."""
    v = np.array([model.velocityLimit[model.joints[j].idx_v] for j in joint_ids], dtype=float)
    return np.where(np.isfinite(v) & (v > 0), v, 1.0)


def _visiting_order(joints: Joints, q: np.ndarray, recorded_q: np.ndarray, alternate: np.ndarray,
                    seed: int) -> np.ndarray:
    """Permutation of the chosen rows: short travel, or balanced approaches of the ``alternate`` joints."""
    lower = np.array([j.lower for j in joints.joints])
    upper = np.array([j.upper for j in joints.joints])
    start = recorded_q[-1] if len(recorded_q) else np.clip(np.zeros(len(lower)), lower, upper)
    if len(alternate):
        return alternating_order(q, joints.velocities, alternate, start, seed)
    return short_tour(q, joints.velocities, start)
