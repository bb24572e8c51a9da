"""The HTML report, opened in a real browser (headless Chromium driven by Playwright).

The README's TIAGo diagnose run (real data) is rendered with ``--html`` and
``evaluate --html``; the paper's Method 2 report of ``pincal demo`` with
``pincal report``. Chromium is Debian's ``chromium`` package (``.ci/run``
installs it). Without it the browser tests skip with one line saying how to install it,
except under ``CI=true`` (CI, where ``.ci/run`` installed it): there a missing browser fails.
"""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.fit.chain_calibration import calibrate_chain
from pincal.fit.metrics import pose_errors
from pincal.fit.outliers import OUTLIER_THRESHOLD
from pincal.measurements.csv_v1 import read_measurements
from pincal.model.chain import KinematicChain
from pincal.robots import example_robot_data_urdf

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data" / "tiago_mocap"
TRAIN = DATA / "qualisys_2021-11-30_static_postures.csv"
HELD_OUT = DATA / "qualisys_2021-11-26_static_postures.csv"
CHROMIUM = "/usr/bin/chromium"
#: Flags for a headless browser in a container (no sandbox as root, no GPU, nothing fetched in the background).
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
#: The README's screenshot viewport [CSS px].
VIEWPORT = {"width": 1280, "height": 1600}


#: Why a browser test cannot run here, and what to do.
NO_BROWSER = "Chromium is not installed: apt-get install -y chromium (.ci/run does this)"


def _missing(reason: str) -> None:
    """Skip in one line, or fail under ``CI=true``: CI must run every browser test."""
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(f"{reason}; CI=true: the browser tests must run")
    pytest.skip(reason)


def _chromium() -> str:
    path = shutil.which("chromium") or (CHROMIUM if Path(CHROMIUM).exists() else None)
    if path is None:
        _missing(NO_BROWSER)
    return path


@pytest.fixture(scope="module")
def tiago(tmp_path_factory):
    """The README's TIAGo diagnose run with --html, and evaluate --html on the held-out session."""
    out = tmp_path_factory.mktemp("tiago")
    urdf = example_robot_data_urdf("tiago_description/robots/tiago.urdf")
    assert main(["diagnose", str(urdf), str(TRAIN), "--validation", str(HELD_OUT),
                 "--tip-link", "wrist_ft_tool_link", "--out", str(out / "tiago_diagnosed.urdf"),
                 "--report", str(out / "REPORT.json"), "--html", str(out / "REPORT.html")]) == 0
    assert main(["evaluate", str(out / "tiago_diagnosed.urdf"), str(out / "REPORT.json"), str(HELD_OUT),
                 "--json", str(out / "evaluation.json"), "--html", str(out / "evaluation.html")]) == 0
    return out


@pytest.fixture(scope="module")
def browser():
    executable = _chromium()
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _missing("playwright is not installed: pip install '.[test]'")
    with sync_playwright() as playwright:
        instance = playwright.chromium.launch(executable_path=executable, args=CHROMIUM_ARGS)
        yield instance
        instance.close()


class Opened:
    """A page opened from disk, with every console message, page error and request it made."""

    def __init__(self, browser, path: Path):
        self.page = browser.new_page(viewport=VIEWPORT)
        self.console, self.errors, self.requests, self.failed = [], [], [], []
        self.page.on("console", lambda m: self.console.append((m.type, m.text)))
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.on("request", lambda r: self.requests.append(r.url))
        self.page.on("requestfailed", lambda r: self.failed.append(r.url))
        self.page.goto(path.as_uri(), wait_until="load")


@pytest.fixture(scope="module")
def diagnosis_page(browser, tiago):
    opened = Opened(browser, tiago / "REPORT.html")
    yield opened
    opened.page.close()


def _determined_by_unit(report: dict) -> list[str]:
    """The determined parameters as the page lists them: one table per unit (lengths, angles),
    each in the report's order."""
    determined = [p for p in report["parameters"] if p["calibrated"] is not None]
    units = list(dict.fromkeys(p["unit"] for p in determined))
    return [p["name"] for unit in units for p in determined if p["unit"] == unit]


def _report(folder: Path) -> dict:
    return json.loads((folder / "REPORT.json").read_text(encoding="utf-8"))


