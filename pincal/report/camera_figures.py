"""The HTML report's parts for a camera: the reprojection errors of each image and a picture of one image
with its corners as detected and as the model reprojects them.

Everything here takes plain values — image names, each corner's image, detected and reprojected pixels
[px], image sizes and files — so a calibration's or an evaluation's workflow calls it with what it has:

* :func:`camera_section` turns them into the values the template's ``camera.html.j2`` shows (a table per
  image, the two figures as ``data:`` URIs);
* :func:`errors_figure` draws each image's errors (a box of its corners' error lengths, its RMS marked) [px];
* :func:`corners_figure` draws one image — the file when it can be read, else a blank image of its size —
  with the detected corners as circles, the reprojected ones as crosses, and each error drawn magnified.

The error of a corner is its reprojected pixel minus its detected one (eq C3 of
:mod:`pincal.residuals.camera`); its length ‖e‖ [px] is what the figures and the table show, RMS over an
image's corners being ``sqrt(mean ‖e‖²)``, the per-coordinate RMS times √2.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import rc_context
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from pincal.errors import PincalError
from pincal.palette import CALIBRATED, FLAG, NOMINAL
from pincal.report.figures import _STYLE, _svg_uri

__all__ = ["CAMERA_TEMPLATE", "CameraImages", "errors_figure", "lengths_figure", "corners_figure", "camera_section",
           "section_values", "render_camera_section"]

#: The template of the camera's section (its macro ``sections(camera)``).
CAMERA_TEMPLATE = "camera.html.j2"
#: The picture's width [in] at 100 dpi, at most: a 1280 px image drawn at 960 px, its corners still apart; a
#: smaller image at its own size, not below 480 px (the labels' room).
_PICTURE_WIDTH_IN = 9.6
_PICTURE_MIN_WIDTH_IN = 4.8


@dataclass(frozen=True)
class CameraImages:
    """The corners of K images as detected and as a model reprojects them.

    Attributes:
        images: each image's name (K,).
        image_of: each corner's image, an index into ``images`` (M,).
        detected: each corner's detected pixel (M, 2) [px].
        reprojected: each corner's reprojected pixel (M, 2) [px].
        sizes: each image's (width, height) (K, 2) [px].
        roles: each image's role (K,): ``calibration`` or ``validation`` (default: all calibration).
        folder: where the image files are (by name); None: not looked for, the picture drawn on a blank image.
    """

    images: tuple[str, ...]
    image_of: np.ndarray
    detected: np.ndarray
    reprojected: np.ndarray
    sizes: np.ndarray
    roles: tuple[str, ...] = ()
    folder: Path | None = None

    def __post_init__(self) -> None:
        k, m = len(self.images), len(self.image_of)
        image_of = np.asarray(self.image_of, dtype=np.intp)
        detected = np.asarray(self.detected, dtype=float).reshape(-1, 2)
        reprojected = np.asarray(self.reprojected, dtype=float).reshape(-1, 2)
        sizes = np.asarray(self.sizes, dtype=float).reshape(-1, 2)
        if len(detected) != m or len(reprojected) != m or np.any((image_of < 0) | (image_of >= k)):
            raise PincalError(f"camera report: {m} corners need {m} detected and reprojected pixels and an image "
                              f"each among the {k} (got {len(detected)}, {len(reprojected)})")
        if len(sizes) != k:
            raise PincalError(f"camera report: {k} images need {k} sizes (got {len(sizes)})")
        roles = tuple(self.roles) or ("calibration",) * k
        if len(roles) != k:
            raise PincalError(f"camera report: {k} images need {k} roles (got {len(roles)})")
        for name, value in (("image_of", image_of), ("detected", detected), ("reprojected", reprojected),
                            ("sizes", sizes), ("roles", roles), ("images", tuple(self.images))):
            object.__setattr__(self, name, value)

    @property
    def errors(self) -> np.ndarray:
        """Each corner's error length ‖reprojected − detected‖ (M,) [px]."""
        return np.linalg.norm(self.reprojected - self.detected, axis=1)

    def per_image(self) -> list[np.ndarray]:
        """Each image's corners' error lengths, K arrays [px]."""
        errors = self.errors
        return [errors[self.image_of == i] for i in range(len(self.images))]

    def rms(self) -> np.ndarray:
        """Each image's RMS error length (K,) [px] (NaN for an image without corners)."""
        k = len(self.images)
        counts = np.bincount(self.image_of, minlength=k)
        sums = np.bincount(self.image_of, weights=self.errors**2, minlength=k)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(sums / counts)


