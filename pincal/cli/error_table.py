"""The table of eq 24 errors that calibrate, evaluate, diagnose and demo print: its header, a set of
rows' columns, and a row per target point when the target has several (the markers of one rigid body).

Positions in mm, orientations in deg (Franaszek & Marvel 2022, eq 24; :mod:`pincal.fit.metrics`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from pincal.fit.metrics import ErrorSummary, PoseErrors

__all__ = ["HEADER", "error_columns", "point_rows"]

HEADER = (
    f"{'':24s} {'pos mean':>9s} {'pos RMS':>9s} {'pos max':>9s}  {'rot mean':>9s} {'rot RMS':>9s} {'rot max':>9s}\n"
    f"{'':24s} {'[mm]':>9s} {'[mm]':>9s} {'[mm]':>9s}  {'[deg]':>9s} {'[deg]':>9s} {'[deg]':>9s}"
)


def _position_columns(position: ErrorSummary) -> str:
    return f"{position.mean:9.4f} {position.rms:9.4f} {position.max:9.4f}"


def error_columns(errors: PoseErrors) -> str:
    """Mean, RMS and max of the position [mm] and orientation [deg] errors, under :data:`HEADER`."""
    rot = errors.rotation
    text = _position_columns(errors.position)
    text += f"  {rot.mean:9.4f} {rot.rms:9.4f} {rot.max:9.4f}" if rot else "  " + " " * 9 + "(no orientation data)"
    return text


def point_rows(errors: PoseErrors) -> list[str]:
    """``  point P`` rows under a row of ``errors``: each target point's position error [mm] over the rows
    (``position_per_point`` in the JSON), with a target of several points; none for one point. The
    orientation is the target's, one per row: it stays in the row above."""
    count = errors.position_m.shape[1]
    return [f"{f'  point {p + 1}':24s} {_position_columns(errors.point(p))}" for p in range(count)] if count > 1 else []
