"""``pincal example NAME --out DIR``: the shipped measurement sets, outside a clone.

Each set is copied byte for byte (README and licence with it), never over an existing folder, and
the docs' commands then run as written from the folder it was copied into. Every file of
``pincal/datasets/`` matches a package-data pattern of pyproject.toml, so the wheel carries it.
"""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import pytest
import tomllib

from pincal.cli.commands import main
from pincal.robots import example_robot_data_urdf
from pincal.workflows.example import EXAMPLES, GENERATED, dataset_folder

ROOT = Path(__file__).resolve().parent.parent
DATASETS = ROOT / "pincal" / "datasets"


@pytest.mark.parametrize("name", sorted(set(EXAMPLES) - set(GENERATED)))
def test_a_set_is_copied_whole_and_never_over_an_existing_one(name, tmp_path, capsys):
    assert main(["example", name, "--out", str(tmp_path / "data")]) == 0
    copied, source = tmp_path / "data" / name, dataset_folder(name)
    shipped = sorted(p.relative_to(source) for p in source.rglob("*")
                     if p.is_file() and p.name != "__init__.py" and "__pycache__" not in p.parts)
    assert sorted(p.relative_to(copied) for p in copied.rglob("*") if p.is_file()) == shipped
    assert all((copied / p).read_bytes() == (source / p).read_bytes() for p in shipped)
    if name == "urdf":  # the robots: the docs' urdf/kuka_lwr4plus.urdf, and no README to carry
        assert shipped == [Path("kuka_lwr4plus.urdf")]
        shipped = [Path("kuka_lwr4plus.urdf")]
        (copied / "README.md").write_text("", encoding="utf-8")  # a file the refusal below must keep
    else:
        assert Path("README.md") in shipped
    assert f"wrote {copied}" in capsys.readouterr().out
    assert [p.name for p in (tmp_path / "data").iterdir()] == [name]  # no staging folder left
    (copied / "README.md").write_text("edited", encoding="utf-8")
    assert main(["example", name, "--out", str(tmp_path / "data")]) == 2
    err = capsys.readouterr().err.strip()
    assert "exists; refusing to overwrite it" in err and len(err.splitlines()) == 1
    assert (copied / "README.md").read_text(encoding="utf-8") == "edited"


def test_the_talos_set_is_made_whole_the_same_each_time_and_never_over_an_existing_one(tmp_path, capsys):
    """pincal example talos simulates its set (nothing shipped): the URDF as example-robot-data has it, the rows,
    truth.json and README; the same bytes on a second run elsewhere; a second run into the same place refused."""
    for out in ("a", "b"):
        assert main(["example", "talos", "--out", str(tmp_path / out)]) == 0
    made = tmp_path / "a" / "talos"
    assert sorted(p.name for p in made.iterdir()) == ["README.md", "calibration.csv", "talos_full_v2.urdf",
                                                      "truth.json", "validation.csv"]
    assert all((made / p.name).read_bytes() == p.read_bytes() for p in (tmp_path / "b" / "talos").iterdir())
    assert (made / "talos_full_v2.urdf").read_bytes() == Path(
        example_robot_data_urdf("talos_data/robots/talos_full_v2.urdf")).read_bytes()
    header = (made / "calibration.csv").read_text(encoding="utf-8").splitlines()[0].split(",")
    assert "gripper_left_joint" in header and not any("fingertip" in c or "inner_double" in c for c in header)
    assert "truth.json" in capsys.readouterr().out
    assert main(["example", "talos", "--out", str(tmp_path / "a")]) == 2
    assert "exists; refusing to overwrite it" in capsys.readouterr().err


def test_the_docs_commands_run_on_a_copied_set(tmp_path, monkeypatch, capsys):
    """docs/getting-started.md's calibrate and evaluate, run in a folder that is not a clone."""
    monkeypatch.chdir(tmp_path)
    assert main(["example", "tiago_mocap"]) == 0
    urdf = str(example_robot_data_urdf("tiago_description/robots/tiago.urdf"))
    assert main(["calibrate", urdf, "data/tiago_mocap/qualisys_2021-11-30_static_postures.csv", "--tip-link",
                 "wrist_ft_tool_link", "--level", "full", "--out", "tiago_calibrated.urdf", "--report", "REPORT.json",
                 "--quiet"]) == 0
    assert main(["evaluate", "tiago_calibrated.urdf", "REPORT.json",
                 "data/tiago_mocap/qualisys_2021-11-26_static_postures.csv"]) == 0


def test_an_example_script_runs_outside_a_clone(tmp_path, monkeypatch, capsys):
    """pincal example examples --out . and the data it reads: docs/getting-started.md's
    `python examples/tiago_mocap.py` prints the table of that page (~2 s)."""
    monkeypatch.chdir(tmp_path)
    assert main(["example", "tiago_mocap"]) == 0 and main(["example", "examples", "--out", "."]) == 0
    monkeypatch.setattr(sys, "argv", ["examples/tiago_mocap.py"])
    with pytest.raises(SystemExit) as exited:
        runpy.run_path("examples/tiago_mocap.py", run_name="__main__")
    assert exited.value.code == 0
    table = capsys.readouterr().out
    page = (ROOT / "docs" / "getting-started.md").read_text(encoding="utf-8")
    # the held-out marker-1 RMS at each level: the page's table
    for level, page_level in (("registration", "registration"), ("offsets", "joint offsets"), ("full", "full")):
        held_out = next(line for line in table.splitlines() if line.startswith(level)).split()[3]
        page_row = next(line for line in page.splitlines() if line.startswith(f"| {page_level} |"))
        assert page_row.split("|")[4].strip().strip("*") == held_out


def test_every_shipped_file_is_package_data_and_the_clone_links_to_it():
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))[
        "tool"]["setuptools"]["package-data"]["pincal.datasets"]
    files = {p for p in DATASETS.rglob("*")  # a set pincal example made in a clone's data/ is no shipped file
             if p.is_file() and p.name != "__init__.py" and p.suffix != ".pyc" and "__pycache__" not in p.parts
             and p.relative_to(DATASETS).parts[0] not in GENERATED}
    shipped = {p for pattern in patterns for p in DATASETS.glob(pattern)}  # globbed as setuptools does
    assert files and not sorted(files - shipped), "add a package-data pattern for these"
    assert (ROOT / "data").resolve() == DATASETS.resolve()  # the docs' data/ paths, in a clone
    assert (ROOT / "examples").resolve() == (DATASETS / "examples").resolve()  # and examples/*.py
    installed = dataset_folder("mukca")  # the repository's folder, or site-packages' after pip install .
    assert sorted(p.name for p in installed.rglob("*.csv")) == sorted(
        p.name for p in (DATASETS / "mukca").rglob("*.csv"))


def test_an_unknown_set_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as caught:
        main(["example", "ur5"])
    assert caught.value.code == 2 and "invalid choice: 'ur5'" in capsys.readouterr().err