def _assert_clean(opened: Opened, path: Path) -> None:
    """No console error or warning, no script error, no request but the page itself, every figure decoded."""
    assert opened.errors == []
    assert [m for m in opened.console if m[0] in ("error", "warning")] == []
    assert opened.failed == []
    assert opened.requests == [path.as_uri()]  # figures are data: URIs, nothing else is fetched
    broken = opened.page.eval_on_selector_all("img", "imgs => imgs.filter(i => !(i.naturalWidth > 0)).length")
    assert broken == 0
    assert opened.page.eval_on_selector_all("img", "imgs => imgs.length") >= 1
    # laid out for the viewport: nothing wider than the window
    assert opened.page.evaluate("document.documentElement.scrollWidth") <= VIEWPORT["width"]


def test_tiago_diagnosis_page_loads_clean_and_offline(diagnosis_page, tiago):
    _assert_clean(diagnosis_page, tiago / "REPORT.html")
    html = (tiago / "REPORT.html").read_text(encoding="utf-8")
    assert "Content-Security-Policy" in html and "default-src 'none'" in html
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", html)


def test_summary_shows_the_numbers_of_the_report(diagnosis_page, tiago):
    report, page = _report(tiago), diagnosis_page.page
    for section in ("summary", "effects", "rows", "parameters", "identifiability", "registration", "notes"):
        assert page.locator(f"section#{section}").count() == 1, section
    cards = {page.locator(".card .set").nth(i).inner_text().split("·")[0].strip().lower():
             page.locator(".card .rms").nth(i).inner_text() for i in range(page.locator(".card").count())}
    held_out = report["diagnosis"]["heldout_errors"]["position"]["rms_mm"]
    calibration = report["diagnosis"]["calibration_errors"]["position"]["rms_mm"]
    assert cards["held-out rows"] == f"{held_out:#.3g}"  # 3.39 mm in the README's run
    assert cards["calibration rows"] == f"{calibration:#.3g}"
    errors = page.locator("#errors-table").inner_text()
    # marker 1, held-out, final model: the README's 2.47 mm
    assert f"{report['diagnosis']['heldout_errors']['position_per_point'][0]['rms_mm']:.3g}" in errors
    assert "nominal geometry" in errors and "geometry and effects" in errors


def test_parameters_identifiability_registration_and_effects(diagnosis_page, tiago):
    report, page = _report(tiago), diagnosis_page.page
    shown = page.locator("#parameters-table tbody tr td:first-child").all_inner_texts()
    assert shown == _determined_by_unit(report)
    undetermined = page.locator("#undetermined-table tbody tr td:first-child").all_inner_texts()
    assert undetermined == [p["name"] for p in report["parameters"] if p["calibrated"] is None]
    ident = page.locator("section#identifiability").inner_text()
    assert f"{report['identifiability']['jacobian_condition']:.4g}" in ident
    pairs = page.locator("#correlations-table tbody tr").count()
    assert pairs == len(report["identifiability"]["correlated_pairs"])
    effects = page.locator("#effects-table").inner_text()
    for effect in report["effects"]:
        assert effect["joint"] in effects
    backlash = next(e for e in report["effects"] if e["type"] == "backlash")
    assert f"{backlash['value'] * 1000:.4g} ± {backlash['std'] * 1000:.2g} mrad" in effects
    plots = page.locator("section#effects .plots img").count()
    assert plots == len(report["diagnosis"]["plots"])
    points = page.locator("#points-table tbody tr").count()
    assert points == len(report["tool"]["points_m"])


def test_row_tables_hold_every_row_flag_outliers_and_sort(diagnosis_page, tiago):
    report, page = _report(tiago), diagnosis_page.page
    for entry in report["row_errors"]:
        table = page.locator(f'table.rows-table[data-set="{entry["set"]}"]')
        lines = [int(t) for t in table.locator("tbody tr td:first-child").all_inner_texts()]
        assert lines == entry["lines"]
        flagged = [int(r.locator("td").first.inner_text()) for r in table.locator("tbody tr.flagged").all()]
        assert flagged == [line for line, score in zip(entry["lines"], entry["robust_score"])
                           if score > OUTLIER_THRESHOLD]
    held = next(e for e in report["row_errors"] if e["set"] == "held-out")
    table = page.locator('table.rows-table[data-set="held-out"]')
    header = table.locator("thead th", has_text="geometry and effects")
    column = len(held["models"])  # file line, then one column per model: the reported model last
    final = held["models"][-1]["position_mm"]
    for clicks, expected in ((1, sorted(final)), (2, sorted(final, reverse=True))):
        header.click()
        values = [float(v) for v in table.locator(f"tbody tr td:nth-child({column + 1})").all_inner_texts()]
        assert values == pytest.approx(expected, rel=1e-3), f"after {clicks} click(s)"
    first_line = int(table.locator("tbody tr td:first-child").first.inner_text())
    assert first_line == held["lines"][max(range(len(final)), key=final.__getitem__)]