def _png_uri(fig: Figure) -> str:
    FigureCanvasAgg(fig)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=100, metadata={"Software": None})
    return "data:image/png;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def errors_figure(images: CameraImages) -> str:
    """Each image's corners' error lengths [px] as a box (quartiles, whiskers to 1.5 IQR, the rest as points),
    its RMS as a diamond; calibration images in the calibrated colour, validation ones in the flag colour.
    An SVG ``data:`` URI."""
    return lengths_figure(images.images, images.roles, images.per_image())


def lengths_figure(names: Sequence[str], roles: Sequence[str], per_image: Sequence[np.ndarray]) -> str:
    """:func:`errors_figure` of each image's corners' error lengths ``per_image`` (K arrays) [px]."""
    k = len(names)
    rms = np.array([np.sqrt(np.mean(e**2)) if len(e) else np.nan for e in per_image])
    with rc_context(_STYLE):
        fig = Figure(figsize=(max(4.5, min(14.0, 1.2 + 0.28 * k)), 3.0), layout="constrained")
        ax = fig.subplots()
        shown = [i for i in range(k) if len(per_image[i])]
        colours = [FLAG if roles[i] == "validation" else CALIBRATED for i in shown]
        boxes = ax.boxplot([per_image[i] for i in shown], positions=shown, widths=0.6, patch_artist=True,
                           flierprops={"markersize": 2.5, "markeredgecolor": NOMINAL})
        for patch, colour in zip(boxes["boxes"], colours):
            patch.set_facecolor(colour)
            patch.set_alpha(0.45)
            patch.set_edgecolor(colour)
        ax.scatter(shown, rms[shown], marker="D", s=14, color=colours, zorder=3, label="RMS of the image")
        ax.set_xticks(range(k), list(names) if k <= 40 else [str(i) for i in range(k)],
                      rotation=90 if k > 6 else 0, fontsize=7)
        ax.set_xlim(-0.7, k - 0.3)
        ax.set_ylim(0.0, None)
        ax.set_ylabel("reprojection error [px]")
        ax.grid(axis="x", visible=False)
        ax.legend(loc="upper right", fontsize=7)
        return _svg_uri(fig)


def _picture(path: Path | None, width: int, height: int) -> tuple[np.ndarray, bool]:
    """The image at ``path`` in grey levels, or a blank one of the size (and whether the file was drawn)."""
    if path is not None and path.is_file():
        from pincal.measurements.images import read_image  # OpenCV: only when there is a file to read

        try:
            image = read_image(path)
        except PincalError:
            image = None
        if image is not None and image.shape == (height, width):
            return image, True
    return np.full((max(height, 1), max(width, 1)), 255, dtype=np.uint8), False


