"""The order in which to visit the chosen configurations.

Without ``--alternate``: keep travel short. A move's time is the slowest
joint's, max_j |Δq_j| / v_j with v_j the URDF's velocity limit (1 rad/s or m/s
where the URDF gives none) [s]; a nearest-neighbour tour from the start is
improved by 2-opt (reversing segments while that shortens it).

With ``--alternate``: a joint with backlash rests on one gear flank or the
other depending on the direction it last moved, s_k = sign(q_j[k] − q_j[k−1])
(moves below :data:`STILL` keep the flank, as ``pincal diagnose`` assumes). To
separate a backlash b·s_k from the joint's offset (a constant) and from its
kinematics (a function of q_j), s must be balanced (as many approaches from
below as from above) and uncorrelated with q_j. The order minimises
Σ_j (imbalance_j² + corr(s_j, q_j)²) + λ·travel/travel₀ (λ = :data:`TRAVEL_WEIGHT`,
travel₀ the short tour's) by simulated annealing over segment reversals and
swaps (seeded).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "STILL", "TRAVEL_WEIGHT", "ANNEAL_STEPS", "move_times", "short_tour", "Balance", "flanks", "approach_balance",
    "alternating_order",
]

#: Joint moves smaller than this keep the flank [rad or m] (the diagnose rule).
STILL = 1e-3
#: Weight of the travel time against the approach balance in the ``--alternate`` order.
TRAVEL_WEIGHT = 0.05
#: Annealing steps of the ``--alternate`` order.
ANNEAL_STEPS = 20000


def move_times(q: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """Time of each move between consecutive rows of ``q`` (K, N) at joint velocities ``velocity`` (N,) [s], (K−1,)."""
    return np.max(np.abs(np.diff(q, axis=0)) / velocity, axis=1) if len(q) > 1 else np.zeros(0)


def short_tour(q: np.ndarray, velocity: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Order of the rows of ``q`` for a short travel from configuration ``start``: nearest neighbour, then 2-opt."""
    k = len(q)
    cost = np.max(np.abs(q[:, None, :] - q[None, :, :]) / velocity, axis=2)  # (K, K) [s]
    from_start = np.max(np.abs(q - start) / velocity, axis=1)
    path = [int(np.argmin(from_start))]
    left = np.ones(k, dtype=bool)
    left[path[0]] = False
    while left.any():
        row = np.where(left, cost[path[-1]], np.inf)
        path.append(int(np.argmin(row)))
        left[path[-1]] = False
    order = np.array(path)
    improved = True
    while improved:  # 2-opt on the open path: reverse order[i:j+1]
        improved = False
        for i in range(1, k - 1):
            a, b = order[i - 1], order[i]
            c = order[i + 1 :]
            d = np.append(order[i + 2 :], -1)
            before = cost[a, b] + np.where(d >= 0, cost[c, d], 0.0)
            after = cost[a, c] + np.where(d >= 0, cost[b, d], 0.0)
            gain = before - after
            j = int(np.argmax(gain))
            if gain[j] > 1e-12:
                order[i : i + j + 2] = order[i : i + j + 2][::-1]
                improved = True
    return order


@dataclass(frozen=True)
class Balance:
    """How one joint approaches its positions in an order.

    Attributes:
        joint: joint name.
        from_below / from_above: rows reached moving up / down.
        kept: rows reached without moving it (flank kept from before).
        balance: from_below / (from_below + from_above) (0.5 is balanced; None if it never moves).
        correlation: Pearson correlation of the flank s_k with q_j (None if undefined).
    """

    joint: str
    from_below: int
    from_above: int
    kept: int
    balance: float | None
    correlation: float | None

    def as_dict(self) -> dict:
        return dict(self.__dict__)


def flanks(q: np.ndarray) -> np.ndarray:
    """Flank s_k ∈ {−1, 0, +1} of each joint at rows 1..K−1 (0 = unknown: not moved yet), (K−1, N)."""
    step = np.diff(q, axis=0)
    moving = np.abs(step) >= STILL
    sign = np.where(moving, np.sign(step), 0.0)
    out = np.zeros_like(sign)
    last = np.zeros(q.shape[1])
    for k in range(len(sign)):
        last = np.where(moving[k], sign[k], last)
        out[k] = last
    return out


def approach_balance(q: np.ndarray, names) -> list[Balance]:
    """Approach counts, balance and flank–position correlation of every joint for rows in order ``q``."""
    out = []
    if len(q) < 2:
        return [Balance(name, 0, 0, len(q), None, None) for name in names]
    side = flanks(q)
    moved = np.sign(np.where(np.abs(np.diff(q, axis=0)) >= STILL, np.diff(q, axis=0), 0.0))
    for j, name in enumerate(names):
        up, down = int(np.sum(moved[:, j] > 0)), int(np.sum(moved[:, j] < 0))
        known = side[:, j] != 0
        s, x = side[known, j], q[1:, j][known]
        correlation = float(np.corrcoef(s, x)[0, 1]) if known.sum() > 2 and s.std() > 0 and x.std() > 0 else None
        out.append(Balance(name, up, down, len(q) - 1 - up - down,
                           up / (up + down) if up + down else None, correlation))
    return out


def _imbalance(q: np.ndarray, joints: np.ndarray) -> float:
    """Σ_j (mean flank)² + corr(flank, q_j)² over the ``joints`` (columns of q)."""
    step = np.diff(q[:, joints], axis=0)
    s = np.sign(step)  # the annealing cost treats tiny moves by their sign; the report uses STILL
    x = q[1:, joints]
    mean = s.mean(axis=0)
    sc, xc = s - mean, x - x.mean(axis=0)
    denominator = np.sqrt((sc**2).sum(axis=0) * (xc**2).sum(axis=0))
    corr = np.divide((sc * xc).sum(axis=0), denominator, out=np.ones_like(mean), where=denominator > 0)
    return float(np.sum(mean**2 + corr**2))


def alternating_order(
    q: np.ndarray, velocity: np.ndarray, joints: np.ndarray, start: np.ndarray, seed: int
) -> np.ndarray:
    """Order of the rows of ``q`` balancing the approach direction of ``joints`` (column indices)."""
    rng = np.random.default_rng(seed)
    order = short_tour(q, velocity, start)
    k = len(order)
    if k < 3:
        return order
    travel0 = max(float(move_times(q[order], velocity).sum()), 1e-9)

    def cost(o: np.ndarray) -> float:
        return _imbalance(q[o], joints) + TRAVEL_WEIGHT * float(move_times(q[o], velocity).sum()) / travel0

    current = best = cost(order)
    best_order = order.copy()
    temperature = 0.05
    cooling = (1e-4 / temperature) ** (1.0 / ANNEAL_STEPS)
    for _ in range(ANNEAL_STEPS):
        i, j = np.sort(rng.choice(k, 2, replace=False))
        trial = order.copy()
        if rng.random() < 0.5:
            trial[i : j + 1] = trial[i : j + 1][::-1]
        else:
            trial[i], trial[j] = trial[j], trial[i]
        value = cost(trial)
        if value < current or rng.random() < np.exp((current - value) / temperature):
            order, current = trial, value
            if value < best:
                best, best_order = value, trial.copy()
        temperature *= cooling
    return best_order
