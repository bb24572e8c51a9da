"""``pincal --help``, each subcommand's help and every refusal of a bad argument start quickly.

Building the parser imports no numpy, scipy or Pinocchio (pincal.cli.parser): with them
``pincal --help`` took 0.72 s on the development machine, without them 0.055 s (docs/performance.md;
numpy alone is 0.1 s of a 0.13 s ``python -c "import numpy"``). The fits still run with one BLAS
thread: the limit is set once the arguments are valid, after the libraries it limits are loaded.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

#: Not imported before a command runs: the numerical stack (their import is the start's cost).
HEAVY = ("numpy", "scipy", "pinocchio")

#: Ask for help, or be refused by argparse: a missing required flag, a bad value of each kind of check
#: (a number's range, a tool pose in degrees, a sensor model, a DH convention, extract's exclusive
#: clock-offset flags, detect's missing --board).
QUICK = [
    ["--help"],
    ["calibrate", "--help"],
    ["calibrate", "nofile.urdf", "nofile.csv"],
    ["calibrate", "u.urdf", "d.csv", "--tip-link", "x", "--out", "o", "--report", "r", "--prior-scale", "1,1e9"],
    ["urdf-from-dh", "t.csv", "--convention", "standard", "--out", "o", "--flange", "0,0,0,0,0,90"],
    ["plan", "u.urdf", "--tip-link", "x", "--count", "3", "--out", "o", "--report", "r", "--measure", "points:1"],
    ["plan", "u.urdf", "--tip-link", "x", "--count", "3", "--out", "o", "--report", "r", "--target-points", "1,2"],
    ["urdf-from-dh", "t.csv", "--convention", "craig", "--out", "o"],
    ["extract", "b", "--joints", "j", "--pose", "p", "--out", "o", "--clock-offset", "1", "--max-offset", "2"],
    ["simulate", "--out", "o", "--seed", "-1"],
    ["detect", "x.png", "--joints", "j.csv", "--out", "o.csv"],
]

_LOADED = ("import json, sys\nfrom pincal.cli.commands import main\n"
           "try:\n    code = main(sys.argv[1:])\nexcept SystemExit as stop:\n    code = stop.code\n"
           "print(json.dumps([code, sorted(sys.modules)]))")


def _heavy_modules(argv: list[str]) -> tuple[int, list[str]]:
    done = subprocess.run([sys.executable, "-c", _LOADED, *argv], capture_output=True, text=True, check=True)
    code, modules = json.loads(done.stdout.strip().splitlines()[-1])
    return code, [m for m in modules if m.split(".")[0] in HEAVY]


@pytest.mark.parametrize("argv", QUICK, ids=" ".join)
def test_help_and_refusals_import_no_numerical_library(argv):
    code, heavy = _heavy_modules(argv)
    assert code == (0 if argv[-1] == "--help" else 2)
    assert heavy == []


def test_every_blas_the_run_loads_gets_one_thread():
    """The limit of ``main`` reaches numpy's and scipy's OpenBLAS (separate builds), and no BLAS that
    calibrate's modules load comes after it. The processes ask for 4 BLAS threads (``OPENBLAS_NUM_THREADS``),
    so the limit shows on a 1-core machine too; the same modules loaded without it keep more than one."""
    template = ("import json, contextlib\nfrom threadpoolctl import threadpool_info\nfrom pincal.cli import commands\n"
                "with {limit}:\n    import pincal.workflows.calibration\n"
                "    pools = [(i['filepath'], i['num_threads'])\n"
                "             for i in threadpool_info() if i['user_api'] == 'blas']\n"
                "print(json.dumps(pools))")
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "4", "OMP_NUM_THREADS": "4"}

    def pools(limit: str) -> list:
        done = subprocess.run([sys.executable, "-c", template.format(limit=limit)], capture_output=True, text=True,
                              check=True, env=env)
        return json.loads(done.stdout.strip().splitlines()[-1])

    limited, free = pools("commands._blas_limited_to_one_thread()"), pools("contextlib.nullcontext()")
    assert len(limited) >= 1 and all(threads == 1 for _, threads in limited), limited
    assert any(threads > 1 for _, threads in free), free  # else this test could not fail
