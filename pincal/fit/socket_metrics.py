"""How well a model puts a ball seated in fixture sockets where the sockets are.

No registration is needed (the MUKCa authors' measures, Franzese, Spahn et al.
2025). With p_k the model's ball centre of row k in the URDF root frame and
p̄_i the mean of the rows in socket i of one placement:

* **consistency** — the RMS spread of the ball centre within a socket,
  sqrt(mean_k ‖p_k − p̄_i(k)‖²) [mm], over the rows of every socket (the
  authors plot sqrt(σ_0² + σ_1²) with σ_i² the spread of socket i: about √2
  times this for two sockets of equal counts);
* **distortion** — for each pair of sockets of a placement, |‖p̄_a − p̄_b‖ −
  ‖f_a − f_b‖| [mm], the error of the computed socket distance against the
  fixture's (50 mm for theirs); the mean over pairs.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from pincal.measurements.fixture import FixtureData
from pincal.model.chain import KinematicChain

__all__ = ["PlacementMetrics", "FixtureMetrics", "metrics_of_positions", "fixture_metrics"]


@dataclass(frozen=True)
class PlacementMetrics:
    """Consistency and distortion of one placement.

    Attributes:
        placement: its name.
        rows: rows evaluated.
        consistency_mm: RMS spread of the ball centre within its socket [mm].
        distortion_mm: mean over socket pairs of the distance error [mm].
        pairs: (socket a, socket b, computed distance [mm], fixture distance [mm]).
        squared_spread_mm2: sum of ‖p_k − p̄_i‖² [mm²] (pooling across placements).
    """

    placement: str
    rows: int
    consistency_mm: float
    distortion_mm: float
    pairs: tuple[tuple[str, str, float, float], ...]
    squared_spread_mm2: float

    def as_dict(self) -> dict[str, Any]:
        return {
            "placement": self.placement,
            "rows": self.rows,
            "consistency_mm": self.consistency_mm,
            "distortion_mm": self.distortion_mm,
            "socket_distances": [{"a": a, "b": b, "computed_mm": c, "fixture_mm": f} for a, b, c, f in self.pairs],
        }


@dataclass(frozen=True)
class FixtureMetrics:
    """Per placement, and over all of them: consistency pooled over every row, distortion averaged over every pair."""

    placements: tuple[PlacementMetrics, ...]

    @property
    def consistency_mm(self) -> float:
        rows = sum(p.rows for p in self.placements)
        return float(np.sqrt(sum(p.squared_spread_mm2 for p in self.placements) / rows))

    @property
    def distortion_mm(self) -> float:
        errors = [abs(c - f) for p in self.placements for _, _, c, f in p.pairs]
        return float(np.mean(errors))

    def as_dict(self) -> dict[str, Any]:
        return {
            "consistency_mm": self.consistency_mm,
            "distortion_mm": self.distortion_mm,
            "placements": [p.as_dict() for p in self.placements],
        }


def metrics_of_positions(positions: npt.ArrayLike, data: FixtureData) -> FixtureMetrics:
    """Consistency and distortion of the ball centres ``positions`` (K, 3) [m] of ``data``'s rows."""
    positions = np.asarray(positions, dtype=float) * 1000.0  # mm
    fixture = data.fixture
    out = []
    for s, name in enumerate(data.placements):
        mine = data.placement == s
        sockets = np.unique(data.socket[mine])
        means = {int(i): positions[mine & (data.socket == i)].mean(axis=0) for i in sockets}
        spread = sum(float(np.sum((positions[mine & (data.socket == i)] - means[int(i)]) ** 2)) for i in sockets)
        pairs = tuple(
            (fixture.names[a], fixture.names[b], float(np.linalg.norm(means[int(a)] - means[int(b)])),
             fixture.distance(a, b) * 1000.0)
            for n, a in enumerate(sockets) for b in sockets[n + 1:]
        )
        rows = int(np.sum(mine))
        out.append(PlacementMetrics(name, rows, float(np.sqrt(spread / rows)),
                                    float(np.mean([abs(c - f) for _, _, c, f in pairs])), pairs, spread))
    return FixtureMetrics(tuple(out))


def fixture_metrics(chain: KinematicChain, data: FixtureData, ball: npt.ArrayLike) -> FixtureMetrics:
    """Consistency and distortion of ``chain`` with the ball centre ``ball`` (3,) [m] in its tool frame."""
    poses = chain.poses(data.q)
    positions = poses.tool_positions + poses.tool_rotations @ np.asarray(ball, dtype=float)
    return metrics_of_positions(positions, data)
