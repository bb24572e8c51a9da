"""effects.yaml: what a corrected URDF cannot carry, where a controller can read it.

A URDF holds the geometry only. Joint readings taken against another joint (``--coupling``,
eq C1 of :mod:`pincal.measurements.couplings`) and the effects ``diagnose`` adopted
(:mod:`pincal.model.effects`) are written beside it — ``CORRECTED.effects.yaml`` for
``--out CORRECTED.urdf`` (:func:`effects_path`) — whenever the result has either, from the
REPORT.json document written with it, so both say the same. At a reading r (rad, or m for a
prismatic joint) a controller takes

    q_J = r_J − F · r_I            for each coupling J = F × I (every driver as read; eq C1)
    q_J = F · r_I                  for each such coupling marked ``follows``: J has no reading (eq M1)
    actual_j = q_j + Σ shift_j(q)  for each joint effect on j (shift formulas of the module
                                   docstring of :mod:`pincal.model.effects`, in words per entry)

and gives ``actual`` to the corrected URDF's kinematics; a ``lateral`` compliance (``side: bend``, eq L1–L3 of
:mod:`pincal.model.lateral`) turns the chain at its joint about the joint's two lateral axes. ``drift``,
``sensor_scale`` and ``pause_step``
describe the calibration's sensor, not the robot: listed with ``side: measurement``, for no controller.
``thermal`` (eq T1 of :mod:`pincal.model.thermal`) scales every length of the URDF with the arm's
temperature: ``side: geometry``, for a controller that reads that temperature.
:func:`read_effects_file` reads the file back (the effects and couplings as pincal's own types).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from pincal._version import __version__
from pincal.errors import PincalError
from pincal.measurements.couplings import ReadingCoupling, couplings_from_report
from pincal.model.effect_units import effect_unit
from pincal.model.effects import APPROACH_MIN_STEP, BEND_EFFECTS, SENSOR_EFFECTS, Effect, effect_from_dict
from pincal.outputs import write_text

__all__ = ["SCHEMA", "SCHEMA_VERSION", "EffectsFile", "effects_path", "carried", "written_line", "effects_document",
           "remove_effects_file", "write_effects_file", "read_effects_file"]

#: The file's ``schema`` and ``schema_version``: a new key may appear; a changed meaning gets a new version.
SCHEMA = "pincal-effects"
SCHEMA_VERSION = 1

_HEADER = ("# What the URDF named below cannot carry, for a controller (docs/diagnose.md, 'effects.yaml for a\n"
           "# controller'). Written by pincal with REPORT.json; both say the same. Joint values in rad (m for a\n"
           "# prismatic joint).\n")


def effects_path(out_urdf: str | Path) -> Path:
    """``CORRECTED.effects.yaml`` beside ``--out CORRECTED.urdf`` (the last suffix replaced)."""
    out = Path(out_urdf)
    return out.with_name(f"{out.stem}.effects.yaml")


def carried(report: Mapping[str, Any]) -> str:
    """What of ``report`` a URDF cannot carry, in words (``1 coupling and 2 effects``); "" for nothing."""
    counts = [(len(report.get(key) or []), key[:-1]) for key in ("couplings", "effects")]
    return " and ".join(f"{n} {name}{'s' if n > 1 else ''}" for n, name in counts if n)


def written_line(path: str | Path, report: Mapping[str, Any]) -> str:
    """The console's one line on an effects.yaml written at ``path`` for ``report``."""
    return f"the URDF cannot carry {carried(report)}: written to {path} (for a controller) and the report"


def _side(effect: Effect) -> str:
    """``joint`` (a shift of a joint value), ``bend`` (the chain turned at a joint about its lateral axes),
    ``geometry`` (the URDF's lengths) or ``measurement`` (the sensor's)."""
    if effect.type in BEND_EFFECTS:
        return "bend"
    return "measurement" if effect.type in SENSOR_EFFECTS else "geometry" if effect.type == "thermal" else "joint"


def _lateral_equation(effect: Effect) -> str:
    """A lateral compliance in words (eq L1–L3 of :mod:`pincal.model.lateral`), for a controller author."""
    joint = effect.joint
    axes = (f"right after {joint}'s motion, turn the chain (the next link's origin and all beyond) about {joint}'s "
            "lateral axis u by angle_u, then about v by angle_v; u = the joint frame's coordinate axis least aligned "
            "with the joint axis a, made orthogonal to a (x for a z axis), v = a x u; ")
    if effect.moments:
        return axes + ("angle_u = sum over the moments u/PARAMETER:LINK of value x L_u[b](q), angle_v likewise over "
                       f"v/...; L_u[b](q) is {joint}'s gravity moment about u per unit of mass moment b over |g| "
                       "(eq M1, M3 of pincal.model.mass_moments); each value is g x the combination of mass moments / "
                       f"{joint}'s lateral stiffness (mass moments unknown)")
    return axes + (f"angle_u = value[0] x M_u(q), angle_v = value[1] x M_v(q), M_u, M_v the gravity moments {joint} "
                   "carries about u and v [N·m] (Pinocchio's rnea at rest on the URDF's inertias, plus payload_kg at "
                   "payload_point_m: the moment of the wrench it transmits, in its frame)")