def test_screenshot_is_saved(diagnosis_page, tiago):
    path = tiago / "report.png"
    diagnosis_page.page.screenshot(path=str(path))
    data = path.read_bytes()
    assert data.startswith(b"\x89PNG") and len(data) > 50_000  # a rendered page, not a blank one


def _statistics(points_mm) -> dict:
    """Mean, RMS and maximum of every point's distance, with numpy: eq 24's summary, recomputed."""
    values = np.asarray(points_mm, dtype=float)
    return {"mean_mm": values.mean(), "rms_mm": np.sqrt(np.mean(values**2)), "max_mm": values.max()}


def test_diagnosis_summaries_are_the_statistics_of_the_rows_and_what_evaluate_recomputes(tiago):
    """REPORT.json's ``diagnosis`` summaries (calibration and held-out rows) are the mean, RMS and
    maximum of the set's point errors (``row_errors``' ``point_position_mm``, recomputed here with
    numpy); the held-out one is also what ``pincal evaluate --json`` computes afresh from the written
    URDF and REPORT.json. (Not the calibration one: there evaluate would take the approach flanks of
    the calibration rows from the calibration rows themselves, diagnose from the held-out rows.)"""
    report = _report(tiago)
    sets = {e["set"]: e for e in report["row_errors"]}
    for name, summary in (("calibration", report["diagnosis"]["calibration_errors"]),
                          ("held-out", report["diagnosis"]["heldout_errors"])):
        points = np.array(sets[name]["point_position_mm"])  # (rows, 4 markers), of the reported model
        assert points.shape == (summary["rows"], 4) == (len(sets[name]["lines"]), 4)
        for key, value in _statistics(points).items():
            assert summary["position"][key] == pytest.approx(value, rel=1e-12), (name, key)
        for marker, per_point in enumerate(summary["position_per_point"]):
            assert per_point == pytest.approx(_statistics(points[:, marker]), rel=1e-12), (name, marker)
        if name == "held-out":
            evaluated = json.loads((tiago / "evaluation.json").read_text(encoding="utf-8"))
            assert evaluated["rows"] == summary["rows"]
            assert evaluated["position"] == pytest.approx(_statistics(points), rel=1e-9)
        models = sets[name]["models"]
        assert [m["model"] for m in models] == ["nominal geometry", "calibrated geometry", "geometry and effects"]
        # each row's value is the RMS over its 4 points: their RMS is the summary's
        row_rms = [np.sqrt(np.mean(np.square(m["position_mm"]))) for m in models]
        assert row_rms[-1] == pytest.approx(summary["position"]["rms_mm"], rel=1e-9)
        # the calibration's first step starts from the calibrated geometry: its "before" errors
        step = report["diagnosis"]["steps"][0]["calibration" if name == "calibration" else "heldout"]["before"]
        assert row_rms[1] == pytest.approx(step["position"]["rms_mm"], rel=1e-9)
        assert row_rms[0] > row_rms[1] > row_rms[2]  # nominal, geometry, geometry and effects


def test_nominal_geometry_is_a_registration_only_calibration(tiago):
    """"Nominal geometry" = the URDF as given, registration and target fitted to the calibration
    rows: what ``calibrate --level registration`` fits (computed here independently)."""
    chain = KinematicChain.from_urdf(example_robot_data_urdf("tiago_description/robots/tiago.urdf"),
                                     "wrist_ft_tool_link")
    data, _ = read_measurements(TRAIN, chain.joint_specs)
    fit = calibrate_chain(chain, data, "registration")
    target = fit.target
    expected = pose_errors(chain, data, target.registration, target.registration, points=target.points,
                           target_rotation=target.rotation)
    nominal = _report(tiago)["row_errors"][0]["models"][0]
    assert nominal["model"] == "nominal geometry"
    # both fits stop at the solver's tolerance from the same start: agreement to 1e-6 relative
    assert nominal["errors"]["position"]["rms_mm"] == pytest.approx(expected.position.rms, rel=1e-6)
    per_row = np.sqrt(np.mean(expected.position_m**2, axis=1)) * 1000.0
    assert nominal["position_mm"] == pytest.approx(per_row.tolist(), rel=1e-5, abs=1e-9)