def corners_figure(images: CameraImages, index: int, magnify: float | None = None) -> tuple[str, float, bool]:
    """Image ``index`` with its detected corners (circles) and reprojected ones (crosses), each error drawn
    ``magnify`` times longer (default: so that the largest is 4 % of the image's width, at least 1×).

    Returns:
        A PNG ``data:`` URI, the magnification used and whether the image's file was drawn (else a blank
        image of its size).
    """
    mine = images.image_of == index
    detected, reprojected = images.detected[mine], images.reprojected[mine]
    width, height = (int(v) for v in images.sizes[index])
    path = None if images.folder is None else Path(images.folder) / Path(images.images[index]).name
    picture, drawn = _picture(path, width, height)
    errors = reprojected - detected
    largest = float(np.max(np.linalg.norm(errors, axis=1))) if len(errors) else 0.0
    if magnify is None:
        magnify = max(1.0, 0.04 * width / largest) if largest > 0 else 1.0
    with rc_context(_STYLE):
        inches = min(_PICTURE_WIDTH_IN, max(_PICTURE_MIN_WIDTH_IN, width / 100.0))
        fig = Figure(figsize=(inches, inches * height / max(width, 1) + 0.4),
                     layout="constrained")
        ax = fig.subplots()
        if drawn:  # a blank image is the axes' white: no 1280x960 array to resample
            ax.imshow(picture, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        else:  # the image's border drawn, as the picture's edge would show it
            ax.add_patch(Rectangle((-0.5, -0.5), width, height, fill=False, edgecolor=NOMINAL, linewidth=0.8))
            ax.set_aspect("equal")
        ax.plot(detected[:, 0], detected[:, 1], "o", markersize=6, markerfacecolor="none",
                markeredgecolor=CALIBRATED, markeredgewidth=1.2, label="detected")
        ax.plot(reprojected[:, 0], reprojected[:, 1], "x", markersize=6, color=FLAG, markeredgewidth=1.2,
                label="reprojected")
        tips = detected + magnify * errors
        ax.add_collection(LineCollection(list(np.stack([detected, tips], axis=1)), colors=FLAG, linewidths=1.0))
        ax.set_xlim(-0.5, width - 0.5)
        ax.set_ylim(height - 0.5, -0.5)
        ax.grid(False)
        ax.set_xlabel("u [px]")
        ax.set_ylabel("v [px]")
        ax.set_title(f"{images.images[index]}: error lines {magnify:.3g}× longer"
                     + ("" if drawn else " (image file not found: a blank image of its size)"), fontsize=9)
        ax.legend(loc="lower right", fontsize=8)
        return _png_uri(fig), magnify, drawn


def camera_section(images: CameraImages, shown: int | None = None) -> dict[str, Any]:
    """The values of the template's camera section (``camera.html.j2``): per image its role, corners, RMS and
    largest error [px]; the errors figure; the picture of image ``shown`` (default: the calibration image
    with the largest RMS, where a bad corner or a bad model shows first)."""
    rms = images.rms()
    k = len(images.images)
    chosen = shown is None
    if shown is None:
        candidates = [i for i in range(k) if np.isfinite(rms[i])]
        calibration = [i for i in candidates if images.roles[i] != "validation"] or candidates
        shown = max(calibration, key=lambda i: rms[i]) if calibration else None
    return section_values(images.images, images.roles, images.per_image(),
                          None if shown is None else (images, shown, chosen))


def section_values(names: Sequence[str], roles: Sequence[str], per_image: Sequence[np.ndarray],
                   picture: tuple[CameraImages, int, bool] | None) -> dict[str, Any]:
    """:func:`camera_section`'s values from each image's corners' error lengths ``per_image`` (K arrays) [px] and
    the picture to draw: (its corners, its index among them, whether it was chosen rather than asked for)."""
    rows = [{"image": name, "role": role, "corners": int(len(e)),
             "rms_px": float(np.sqrt(np.mean(e**2))) if len(e) else None,
             "max_px": float(np.max(e)) if len(e) else None} for name, role, e in zip(names, roles, per_image)]
    shown = None
    if picture is not None:
        corners, index, chosen = picture
        uri, magnify, drawn = corners_figure(corners, index)
        shown = {"uri": uri, "image": corners.images[index], "role": corners.roles[index], "magnify": magnify,
                 "drawn": drawn,
                 "rms_px": float(corners.rms()[index]), "chosen": chosen}
    errors = np.concatenate([np.asarray(e, dtype=float) for e in per_image]) if len(per_image) else np.zeros(0)
    overall = float(np.sqrt(np.mean(errors**2))) if len(errors) else None
    return {"rows": rows, "figure": lengths_figure(names, roles, per_image) if len(errors) else None,
            "picture": shown, "rms_px": overall, "corners": int(len(errors)), "images": len(names)}


def render_camera_section(section: dict[str, Any]) -> str:
    """The camera's section of the page alone (HTML), as the report page includes it."""
    from pincal.report.templating import environment

    template = environment().from_string('{% import "' + CAMERA_TEMPLATE + '" as camera_parts %}'
                                         "{{ camera_parts.sections(camera) }}")
    return template.render(camera=section)