def _equation(effect: Effect, entry: Mapping[str, Any]) -> str:
    """The shift of an effect in words (:mod:`pincal.model.effects`), for a controller author: q the joint
    values after the couplings, tau(q) the gravity torques there [N·m, or N for a prismatic joint]."""
    joint, driver = effect.joint, effect.driver or effect.joint
    head = f"actual {joint} = q[{joint}] + "
    if effect.type in BEND_EFFECTS:
        return _lateral_equation(effect)
    if effect.moments:
        return (head + f"sum over b of value[b] x L[b](q), b each mass moment of moments (PARAMETER:LINK, m its mass, "
                f"mx my mz its first moment in its joint frame) and L[b](q) {joint}'s gravity load per unit of it "
                "over |g| (eq M1-M2 of pincal.model.mass_moments: Pinocchio's jointBodyRegressor after rnea at rest, "
                f"carried to {joint} and projected on its axis); each value is g x the combination of mass moments "
                f"named in combinations / {joint}'s stiffness (mass moments unknown)")
    if effect.type == "compliance":
        return (head + f"value x tau(q)[{driver}] (the gravity torques of Pinocchio's computeGeneralizedGravity on "
                "the URDF's inertias, plus payload_kg at payload_point_m)")
    if effect.type == "encoder_scale":
        return head + f"value x q[{joint}]"
    if effect.type == "cyclic":
        h = effect.harmonic
        return head + f"sin x sin({h} x q[{joint}]) + cos x cos({h} x q[{joint}])"
    if effect.type == "coupling":
        return head + f"value x q[{driver}]"
    if effect.type == "backlash" and effect.source == "gravity":
        return head + f"value x sign(tau(q)[{joint}]) (the gear flank gravity pushes it to)"
    if effect.type == "backlash":
        return head + (f"value x the direction of {joint}'s last move (+1 up, -1 down; a move under "
                       f"{APPROACH_MIN_STEP:g} keeps the flank; 0 before the first move)")
    if effect.type == "drift":
        return ("measurement side, not for a controller: the sensor's registration translation moved by "
                f"(t - {entry.get('time_reference_s')} s) x value [m/s] inside the time span of the calibration")
    if effect.type == "pause_step":
        return ("measurement side, not for a controller: the sensor's registration translation moved by value [m] "
                "after the calibration's pause number pause")
    if effect.type == "thermal":
        return (f"every length of the URDF (joint origins' xyz and the tool) x (1 + value x (T - "
                f"{entry.get('temperature_reference_c')} degC)), T the arm's temperature in the calibration's "
                f"column {entry.get('temperature_column')!r}; held at the ends of the fitted range "
                f"{entry.get('temperature_range_c')} degC, never extrapolated")
    return "measurement side, not for a controller: the sensor's lengths were scaled by 1 + value"


def _coupling_equation(entry: Mapping[str, Any]) -> str:
    """A ``couplings`` entry's equation in words: a reading taken against its driver (eq C1), or, ``follows``,
    a joint without a reading computed from its driver's (eq M1, offset 0)."""
    joint, driver = entry["joint"], entry["driver"]
    if entry.get("follows"):
        return (f"q[{joint}] = factor x r[{driver}] (eq M1: {joint} has no reading, it follows {driver}; "
                "the driver as read)")
    return (f"q[{joint}] = r[{joint}] - factor x r[{driver}] (eq C1: the controller's reading includes factor x "
            "the driver's)")


def effects_document(report: Mapping[str, Any], urdf: str | Path, report_path: str | Path) -> dict[str, Any]:
    """The effects.yaml mapping of a REPORT.json ``report``: its ``couplings`` and ``effects`` (each
    :func:`~pincal.model.effects.effect_to_dict`'s keys plus ``unit``, ``side`` and ``equation``)."""
    chain = report.get("chain") or {}
    kinds = dict(zip(chain.get("joints", []), chain.get("joint_kinds", [])))
    tool = report.get("tool") or {}
    points = np.asarray(tool.get("points_m") or [tool.get("xyz_m", [0.0, 0.0, 0.0])], dtype=float)
    couplings = [{**c, "unit": "(relative)", "equation": _coupling_equation(c)} for c in report.get("couplings") or []]
    effects = []
    for entry in report.get("effects") or []:
        effect, _ = effect_from_dict(entry)
        keep = {k: v for k, v in entry.items() if k not in ("target_change", "advice")}
        span = report.get("temperature_range_c") or {}
        context = {"time_reference_s": report.get("time_reference_s"), "temperature_column": report.get(
            "temperature_column"), "temperature_reference_c": span.get("mean"),
            "temperature_range_c": [span.get("min"), span.get("max")]}
        if effect.type == "thermal":  # what a controller needs besides alpha: T_ref, the column, the range [°C]
            keep.update(temperature_column=context["temperature_column"],
                        temperature_reference_c=context["temperature_reference_c"],
                        temperature_range_c=context["temperature_range_c"])
        effects.append({**keep, "unit": effect_unit(effect, kinds),
                        "side": _side(effect), "equation": _equation(effect, context)})
    return {
        "schema": SCHEMA,
        "schema_version": SCHEMA_VERSION,
        "written_by": f"pincal {__version__}",
        "urdf": str(urdf),
        "urdf_sha256": report.get("urdf_sha256"),
        "report": str(report_path),
        "apply": ["r = the controller's joint readings [rad, or m for a prismatic joint]",
                  "q = r, then each entry of couplings applied (every driver from r as read; q = r without any)",
                  *(["an entry of couplings with follows: q[joint] = factor x r[driver], the joint has no reading"]
                    if any(c.get("follows") for c in couplings) else []),
                  "actual = q + the shift of each entry of effects with side joint, evaluated at q",
                  "the joint values of the URDF named in urdf are actual; side measurement is the sensor's",
                  *(["side bend (lateral): the chain turned at the joint about its lateral axes, as its equation "
                     "says, the angles evaluated at q"] if any(e["side"] == "bend" for e in effects) else []),
                  *(["side geometry (thermal): the URDF's lengths at the arm's temperature, as its equation says"]
                    if any(e["side"] == "geometry" for e in effects) else [])],
        "tool_parent": tool.get("parent_link"),
        "payload_kg": float(report.get("payload_kg", 0.0)),
        "payload_point_m": points.mean(axis=0).tolist(),
        "payload_point_frame": f"{tool.get('parent_link')} (the mean of the report's target points)",
        "couplings": couplings,
        "effects": effects,
    }


