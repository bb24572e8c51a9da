"""The HTML report's parts for a camera (pincal.report.camera_figures): the reprojection errors per image and
one image with its detected and reprojected corners, from plain values."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pytest

from pincal.errors import PincalError
from pincal.report.camera_figures import (
    CameraImages,
    camera_section,
    corners_figure,
    errors_figure,
    render_camera_section,
)
from pincal.report.html import render_html, write_html

SIZE = (320, 240)


def _images(folder: Path | None = None) -> CameraImages:
    """Three images of 6 corners each (the third's a validation image), errors of known size: image 1's corners
    are off by (3, 4) px (5 px long), the others' by (0.3, 0.4) px (0.5 px long), one corner of image 0 by 2 px."""
    rng = np.random.default_rng(5)
    detected = rng.uniform(20, 200, (18, 2))
    error = np.tile([0.3, 0.4], (18, 1))
    error[6:12] = [3.0, 4.0]
    error[0] = [2.0, 0.0]
    return CameraImages(images=("a.png", "b.png", "c.png"), image_of=np.repeat(np.arange(3), 6), detected=detected,
                        reprojected=detected + error, sizes=np.tile(SIZE, (3, 1)),
                        roles=("calibration", "calibration", "validation"), folder=folder)


def _png_size(uri: str) -> tuple[int, int]:
    data = base64.b64decode(uri.split(",", 1)[1])
    assert data.startswith(b"\x89PNG")
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


@pytest.fixture(scope="module")
def section() -> dict:
    return camera_section(_images())


def test_the_section_carries_each_image_s_numbers_and_shows_the_worst_calibration_image(section: dict) -> None:
    rows = {r["image"]: r for r in section["rows"]}
    assert rows["b.png"]["rms_px"] == pytest.approx(5.0) and rows["b.png"]["max_px"] == pytest.approx(5.0)
    assert rows["a.png"]["rms_px"] == pytest.approx(np.sqrt((4.0 + 5 * 0.25) / 6)) and rows["a.png"]["max_px"] == 2.0
    assert rows["c.png"]["role"] == "validation" and rows["c.png"]["corners"] == 6
    assert section["rms_px"] == pytest.approx(np.sqrt((4.0 + 11 * 0.25 + 6 * 25.0) / 18))
    assert section["picture"]["image"] == "b.png" and section["picture"]["chosen"]
    assert not section["picture"]["drawn"]  # no folder: a blank image of its size
    html = render_camera_section(section)
    assert "<td>b.png</td><td>calibration</td><td>6</td><td>5</td><td>5</td>" in html
    assert "<td>a.png</td><td>calibration</td><td>6</td><td>0.935</td><td>2</td>" in html
    assert 'id="figure-camera-errors"' in html and 'id="figure-camera-corners"' in html
    assert re.search(r'id="camera-rms">([0-9.]+)<', html).group(1) == f"{section['rms_px']:.3g}"


def test_the_errors_figure_is_an_svg_with_a_box_per_image() -> None:
    uri = errors_figure(_images())
    svg = base64.b64decode(uri.split(",", 1)[1]).decode()
    assert uri.startswith("data:image/svg+xml;base64,") and all(n in svg for n in ("a.png", "b.png", "c.png"))
    assert "reprojection error [px]" in svg


def test_the_picture_draws_the_image_file_when_there_is_one(tmp_path: Path, section: dict) -> None:
    import cv2

    image = np.zeros(SIZE[::-1], dtype=np.uint8)
    image[:, : SIZE[0] // 2] = 200  # a half-bright image: the drawn picture is not blank
    cv2.imwrite(str(tmp_path / "b.png"), image)
    uri, magnify, drawn = corners_figure(_images(tmp_path), 1)
    assert drawn and magnify == pytest.approx(max(1.0, 0.04 * SIZE[0] / 5.0))
    assert uri != section["picture"]["uri"]  # the same image blank
    width, height = _png_size(uri)
    assert width == 480 and abs(height / width - (SIZE[1] / SIZE[0] * 4.8 + 0.4) / 4.8) < 0.01
    wrong = np.zeros((10, 10), dtype=np.uint8)  # a file of another size than the corners' image: not drawn
    cv2.imwrite(str(tmp_path / "a.png"), wrong)
    shown = camera_section(_images(tmp_path), shown=0)["picture"]
    assert shown["image"] == "a.png" and not shown["drawn"] and not shown["chosen"]


def test_the_report_page_shows_the_camera_section(tmp_path: Path, section: dict) -> None:
    assert render_html({}, camera=None).count('id="camera"') == 0
    out = tmp_path / "REPORT.html"
    write_html(out, {}, camera=section)
    page = out.read_text()
    assert page.count('id="camera"') == 1 and 'href="#camera"' in page and 'id="figure-camera-corners"' in page
    assert "One image: b.png" in page and "the calibration image with the largest RMS error" in page


def test_values_that_do_not_fit_are_refused() -> None:
    with pytest.raises(PincalError, match="18 corners need 18 detected"):
        CameraImages(("a.png",), np.zeros(18, dtype=int), np.zeros((17, 2)), np.zeros((18, 2)), np.array([SIZE]))
    with pytest.raises(PincalError, match="need 2 sizes"):
        CameraImages(("a.png", "b.png"), np.zeros(2, dtype=int), np.zeros((2, 2)), np.zeros((2, 2)), np.array([SIZE]))


@pytest.fixture(scope="module")
def calibrated_page(tmp_path_factory):
    """calibrate --camera-link --html of 4 noise-free images eye to hand (level registration), the image files in a
    folder of their own given with --images: blank 1280x960 PNGs."""
    import cv2

    from pincal.cli.commands import main
    from pincal.workflows.camera_simulation import CameraSimulationSettings, simulate_camera_files

    root = tmp_path_factory.mktemp("camera_page")
    sim = simulate_camera_files(root, CameraSimulationSettings("eye_to_hand", images=4, held_out=1, noise_px=0.0))
    folder = root / "images"
    folder.mkdir()
    for k in range(5):
        cv2.imwrite(str(folder / f"image_{k:03d}.png"), np.full((960, 1280), 90, dtype=np.uint8))
    out = root / "out"
    argv = ["calibrate", str(sim.urdf), str(sim.data), "--camera-link", sim.camera_link, "--board-link",
            sim.board_link, "--intrinsics", str(sim.intrinsics), "--level", "registration", "--out",
            str(out / "robot.urdf"), "--report", str(out / "REPORT.json"), "--html", str(out / "REPORT.html"),
            "--images", str(folder)]
    assert main(argv) == 0
    return out, folder, sim


def test_calibrate_writes_the_camera_s_page_and_report_redraws_it(calibrated_page, tmp_path: Path, capsys) -> None:
    import json

    from pincal.cli.commands import main

    out, folder, _ = calibrated_page
    page = (out / "REPORT.html").read_text()
    report = json.loads((out / "REPORT.json").read_text())
    picture = report["camera"]["picture"]
    assert picture["role"] == "calibration" and len(picture["detected_px"]) == len(picture["reprojected_px"]) > 3
    assert report["sources"]["images"] == str(folder)
    images = report["camera"]["images"]
    assert [len(i["errors_px"]) for i in images] == [i["corners"] for i in images]
    assert "Camera calibration (registration, eye to hand)" in page and page.count('id="camera"') == 1
    assert f"One image: {picture['image']}" in page and "image file was not found" not in page
    assert "calibration images · 4" in page and "validation images · 1" in page and "Errors (eq 24)" not in page
    assert "camera in the world — in the corrected URDF" in page and "More in this report" not in page
    assert main(["report", str(out / "REPORT.json"), "--out", str(tmp_path / "again.html")]) == 0
    assert (tmp_path / "again.html").read_text() == page  # the page is the report's alone
    capsys.readouterr()


def test_evaluate_html_shows_the_evaluated_images(calibrated_page, tmp_path: Path, capsys) -> None:
    """evaluate --html: the report's page with an evaluated card, the evaluated images' rows and the worst of them
    drawn (looked for beside the evaluated DATA.csv: not there, a blank image)."""
    import json

    from pincal.cli.commands import main

    out, _, sim = calibrated_page
    assert main(["evaluate", str(out / "robot.urdf"), str(out / "REPORT.json"), str(sim.held_out), "--json",
                 str(tmp_path / "evaluation.json"), "--html", str(tmp_path / "EVALUATION.html")]) == 0
    page = (tmp_path / "EVALUATION.html").read_text()
    evaluation = json.loads((tmp_path / "evaluation.json").read_text())
    assert evaluation["picture"]["image"] == "image_004.png" and "evaluated images · 1" in page
    assert "One image: image_004.png" in page and "the validation image with the largest RMS error" in page
    assert "<td>image_004.png</td><td>validation</td>" in page and "<td>image_000.png</td>" not in page
    assert "image file was not found" in page and f"{sim.held_out} through" in page
    assert "<dt>board motion between consecutive images</dt><dd>no pairs: no session has 2" in page  # one held out
    capsys.readouterr()
    assert main(["report", str(tmp_path / "evaluation.json"), "--out", str(tmp_path / "alone.html")]) == 2
    assert "pincal evaluate ... --html" in capsys.readouterr().err and not (tmp_path / "alone.html").exists()
