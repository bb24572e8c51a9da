"""The units of the effects' values (:mod:`pincal.model.effects`), which depend on the joints' kinds.

A joint effect's value is a shift of its joint [rad, or m for a prismatic joint] per unit of what
drives it: a compliance's gravity load [N·m of a revolute joint's torque, N of a prismatic joint's
force] — its own joint's, or its ``driver``'s —, a coupling's driver reading [rad or m]. So a
compliance is in rad/(N·m), m/N, rad/N (a revolute joint under a prismatic joint's load) or m/(N·m)
(a prismatic joint under a revolute joint's torque).

A compliance of unknown masses (``moments``) follows g₀ × mass moments instead of a load: its values are
g₀ · (mass moment) / k, a shift [rad, or m for a prismatic joint] (:mod:`pincal.model.mass_moments`; a
combination led by a link's mass, rather than its moment, is per metre of its lever arm: rad/m).
A lateral compliance turns a revolute joint about its two lateral axes per N·m of gravity moment about them:
rad/(N·m) (rad per mass moment without masses, as a compliance's; :mod:`pincal.model.lateral`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Protocol

__all__ = ["EffectJoints", "shift_unit", "load_unit", "value_unit", "effect_unit"]


class EffectJoints(Protocol):
    """What the unit of an effect depends on (:class:`pincal.model.effects.Effect` has it)."""

    @property
    def type(self) -> str: ...

    @property
    def joint(self) -> str | None: ...

    @property
    def driver(self) -> str | None: ...


def shift_unit(prismatic: bool) -> str:
    """The unit of a joint's reading and of its shift: ``m`` for a prismatic joint, ``rad`` otherwise."""
    return "m" if prismatic else "rad"


def load_unit(prismatic: bool) -> str:
    """The unit of a joint's gravity load: the force of a prismatic joint [``N``], the torque of a
    revolute one [``N·m``]."""
    return "N" if prismatic else "N·m"


def value_unit(kind: str, prismatic: bool = False, driver_prismatic: bool | None = None) -> str:
    """The unit of the values of an effect of type ``kind`` (module docstring), its joint ``prismatic``
    or not, the joint that drives it ``driver_prismatic`` or not (None: the joint itself)."""
    shift = shift_unit(prismatic)
    driver = prismatic if driver_prismatic is None else driver_prismatic
    if kind == "compliance":
        return f"{shift}/N" if driver else f"{shift}/(N·m)"
    if kind == "lateral":  # a revolute joint's deflection about its lateral axes per N·m of moment about them
        return "rad/(N·m)"
    if kind in ("cyclic", "backlash"):
        return shift
    if kind == "coupling" and driver != prismatic:
        return f"{shift}/{shift_unit(driver)}"
    units = {"drift": "m/s", "thermal": "1/K", "pause_step": "m"}
    return units.get(kind, "(relative)")  # encoder_scale, sensor_scale, a coupling of like joints


def effect_unit(effect: EffectJoints, kinds: Mapping[str, str]) -> str:
    """The unit of ``effect``'s values on a chain whose joints have the kinds ``kinds`` (joint name →
    ``revolute``, ``continuous`` or ``prismatic``, as REPORT.json's ``chain``): its joint's and its driver's."""
    def prismatic(name: str | None) -> bool:
        return kinds.get(name or "") == "prismatic"

    if getattr(effect, "moments", ()):  # a compliance of unknown masses: the shift's unit (module docstring)
        return shift_unit(prismatic(effect.joint))
    return value_unit(effect.type, prismatic(effect.joint), None if effect.driver is None else prismatic(effect.driver))
