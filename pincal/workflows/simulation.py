"""``pincal simulate``'s job: the paper's experiment simulated on the packaged KUKA LWR 4+ and
written as CSV v1 files with the truth beside them (:func:`simulate_to_directory`)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from pincal._version import __version__
from pincal.errors import PincalError, did_you_mean
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain, xyz_rpy_from_pose
from pincal.model.dh.table import DEVIATION_SETS, KUKA_LWR4_DH
from pincal.model.effects import effect_to_dict, parse_effect
from pincal.outputs import write_text
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf
from pincal.workflows.paths import ensure_directory

if TYPE_CHECKING:  # imported where used, so `pincal calibrate` loads none of these
    from pincal.simulation.paper import SimulatedExperiment, SimulationSettings

__all__ = ["simulate_to_directory"]


def simulate_to_directory(
    out_dir: str | Path, deviations: str, settings: SimulationSettings, effects: Sequence[str] = ()
) -> tuple[SimulatedExperiment, dict[str, Any]]:
    """Simulate the paper's experiment on the packaged KUKA LWR 4+ and write
    ``calibration.csv``, ``validation.csv`` and ``truth.json`` into ``out_dir``.

    ``effects`` (``TYPE:JOINT:VALUE`` strings, see :func:`pincal.model.effects.parse_effect`)
    are injected into the data without being declared in it; truth.json records them.
    """
    from pincal.simulation.paper import simulate_experiment

    if deviations not in DEVIATION_SETS:
        raise PincalError(f"unknown deviation set '{deviations}'; use one of {sorted(DEVIATION_SETS)}")
    urdf = kuka_lwr4plus_urdf()
    chain = KinematicChain.from_urdf(urdf, KUKA_FLANGE_LINK)
    injected = [parse_effect(text) for text in effects]
    for effect, _ in injected:
        for name in (effect.joint, effect.driver):
            if name is not None and name not in chain.joint_names:
                raise PincalError(f"effect '{effect.label}': no joint '{name}'; "
                                  f"{did_you_mean(name, chain.joint_names, 'joints')}")
    experiment = simulate_experiment(chain, KUKA_LWR4_DH, DEVIATION_SETS[deviations], settings, effects=injected)
    out = ensure_directory(out_dir)
    write_measurements(out / "calibration.csv", experiment.calibration)
    write_measurements(out / "validation.csv", experiment.validation)
    xyz, rpy = xyz_rpy_from_pose(experiment.tool)
    tool_arg = ",".join(repr(float(v)) for v in (*xyz, *rpy))
    truth = {
        "pincal_version": __version__,
        "robot": "KUKA LWR 4+ (Franaszek & Marvel 2022, Table 1)",
        "deviations": deviations,
        "settings": {
            "sigma_pos_mm": settings.sigma_pos_mm,
            "sigma_rot_deg": settings.sigma_rot_deg,
            "seed": settings.seed,
            "cpa_rows_per_joint": settings.n_cpa,
            "calibration_rows": settings.n_calibration,
            "validation_rows": settings.n_validation,
        },
        "dh": {
            "alpha_rad": experiment.truth.alpha.tolist(),
            "epsilon_rad": experiment.truth.epsilon.tolist(),
            "r_m": experiment.truth.r.tolist(),
            "d_m": experiment.truth.d.tolist(),
        },
        "registration": experiment.registration.as_dict(),
        "tool": {"parent_link": KUKA_FLANGE_LINK, "xyz_m": xyz.tolist(), "rpy_rad": rpy.tolist()},
        "effects": [effect_to_dict(e, v) for e, v in injected],
        "calibrate_command": (
            f"pincal calibrate {urdf} {out / 'calibration.csv'} --method 2 "
            f"--tool {tool_arg} --tool-parent {KUKA_FLANGE_LINK} "
            f"--out corrected.urdf --report REPORT.json"
        ),
    }
    write_text(out / "truth.json", json.dumps(truth, indent=2) + "\n")
    return experiment, truth
