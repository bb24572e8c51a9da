"""REPORT.json of a calibration of several targets on a tree (:mod:`pincal.report.model_tree`), from
:func:`pincal.fit.tree_calibration.calibrate_tree`'s result: the parameters and the identifiability as a
chain's report words them, each target's points and errors, each session's registration."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from pincal._version import __version__
from pincal.fit.metrics import ErrorSummary
from pincal.fit.tree_calibration import TreeCalibration
from pincal.model.tree import KinematicTree
from pincal.report.document import REPORT_VERSION, identifiability_report, mimics_json, parameters_report
from pincal.report.model import PositionStats, Sha256, Sources, couplings_part, registration_pair
from pincal.report.model_level_choice import level_choice_part
from pincal.report.model_tree import TargetErrors, TargetJson, TreeChainJson, TreeReport

if TYPE_CHECKING:
    from pincal.fit.level_choice import LevelChoice
    from pincal.measurements.couplings import ReadingCoupling

__all__ = ["target_errors", "orientation_of", "tree_report"]


def target_errors(point_errors: np.ndarray, numbers: tuple[int, ...], turns: np.ndarray | None = None
                  ) -> TargetErrors:
    """A target's errors: ``point_errors`` (K, P) [m] of every point, NaN where not seen; ``numbers``: its
    points (1-based), each seen in some row (:func:`pincal.fit.tree_calibration.tree_rows`); ``turns``: its
    orientation errors (K,) [rad], NaN where not seen, or None (its orientation not measured)."""
    mine = np.asarray(point_errors, dtype=float)[:, [p - 1 for p in numbers]] * 1000.0

    def stats(values: np.ndarray) -> PositionStats:
        return ErrorSummary.of(values[np.isfinite(values)], "mm").as_dict()  # type: ignore[return-value]

    out: TargetErrors = {"seen": int(np.isfinite(mine).sum()), "position": stats(mine),
                         "position_per_point": [stats(mine[:, i]) for i in range(len(numbers))]}
    if turns is not None:
        seen = np.degrees(np.asarray(turns, dtype=float)[np.isfinite(turns)])
        out["orientation_seen"] = int(seen.size)
        if seen.size:
            out["orientation"] = ErrorSummary.of(seen, "deg").as_dict()  # type: ignore[typeddict-item]
    return out


def orientation_of(errors: np.ndarray | None, t: int) -> np.ndarray | None:
    """Target ``t``'s orientation errors (K,) [rad] of a result's (K, T), None where it has none."""
    return None if errors is None or not np.isfinite(errors[:, t]).any() else errors[:, t]


def tree_report(result: TreeCalibration, nominal: TreeCalibration, tree: KinematicTree, sources: Sources,  # noqa: PLR0913
                notes: list[str], digest: tuple[Sha256, dict[str, str]], couplings: Sequence[ReadingCoupling] = (),
                choice: LevelChoice | None = None) -> TreeReport:
    """The REPORT.json of ``result`` (``nominal``: the nominal model registered to the same rows, for the
    errors before); ``digest``: the corrected URDF's SHA-256 and the xacro arguments; ``couplings``: the run's
    ``--coupling`` as it decided them (``couplings``); ``choice``: how ``--level auto`` chose (``level_choice``)."""
    targets: list[TargetJson] = [{
        "tip_link": target.link, "points": list(target.spec.points), "joints": list(target.chain.joint_names),
        "points_m": result.target.points[[p - 1 for p in target.spec.points]].tolist(),
        "nominal_errors": target_errors(nominal.point_errors, target.spec.points,
                                        orientation_of(nominal.orientation_errors, t)),
        "calibration_errors": target_errors(result.point_errors, target.spec.points,
                                            orientation_of(result.orientation_errors, t)),
    } for t, target in enumerate(tree.targets)]
    for t, entry in enumerate(targets):
        if orientation_of(result.orientation_errors, t) is not None:  # R_T,t as one chain's target rotation
            entry["rotation_xyzw"] = Rotation.from_matrix(result.target.rotation[t]).as_quat().tolist()
    counts = [int(np.sum(result.row_sessions == s)) for s in range(len(result.session_names))]
    return {
        "pincal_version": __version__, "report_version": REPORT_VERSION, "method": None, "level": result.level,
        "model": "joint placements", "sources": sources,
        "chain": _chain(tree),
        "targets": targets,
        "parameters": parameters_report(result),
        "identifiability": identifiability_report(result),
        "registration": registration_pair(result.target.registration, result.target.registration),
        "sessions": [{"name": name, "rows": count, "registration": registration_pair(r, r)}
                     for name, count, r in zip(result.session_names, counts, result.target.registrations)],
        "noise": {"sigma_pos_mm": result.sigma_pos_m * 1000.0,
                  "sigma_rot_deg": None if result.sigma_rot_rad is None else float(np.degrees(result.sigma_rot_rad))},
        "notes": notes, "warnings": [], "urdf_sha256": digest[0], "xacro_args": digest[1],
        **level_choice_part(choice), **couplings_part(couplings),
    }


def _chain(tree: KinematicTree) -> TreeChainJson:
    """REPORT.json ``chain`` of a tree: its root link, its joints once with their kinds, those that follow another."""
    out: TreeChainJson = {"root_link": tree.targets[0].chain.root_link, "joints": list(tree.joint_names),
                          "joint_kinds": [j.kind for j in tree.joints]}
    mimics = mimics_json(tree.joints)
    if mimics:
        out["mimics"] = mimics
    return out
