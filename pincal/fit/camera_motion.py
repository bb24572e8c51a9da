"""The mounted frame's motion between two images, as a model predicts it and as the images measure it, and the
floor the corners' noise puts under their comparison.

The mounted frame is the camera eye in hand and the board eye to hand (:mod:`pincal.model.camera_view`); at image
k it is ``T_k = base_T_tip(q_k) M`` (:func:`pincal.fit.camera_calibration.mounted_frames`). Between two images j, k
of one session (the board, or the camera, fixed in the world W):

* predicted: ``D̂_jk = T_j⁻¹ T_k``                                                                          (R1)
* measured, from each image's board pose ``V_k = camera_T_board`` (PnP of its corners):
  eye in hand ``D_jk = V_j V_k⁻¹`` (``T_k V_k = W``), eye to hand ``D_jk = V_j⁻¹ V_k`` (``W T_k = V_k``)     (R2)
* the error ``E = D_jk⁻¹ D̂_jk``: its translation's length [mm] and its rotation's angle [deg]              (R3)

W enters neither side: the error measures the kinematics and the mount, whatever the world frame.

The floor: the measured motion errs by what the corners' noise moves each PnP pose. With ``V_k = V̂_k exp(ξ_k)``
(Pinocchio's exp6, ξ = (v, ω), linear first), p = R b + t of a board point b moves by ``R v − R [b]× ω``, so the
corners' pixels by ``J_k ξ_k`` with ``J_k = (dpixel/dp) [R, −R [b]×]``
(:func:`pincal.model.pinhole.projection_jacobians`), and to first order

* ``Σ_k = σ² (J_kᵀ J_k)⁻¹``, σ² = Σ r² / (2 M − 6 K) the PnP residuals r of the K placed images' M corners, pooled  (R4)
* ``D_jk = D̂ exp(η)``: eye in hand ``η = Ad(V̂_k)(ξ_j − ξ_k)``, eye to hand ``η = ξ_k − Ad(D̂⁻¹) ξ_j``             (R5)
* floor of the pair: ``(√tr Σ_η,v, √tr Σ_η,ω)`` [mm, deg]: the RMS error a perfect model's prediction shows     (R6)

σ comes from PnP's own residuals, not from a model's reprojection: the floor is then the same for every model
compared, and a model that misses its corners does not raise the floor it is judged against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares
from scipy.stats import chi2

from pincal.errors import CalibrationError
from pincal.fit.camera_calibration import images_of
from pincal.fit.camera_start import MIN_CORNERS, board_poses
from pincal.measurements.camera_csv import CornerSet
from pincal.model.camera_view import Arrangement
from pincal.model.pinhole import CameraIntrinsics, project, projection_jacobians
from pincal.residuals.so3 import log3, skew

__all__ = ["FLOOR_LEVEL", "MeasuredMotions", "image_pairs", "relative_motions", "motion_errors", "measured_motions",
           "within_floor"]

#: The level at which a model's errors are "within the floor": a perfect model's RMS error exceeds the bound with
#: this probability (the conventional 5 %), its mean square over P pairs taken as the floor's times a chi-square of
#: 3P degrees of freedom over 3P (:func:`within_floor`). An approximation: consecutive pairs share an image, and a
#: pair's error is not isotropic (PnP's tilt dominates), both of which widen the true spread a little.
FLOOR_LEVEL = 0.05


@dataclass(frozen=True)
class MeasuredMotions:
    """The motions the images measure (eq R2) and their floor (eq R6).

    Attributes:
        pairs: the images of each pair, indices into the corner set's images (P, 2).
        motions: D_jk of each pair (P, 4, 4) [m].
        floor: each pair's floor (P, 2) [mm, deg].
        noise_px: σ of eq R4, the corners' noise per coordinate the PnP residuals show [px] (None: no pair).
        unplaced: the images PnP cannot place (fewer than 4 corners, all on one line, or solvePnP finds no pose),
            left out of the pairs.
    """

    pairs: np.ndarray
    motions: np.ndarray
    floor: np.ndarray
    noise_px: float | None
    unplaced: tuple[str, ...]


def image_pairs(corners: CornerSet, placed: np.ndarray) -> np.ndarray:
    """Consecutive images of one session among those ``placed`` (K,) bool, in the file's order (P, 2)."""
    last: dict[str, int] = {}
    out = []
    for k in np.flatnonzero(placed):
        session = str(corners.sessions[k])
        if session in last:
            out.append((last[session], int(k)))
        last[session] = int(k)
    return np.array(out, dtype=np.intp).reshape(-1, 2)