def remove_effects_file(out_urdf: str | Path) -> Path | None:
    """Remove the ``CORRECTED.effects.yaml`` (:func:`effects_path`) pincal wrote beside ``out_urdf`` for an
    earlier run, if there is one (a file of that name not pincal's is left alone); the file removed, or None."""
    path = effects_path(out_urdf)
    try:
        if yaml.safe_load(path.read_text(encoding="utf-8")).get("schema") == SCHEMA:
            path.unlink()
            return path
    except (OSError, UnicodeDecodeError, yaml.YAMLError, AttributeError):
        pass  # absent, or not ours: left alone
    return None


def write_effects_file(out_urdf: str | Path, report_path: str | Path, report: Mapping[str, Any]) -> Path | None:
    """Write ``CORRECTED.effects.yaml`` (:func:`effects_path`) of ``report`` when it has couplings or effects
    (atomically: :func:`pincal.outputs.write_text`); without either, remove a file of that name pincal wrote
    for an earlier run (it would pair the new URDF with old effects). Returns the file written, or None."""
    path = effects_path(out_urdf)
    if not carried(report):
        remove_effects_file(out_urdf)
        return None
    document = effects_document(report, out_urdf, report_path)
    write_text(path, _HEADER + yaml.safe_dump(document, sort_keys=False, allow_unicode=True, width=110))
    return path


@dataclass(frozen=True)
class EffectsFile:
    """An effects.yaml read back.

    Attributes:
        couplings: the readings taken against another joint (eq C1), and the joints that follow one
            (``follows``, eq M1).
        effects: each effect with its values, joint and measurement side alike.
        payload_kg / payload_point_m: the point mass the gravity torques include [kg] and where it sits,
            in ``tool_parent``'s frame [m] (3,).
        urdf / urdf_sha256: the corrected URDF the file goes with.
    """

    couplings: tuple[ReadingCoupling, ...]
    effects: tuple[tuple[Effect, np.ndarray], ...]
    payload_kg: float
    payload_point_m: np.ndarray
    tool_parent: str | None
    urdf: str
    urdf_sha256: str | None


def read_effects_file(path: str | Path) -> EffectsFile:
    """Read an effects.yaml (:func:`write_effects_file`).

    Raises:
        PincalError: not a readable effects.yaml of this schema version (one line naming the file).
    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text(encoding="utf-8"))
        if not isinstance(document, dict) or document.get("schema") != SCHEMA:
            raise ValueError(f"not a {SCHEMA} file")
        if document.get("schema_version") != SCHEMA_VERSION:
            raise ValueError(f"schema_version {document.get('schema_version')!r}, this pincal reads {SCHEMA_VERSION}")
        point = np.asarray(document["payload_point_m"], dtype=float).reshape(3)
        payload = float(document["payload_kg"])
        if not (math.isfinite(payload) and payload >= 0 and np.isfinite(point).all()):
            raise ValueError("payload_kg and payload_point_m must be finite, payload_kg >= 0")
        return EffectsFile(
            couplings=couplings_from_report(document.get("couplings") or [], str(path)),
            effects=tuple(effect_from_dict(entry) for entry in document.get("effects") or []),
            payload_kg=payload, payload_point_m=point, tool_parent=document.get("tool_parent"),
            urdf=str(document["urdf"]), urdf_sha256=document.get("urdf_sha256"),
        )
    except FileNotFoundError:
        raise PincalError(f"{path}: no such effects file") from None
    except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError, ValueError) as exc:
        raise PincalError(f"{path}: not a readable pincal effects.yaml ({exc}); write it again with pincal "
                          "calibrate or diagnose") from None
