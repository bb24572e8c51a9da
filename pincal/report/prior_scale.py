"""The prior's scales in words, from REPORT.json's ``identifiability.selection.prior_scale``: the line
calibrate and diagnose print and the HTML page shows (no numpy: the command line imports it)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = ["prior_scale_line"]


def _scales(scale: Mapping[str, Any]) -> str:
    return (f"lengths {scale['translation_mm']:.3g} mm, angles {scale['rotation_deg']:.3g}°, "
            f"joint zeros {scale.get('joint_zero_deg', scale['rotation_deg']):.3g}°")


def prior_scale_line(selection: Mapping[str, Any] | None) -> str | None:
    """``prior scales: lengths X mm, angles Y°, joint zeros Z° (estimated)`` from REPORT.json's
    ``identifiability.selection`` (None without a prior): the scales the fit used, and whether they are
    the rows' estimate, the defaults the estimate did not beat (with the estimate and why) or given."""
    scale = (selection or {}).get("prior_scale")
    if not scale:
        return None
    line = f"prior scales: {_scales(scale)}"
    if scale.get("estimated"):
        return line + " (estimated)"
    estimate = scale.get("estimate")
    if estimate is None:
        return line + (" (given)" if scale.get("reason", "given") == "given" else f" ({scale['reason']})")
    why = scale["reason"].removeprefix("the default scales: ")
    return line + f" (the defaults; estimated {_scales(estimate)}: {why})"