def relative_motions(frames: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Eq R1: ``T_j⁻¹ T_k`` of each pair (P, 4, 4) of the frames (K, 4, 4) [m]."""
    return np.linalg.inv(frames[pairs[:, 0]]) @ frames[pairs[:, 1]]


def motion_errors(predicted: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """Eq R3 of each pair (P, 2): the translation's length [mm] and the rotation's angle [deg] of
    ``measured⁻¹ predicted`` (P, 4, 4) each [m]."""
    errors = np.linalg.inv(measured) @ predicted
    return np.stack([np.linalg.norm(errors[:, :3, 3], axis=1) * 1e3,
                     np.degrees(np.linalg.norm(log3(errors[:, :3, :3]), axis=1))], axis=1).reshape(-1, 2)


def _pose_jacobian(intrinsics: CameraIntrinsics, view: np.ndarray, board: np.ndarray) -> np.ndarray:
    """d pixel / d ξ of the corners ``board`` (M, 3) [m] seen at ``view`` = camera_T_board exp(ξ), (2M, 6)
    [px per m, px per rad] (the module docstring)."""
    rotation = view[:3, :3]
    d_point, _ = projection_jacobians(intrinsics, board @ rotation.T + view[:3, 3])
    d_pose = np.concatenate([np.broadcast_to(rotation, (len(board), 3, 3)), -rotation @ skew(board)], axis=2)
    return (d_point @ d_pose).reshape(-1, 6)


def _polished(intrinsics: CameraIntrinsics, view: np.ndarray, board: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """``view`` (4, 4) [m] refined to the least squares of its corners' reprojection through ``intrinsics`` (pincal's
    projection, the one the floor linearises: OpenCV's refinement stops at single precision's relative step)."""
    def moved(step: np.ndarray) -> np.ndarray:
        return np.asarray(view @ pin.exp6(step).homogeneous)

    def residual(step: np.ndarray) -> np.ndarray:
        placed = moved(step)
        return np.asarray((project(intrinsics, board @ placed[:3, :3].T + placed[:3, 3]) - pixels).reshape(-1))

    def jacobian(step: np.ndarray) -> np.ndarray:
        return _pose_jacobian(intrinsics, moved(step), board) @ pin.Jexp6(step)

    return moved(least_squares(residual, np.zeros(6), jac=jacobian, method="lm", xtol=1e-15, ftol=1e-15).x)


def measured_motions(corners: CornerSet, intrinsics: CameraIntrinsics, arrangement: Arrangement) -> MeasuredMotions:
    """Eqs R2 and R4-R6 over the consecutive images of each session that PnP places (``board_poses``: IPPE then
    Levenberg-Marquardt, with ``intrinsics``)."""
    counts = np.bincount(corners.image_of, minlength=len(corners.images))
    enough = counts >= MIN_CORNERS
    views = np.full((len(corners.images), 4, 4), np.nan)
    for k in np.flatnonzero(enough):  # one image at a time: one PnP cannot place leaves its pairs, not the rest
        try:
            views[k] = board_poses(images_of(corners, np.array([k])), intrinsics)[0]
        except CalibrationError:
            continue
    placed = np.all(np.isfinite(views), axis=(1, 2))
    unplaced = tuple(corners.images[k] for k in np.flatnonzero(~placed))
    pairs = image_pairs(corners, placed)
    if not len(pairs):
        return MeasuredMotions(pairs, np.zeros((0, 4, 4)), np.zeros((0, 2)), None, unplaced)
    used = np.unique(pairs)
    information, squares, rows = {}, 0.0, 0
    for k in used:
        mine = corners.image_of == k
        board = corners.board_points[mine]
        views[k] = _polished(intrinsics, views[k], board, corners.pixels[mine])
        residual = project(intrinsics, board @ views[k, :3, :3].T + views[k, :3, 3]) - corners.pixels[mine]
        squares, rows = squares + float(np.sum(residual**2)), rows + residual.size
        jacobian = _pose_jacobian(intrinsics, views[k], board)
        information[int(k)] = jacobian.T @ jacobian
    noise = float(np.sqrt(squares / max(rows - 6 * len(used), 1)))
    covariance = {k: noise**2 * np.linalg.pinv(a) for k, a in information.items()}  # eq R4
    if arrangement == "eye_in_hand":
        motions = views[pairs[:, 0]] @ np.linalg.inv(views[pairs[:, 1]])
    else:
        motions = np.linalg.inv(views[pairs[:, 0]]) @ views[pairs[:, 1]]
    floor = np.empty((len(pairs), 2))
    for i, (j, k) in enumerate(pairs):  # eq R5
        if arrangement == "eye_in_hand":
            adjoint = pin.SE3(views[k]).action
            first, second = adjoint, -adjoint
        else:
            first, second = -pin.SE3(motions[i]).inverse().action, np.eye(6)
        sigma = first @ covariance[int(j)] @ first.T + second @ covariance[int(k)] @ second.T
        floor[i] = np.sqrt(np.trace(sigma[:3, :3])) * 1e3, np.degrees(np.sqrt(np.trace(sigma[3:, 3:])))  # eq R6
    return MeasuredMotions(pairs, motions, floor, noise, unplaced)


def within_floor(errors: np.ndarray, floor: np.ndarray) -> bool:
    """Whether the pairs' errors (P, 2) [mm, deg] are what a perfect model's would be, given their floor (P, 2): the
    RMS of each column at most the RMS floor's times √(chi2⁻¹(1 − :data:`FLOOR_LEVEL`; 3P) / 3P)."""
    if not len(errors):
        return False
    dof = 3 * len(errors)
    bound = np.sqrt(np.mean(floor**2, axis=0) * chi2.ppf(1.0 - FLOOR_LEVEL, dof) / dof)
    return bool(np.all(np.sqrt(np.mean(errors**2, axis=0)) <= bound))
