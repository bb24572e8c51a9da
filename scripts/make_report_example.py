#!/usr/bin/env python3
"""Regenerate docs/report-example.html and docs/report.png from the documented commands.

    python scripts/make_report_example.py             # rewrites docs/report-example.html and docs/report.png
    python scripts/make_report_example.py --out DIR   # writes DIR/report-example.html and DIR/report.png

In a temporary folder prepared as a user's (``pincal example tiago_mocap``), it runs the TIAGo
command of docs/diagnose.md ("TIAGo, real data") as written there, plus ``--html
tiago_diag/REPORT.html`` (docs/html-report.md), copies that page to ``report-example.html`` and
takes the screenshot of docs/html-report.md, the top of the page in headless Chromium at
1280×1600:

    chromium --headless --window-size=1280,1600 --screenshot=docs/report.png file://$PWD/tiago_diag/REPORT.html

The page holds the run's timings, so two runs differ there and nowhere else. Needs Chromium
(Debian's ``chromium``); about 15 s.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from pincal.outputs import write_bytes
from pincal.robots import example_robot_data_urdf

ROOT = Path(__file__).resolve().parents[1]
#: docs/diagnose.md's TIAGo command (the URDF as its $(python -c ...) prints it), and the page.
DIAGNOSE = ["diagnose", "data/tiago_mocap/qualisys_2021-11-30_static_postures.csv",
            "--validation", "data/tiago_mocap/qualisys_2021-11-26_static_postures.csv",
            "--tip-link", "wrist_ft_tool_link", "--out", "tiago_diagnosed.urdf", "--report", "tiago_diag/REPORT.json"]
HTML = "tiago_diag/REPORT.html"
WINDOW = "1280,1600"


def pincal(*args: str, cwd: Path) -> None:
    """Run ``pincal ARGS`` in ``cwd`` as a user would (a new process); stop on a failure."""
    subprocess.run([sys.executable, "-m", "pincal", *args], cwd=cwd, check=True, stdout=subprocess.DEVNULL)


def screenshot(page: Path, png: Path) -> None:
    """The top of ``page`` in headless Chromium at :data:`WINDOW` pixels, as ``png``."""
    chromium = shutil.which("chromium")
    if chromium is None:
        sys.exit("make_report_example: Chromium is not installed: apt-get install -y chromium")
    sandbox = ["--no-sandbox"] if hasattr(os, "geteuid") and os.geteuid() == 0 else []  # root cannot sandbox
    subprocess.run([chromium, "--headless", *sandbox, "--hide-scrollbars", f"--window-size={WINDOW}",
                    f"--screenshot={png}", page.resolve().as_uri()], check=True, capture_output=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs", help="folder to write into (default: docs/)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="pincal-report-example-") as folder:
        work = Path(folder)
        pincal("example", "tiago_mocap", cwd=work)
        tiago = str(example_robot_data_urdf("tiago_description/robots/tiago.urdf"))
        pincal(DIAGNOSE[0], tiago, *DIAGNOSE[1:], "--html", HTML, cwd=work)
        png = work / "report.png"
        screenshot(work / HTML, png)
        args.out.mkdir(parents=True, exist_ok=True)
        write_bytes(args.out / "report-example.html", (work / HTML).read_bytes())
        write_bytes(args.out / "report.png", png.read_bytes())
    print(f"wrote {args.out / 'report-example.html'}\nwrote {args.out / 'report.png'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