def test_evaluate_page_adds_the_evaluated_rows(browser, tiago):
    opened = Opened(browser, tiago / "evaluation.html")
    try:
        _assert_clean(opened, tiago / "evaluation.html")
        metrics = json.loads((tiago / "evaluation.json").read_text(encoding="utf-8"))
        page = opened.page
        lines = page.locator('table.rows-table[data-set="evaluated"] tbody tr').count()
        assert lines == metrics["rows"]
        assert f"{metrics['position']['rms_mm']:#.3g}" in page.locator("section#summary").inner_text()
    finally:
        opened.page.close()


def test_report_command_renders_a_paper_report_and_unknown_keys(browser, tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path / "demo")]) == 0
    report = json.loads((tmp_path / "demo" / "REPORT_method2.json").read_text(encoding="utf-8"))
    # a key the page knows (sessions, as pincal/report/sessions.py documents it) and one it does not
    registration = report["registration"]["position"]
    report["sessions"] = [{"name": name, "file": "calibration.csv", "rows": 50,
                           "registration": {"position": registration, "orientation": registration},
                           "calibration_errors": report["fit"]["calibration_errors"]} for name in ("monday", "tuesday")]
    report["instrument"] = [{"serial": "LT-4711", "temperature_c": 21.5}]
    (tmp_path / "REPORT.json").write_text(json.dumps(report), encoding="utf-8")
    capsys.readouterr()
    assert main(["report", str(tmp_path / "REPORT.json"), "--out", str(tmp_path / "REPORT.html")]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {tmp_path / 'REPORT.html'}"
    opened = Opened(browser, tmp_path / "REPORT.html")
    try:
        _assert_clean(opened, tmp_path / "REPORT.html")
        page = opened.page
        assert "Method 2" in page.locator("h1").inner_text()
        stages = page.locator("#stages-table").inner_text()
        assert "Err_rot" in stages and "Err_pos" in stages
        sessions = page.locator("#sessions-table tbody tr td:first-child").all_inner_texts()
        assert sessions == ["monday", "tuesday"]
        translation = ", ".join(f"{v:.5f}" for v in registration["translation_m"])
        assert page.locator("#sessions-table tbody tr").first.inner_text().count(translation) == 1
        more = page.locator("section#more").inner_text()
        assert "instrument" in more and "LT-4711" in more and "21.5" in more
        shown = page.locator("#parameters-table tbody tr td:first-child").all_inner_texts()
        assert shown == _determined_by_unit(report)
    finally:
        opened.page.close()


@pytest.mark.parametrize("case, message", [
    ("missing", "no such report file"),
    ("invalid", "not a readable JSON report"),
    ("not a report", "not a pincal report"),
    ("malformed", "unexpected form"),
    ("same file", "refusing to overwrite an input file"),
    ("directory", "is a directory"),
])
def test_report_command_bad_input_is_one_line(tmp_path, capsys, case, message):
    source, out = tmp_path / "REPORT.json", tmp_path / "REPORT.html"
    if case == "invalid":
        source.write_text("{\"parameters\": [", encoding="utf-8")
    elif case == "not a report":
        source.write_text("[1, 2, 3]", encoding="utf-8")
    elif case == "malformed":
        source.write_text(json.dumps({"parameters": [1, 2], "row_errors": "none"}), encoding="utf-8")
    elif case == "same file":
        source.write_text(json.dumps({"position": {"rms_mm": 1.0}, "rows": 1}), encoding="utf-8")
        out = source
    elif case == "directory":
        source = tmp_path
    before = source.read_bytes() if source.is_file() else None
    assert main(["report", str(source), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("pincal: error: ") and message in err and "\n" not in err
    if before is not None:
        assert source.read_bytes() == before  # the input is never overwritten


def test_socket_fixture_page_loads_clean_and_shows_its_consistency(browser, tmp_path):
    """calibrate --fixture --html (MUKCa iiwa, offsets, two placements; ~1 s): no console error, nothing
    fetched, and the consistency of each calibration placement from REPORT.json, nominal → calibrated."""
    mukca = ROOT / "data" / "mukca"
    assert main(["calibrate", str(mukca / "urdf" / "iiwa14.urdf"), str(mukca / "kuka_14" / "front.csv"),
                 str(mukca / "kuka_14" / "left_back.csv"), "--fixture", str(mukca / "fixture.csv"),
                 "--tip-link", "tool0", "--level", "offsets", "--out", str(tmp_path / "o.urdf"),
                 "--report", str(tmp_path / "REPORT.json"), "--html", str(tmp_path / "REPORT.html")]) == 0
    training = _report(tmp_path)["fixture"]["training"]
    opened = Opened(browser, tmp_path / "REPORT.html")
    try:
        _assert_clean(opened, tmp_path / "REPORT.html")
        rows = opened.page.locator("#fixture table.fixture-metrics").first.locator("tbody tr").all_inner_texts()
        for row, before, after in zip(rows, training["before"]["placements"], training["after"]["placements"]):
            assert row.startswith(after["placement"])
            assert f"{before['consistency_mm']:.3f} → {after['consistency_mm']:.3f}" in row
        assert opened.page.locator(".fixture-card .consistency").first.inner_text() == \
            f"{training['after']['consistency_mm']:.3f}"
        assert opened.page.locator("#registration").count() == 0
    finally:
        opened.page.close()


# --- several sessions and re-estimated registrations, without a browser (the page's HTML, parsed) ----------

UR5 = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf")
#: Two sensor placements (sensor_T_base) and a third the fit never sees.
SENSORS = {"A": ([35, -12, 8], [1.85, -0.62, 0.43]), "B": ([-80, 5, -3], [0.2, 1.5, -0.1]),
           "D": ([60, 10, -20], [0.9, 0.9, 0.2])}


def _ur5_rows(name: str, rows: int, seed: int, role: str = "calibration"):
    """Noise-free point rows of a UR5 seen from sensor ``name`` (0.05 mm noise for the held-out ones)."""
    from scipy.spatial.transform import Rotation

    from pincal.model.sensor import Registration
    from pincal.simulation.sensor import SimulatedSensor, measure, random_configurations

    chain = KinematicChain.from_urdf(UR5, "tool0")
    rng = np.random.default_rng(seed)
    angles, shift = SENSORS[name]
    sensor = Registration(Rotation.from_euler("ZYX", angles, degrees=True).as_matrix(), np.array(shift))
    sigma = 5e-5 if role == "validation" else 0.0
    return measure(chain, random_configurations(chain, rng, rows), sensor, rng,
                   SimulatedSensor(sigma, 0.0, points=np.array([[0.03, -0.02, 0.08]]), with_rotation=False), role)


def _page(html: str):
    from lxml import html as lxml_html

    return lxml_html.fromstring(html)


@pytest.fixture(scope="module")
def two_files(tmp_path_factory):
    """calibrate UR5 A.csv B.csv (B's line 7 20 mm off: an outlier; A's line 7 is not), with --html;
    evaluate --html an unseen session of 3 rows (its registration re-estimated)."""
    from dataclasses import replace

    from pincal.measurements.csv_v1 import write_measurements

    out = tmp_path_factory.mktemp("sessions_html")
    write_measurements(out / "A.csv", _ur5_rows("A", 14, 1))
    bad = _ur5_rows("B", 14, 2)
    points = bad.points.copy()
    points[5, 0, 0] += 0.02  # file line 7
    write_measurements(out / "B.csv", replace(bad, points=points))
    write_measurements(out / "D.csv", _ur5_rows("D", 3, 3, "validation"))
    # --select aic: the outlier flags this page is tested on are those of the subset fit
    assert main(["calibrate", str(UR5), str(out / "A.csv"), str(out / "B.csv"), "--tip-link", "tool0", "--level",
                 "offsets", "--select", "aic", "--out", str(out / "c.urdf"), "--report", str(out / "REPORT.json"),
                 "--html", str(out / "REPORT.html"), "--quiet"]) == 0
    assert main(["evaluate", str(out / "c.urdf"), str(out / "REPORT.json"), str(out / "D.csv"),
                 "--json", str(out / "D.json"), "--html", str(out / "D.html")]) == 0
    return out


def test_row_errors_give_each_rows_file_and_session(two_files):
    report = _report(two_files)
    (entry,) = report["row_errors"]
    assert entry["file"] == f"{two_files / 'A.csv'} + {two_files / 'B.csv'}"
    assert entry["files"] == [str(two_files / "A.csv")] * 14 + [str(two_files / "B.csv")] * 14
    assert entry["sessions"] == ["A"] * 14 + ["B"] * 14
    assert entry["lines"] == list(range(2, 16)) * 2  # the same line numbers in both files


def test_row_table_names_file_and_session_and_flags_file_line(two_files):
    page = _page((two_files / "REPORT.html").read_text(encoding="utf-8"))
    (table,) = page.xpath('//section[@id="rows"]//table[contains(@class, "rows-table")]')
    assert [th.text_content() for th in table.xpath("./thead/tr/th")][:3] == ["file", "session", "file line"]
    rows = [[td.text_content() for td in tr.xpath("./td")] for tr in table.xpath("./tbody/tr")]
    assert [(r[0], r[1], r[2]) for r in rows] == [("A.csv", "A", str(n)) for n in range(2, 16)] + [
        ("B.csv", "B", str(n)) for n in range(2, 16)]
    flagged = [(r[0], r[2]) for r, tr in zip(rows, table.xpath("./tbody/tr")) if "flagged" in tr.get("class", "")]
    assert flagged == [("B.csv", "7")]  # A.csv's line 7 shares the number, not the outlier
    pills = [p.text_content() for p in page.xpath('//section[@id="rows"]//span[@class="pill"]')]
    assert pills == ["B.csv:7"]


def test_registration_section_says_whose_registration_and_what_was_measured(two_files):
    page = _page((two_files / "REPORT.html").read_text(encoding="utf-8"))
    first = page.xpath('//table[@id="registration-table"]/tbody/tr/td')[0].text_content()
    assert first == "session 'A' (the first of 2; each one's below): registration (positions; no orientations measured)"
    section = page.get_element_by_id("registration").text_content()
    assert "(points estimated; its rotation is not: no orientations were measured)" in section
    assert "the tip frame's, not estimated: the data have no orientations" in section
    assert "(estimated)" not in section


def test_evaluate_page_flags_a_reestimated_registration_with_its_degrees_of_freedom(two_files):
    metrics = json.loads((two_files / "D.json").read_text(encoding="utf-8"))
    (session,) = metrics["sessions"]
    assert (session["residuals"], session["registration_dof"]) == (9, 3)
    page = _page((two_files / "D.html").read_text(encoding="utf-8"))
    cards = [c.text_content() for c in page.xpath('//div[@class="card"]')]
    (evaluated,) = [c for c in cards if c.strip().lower().startswith("evaluated")]
    assert ("session D: registration re-estimated on these rows — 9 residuals, 3 degrees of freedom left: "
            "errors about 0.58 × the true error") in evaluated
    cells = [td.text_content() for td in page.xpath('//table[@id="evaluated-sessions-table"]/tbody/tr/td')]
    assert cells[:5] == ["D", "3", "re-estimated re-estimated on these rows (6 parameters; model and target fixed)",
                         "9", "3"]
    assert cells[5] == f"{session['errors']['position']['rms_mm']:.4g}"


def test_report_command_names_the_file_of_a_malformed_report(tmp_path, capsys):
    source = tmp_path / "odd.json"
    source.write_text(json.dumps({"parameters": [1, 2], "row_errors": "none"}), encoding="utf-8")
    assert main(["report", str(source), "--out", str(tmp_path / "odd.html")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pincal: error: {source}: the report has an unexpected form") and err.count("\n") == 1


def test_a_missing_browser_skips_in_one_line_and_fails_under_ci(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.setattr(Path, "exists", lambda self: False)
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="apt-get install -y chromium"):
        _chromium()
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="CI=true: the browser tests must run"):
        _chromium()


def test_calibrate_files_writes_the_page_after_the_report_and_refuses_an_input_before_the_run(two_files, tmp_path):
    """The --html page is the workflow's output (pincal.workflows.report_page): written with the report by
    calibrate_files, and an --html path that is an input refused before anything is written."""
    from pincal.workflows.calibration import calibrate_files
    from pincal.workflows.settings import CalibrateSettings

    settings = CalibrateSettings("tool0", level="offsets")
    run = calibrate_files(UR5, two_files / "A.csv", tmp_path / "c.urdf", tmp_path / "R.json", settings,
                          html=tmp_path / "R.html")
    assert run.html == tmp_path / "R.html"
    assert "<html" in run.html.read_text() and (tmp_path / "R.json").is_file()
    with pytest.raises(PincalError, match="is an input of this run"):
        calibrate_files(UR5, two_files / "A.csv", tmp_path / "d.urdf", tmp_path / "S.json", settings,
                        html=two_files / "A.csv")
    assert not (tmp_path / "d.urdf").exists() and not (tmp_path / "S.json").exists()
    no_page = calibrate_files(UR5, two_files / "A.csv", tmp_path / "e.urdf", tmp_path / "T.json", settings)
    assert no_page.html is None
