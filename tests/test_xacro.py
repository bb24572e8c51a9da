"""xacro robot descriptions: expanded in memory, calibrated end to end, errors in one line.

The description under test is ``tests/data/kuka_lwr4plus_xacro`` (see its README): a
xacro rendering of the packaged KUKA LWR 4+ URDF with arguments ``prefix`` and
``flange_length``; with the defaults it expands to the same numbers as the URDF.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from pincal.cli.commands import main
from pincal.errors import ModelError
from pincal.measurements.csv_v1 import write_measurements
from pincal.model.chain import KinematicChain
from pincal.model.description import read_description
from pincal.model.urdf import read_joint_origins, write_urdf_with_origins
from pincal.robots import KUKA_FLANGE_JOINT, KUKA_FLANGE_LINK, KUKA_JOINTS, kuka_lwr4plus_urdf

XACRO_DIR = Path(__file__).parent / "data" / "kuka_lwr4plus_xacro"
XACRO = XACRO_DIR / "kuka_lwr4plus.urdf.xacro"


@pytest.fixture
def xacro_copy(tmp_path) -> Path:
    """The test description copied into its own folder (so tests can watch or change it)."""
    folder = tmp_path / "description"
    shutil.copytree(XACRO_DIR, folder)
    return folder / XACRO.name


@pytest.fixture(scope="module")
def arm_data(tmp_path_factory, noisy_large_experiment) -> tuple[Path, Path]:
    """The simulated KUKA calibration rows, once with the URDF's joint names and once prefixed ``arm_``."""
    folder = tmp_path_factory.mktemp("xacro_data")
    plain = folder / "lwr.csv"
    write_measurements(plain, noisy_large_experiment.calibration)
    renamed = folder / "arm.csv"
    header, rest = plain.read_text().split("\n", 1)
    renamed.write_text(header.replace("lwr_", "arm_") + "\n" + rest)
    return plain, renamed


def test_defaults_expand_to_the_packaged_urdf(tmp_path):
    """Every joint origin, limit and inertial of the expansion equals the packaged URDF's, and FK to 1e-12."""
    expanded = read_description(XACRO).root()
    packaged = etree.parse(str(kuka_lwr4plus_urdf()), etree.XMLParser(remove_comments=True)).getroot()

    def numbers(root):
        out = {}
        for element in root.iter():
            for key, value in element.attrib.items():
                if key not in ("name", "link", "type"):
                    owner = next((a.get("name") for a in element.iterancestors() if a.get("name")), "")
                    out[(owner, element.tag, key)] = [float(v) for v in value.split()]
        return out

    assert numbers(expanded) == numbers(packaged)
    q = np.random.default_rng(7).uniform(-2.0, 2.0, (40, 7))
    a = KinematicChain.from_urdf(XACRO, KUKA_FLANGE_LINK).poses(q)
    b = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK).poses(q)
    # 1e-12: both are the same doubles through the same Pinocchio code; any formatting loss would show.
    assert np.abs(a.tool_positions - b.tool_positions).max() <= 1e-12
    assert np.abs(a.tool_rotations - b.tool_rotations).max() <= 1e-12


def test_arguments_rename_and_move_the_flange():
    chain = KinematicChain.from_urdf(XACRO, "arm_flange", xacro_args={"prefix": "arm_", "flange_length": "0.1"})
    assert chain.joint_names == tuple(name.replace("lwr_", "arm_") for name in KUKA_JOINTS)
    origins = read_joint_origins(XACRO, [("prefix", "arm_"), ("flange_length", "0.1")])
    np.testing.assert_array_equal(origins["arm_flange_joint"][:3, 3], [0.0, 0.0, 0.1])


def test_expansion_writes_nothing_and_follows_edits(xacro_copy):
    before = sorted(p.name for p in xacro_copy.parent.iterdir())
    assert read_description(xacro_copy).provenance().startswith(f"Expanded from the xacro file {xacro_copy}")
    assert sorted(p.name for p in xacro_copy.parent.iterdir()) == before
    macros = xacro_copy.parent / "kuka_lwr4plus_macros.xacro"
    macros.write_text(macros.read_text().replace('effort="204.0"', 'effort="205.0"', 1))  # an included file
    assert b'effort="205.0"' in read_description(xacro_copy).xml  # the cached expansion is not reused


def test_an_included_file_is_never_overwritten(xacro_copy):
    macros = xacro_copy.parent / "kuka_lwr4plus_macros.xacro"
    before = macros.read_bytes()
    with pytest.raises(ModelError, match="includes it; never overwrite an input"):
        write_urdf_with_origins(xacro_copy, macros, {})
    assert macros.read_bytes() == before


def test_calibrate_xacro_end_to_end(tmp_path, arm_data, capsys):
    """calibrate on a xacro with arguments = calibrate on the plain URDF; the output is plain, commented URDF."""
    lwr, arm = arm_data
    common = ["--tip-link", "--level", "full"]
    assert main(["calibrate", str(kuka_lwr4plus_urdf()), str(lwr), common[0], KUKA_FLANGE_LINK, *common[1:],
                 "--out", str(tmp_path / "plain.urdf"), "--report", str(tmp_path / "plain.json")]) == 0
    assert main(["calibrate", str(XACRO), str(arm), "--xacro-arg", "prefix:=arm_", "--xacro-arg",
                 "flange_length:=0.078", common[0], "arm_flange", *common[1:],
                 "--out", str(tmp_path / "arm.urdf"), "--report", str(tmp_path / "arm.json")]) == 0
    capsys.readouterr()
    written = (tmp_path / "arm.urdf").read_text()
    assert "xacro" not in written.split("<robot", 1)[1]  # plain URDF: no xacro markup or namespace
    comment = written.split("-->", 1)[0]
    assert f"Expanded from the xacro file {XACRO.resolve()}" in comment
    assert "arguments: prefix:=arm_, flange_length:=0.078" in comment
    plain = read_joint_origins(tmp_path / "plain.urdf")
    corrected = read_joint_origins(tmp_path / "arm.urdf")
    for name in (*KUKA_JOINTS, KUKA_FLANGE_JOINT):
        # Same data, same model, same solver: the same doubles (1e-12 leaves room for nothing else).
        np.testing.assert_allclose(corrected[name.replace("lwr_", "arm_")], plain[name], rtol=0, atol=1e-12)
    report = json.loads((tmp_path / "arm.json").read_text())
    assert report["xacro_args"] == {"prefix": "arm_", "flange_length": "0.078"}
    assert json.loads((tmp_path / "plain.json").read_text())["xacro_args"] == {}
    # The corrected URDF is what the report's urdf_sha256 names: evaluate accepts the pair.
    assert main(["evaluate", str(tmp_path / "arm.urdf"), str(tmp_path / "arm.json"), str(arm)]) == 0
    # The nominal xacro evaluates too (another URDF than the report's, so it needs --allow-other-urdf).
    assert main(["evaluate", str(XACRO), str(tmp_path / "arm.json"), str(arm), "--xacro-arg", "prefix:=arm_",
                 "--allow-other-urdf"]) == 0


def test_plan_reads_a_xacro(tmp_path, capsys):
    assert main(["plan", str(XACRO), "--xacro-arg", "prefix:=arm_", "--tip-link", "arm_flange", "--count", "12",
                 "--sample", "60", "--out", str(tmp_path / "plan.csv"), "--report", str(tmp_path / "plan.json")]) == 0
    assert (tmp_path / "plan.csv").read_text().startswith("arm_joint_1,")
    assert json.loads((tmp_path / "plan.json").read_text())["sources"]["xacro_args"] == {"prefix": "arm_"}


def _one_line_error(capsys, argv) -> str:
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[-1].startswith("pincal calibrate: error: argument --xacro-arg:")
    return lines[-1]


def test_bad_xacro_arg_syntax_is_one_argparse_line(tmp_path, capsys):
    for text in ("flange_length=0.1", "flange_length", ":=0.1", "1x:=2", "a b:=1"):
        line = _one_line_error(capsys, ["calibrate", str(XACRO), "d.csv", "--xacro-arg", text, "--tip-link", "x",
                                        "--out", str(tmp_path / "o.urdf"), "--report", str(tmp_path / "r.json")])
        assert "NAME:=VALUE" in line


XACRO_HEAD = '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
BROKEN = {
    "missing include": (f'{XACRO_HEAD}<xacro:include filename="nowhere.xacro"/></robot>', "nowhere.xacro"),
    "undefined arg": (f'{XACRO_HEAD}<link name="$(arg tool_length)"/></robot>', "--xacro-arg tool_length:=VALUE"),
    "find": (f'{XACRO_HEAD}<xacro:include filename="$(find my_robot)/x.xacro"/></robot>', "$(find"),
    "bad xml": (f'{XACRO_HEAD}<link name="a"></robot>', "not well-formed XML"),
    "bad expression": (f'{XACRO_HEAD}<link name="${{1/0}}"/></robot>', "fix the xacro"),
    "unknown macro": (f'{XACRO_HEAD}<xacro:arm/></robot>', "unknown macro"),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_xacro_is_one_line_naming_the_file(tmp_path, arm_data, capfd, case):
    text, fragment = BROKEN[case]
    path = tmp_path / "robot.urdf.xacro"
    path.write_text(text)
    assert main(["calibrate", str(path), str(arm_data[0]), "--tip-link", "a", "--out", str(tmp_path / "o.urdf"),
                 "--report", str(tmp_path / "r.json")]) == 2
    out, err = capfd.readouterr()
    assert err.count("\n") == 1 and err.startswith("pincal: error: "), err
    assert str(path) in err and fragment in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["robot.urdf.xacro"]  # nothing written near the input


def test_argument_errors_name_what_to_do(capsys):
    with pytest.raises(ModelError, match=r"flange_lenght not used by this description \(its arguments: "
                                         r"flange_length, prefix\)"):
        read_description(XACRO, {"flange_lenght": "0.1"})
    with pytest.raises(ModelError, match="given twice"):
        read_description(XACRO, [("prefix", "a_"), ("prefix", "b_")])
    with pytest.raises(ModelError, match="apply to .xacro files only"):
        read_description(kuka_lwr4plus_urdf(), {"prefix": "a_"})
    with pytest.raises(ModelError, match=r"flange_joint'?: <origin xyz=\"0.0 0.0 abc\"> is not 3 finite numbers"):
        read_description(XACRO, {"flange_length": "abc"})


MACROS = "kuka_lwr4plus_macros.xacro"


@pytest.mark.parametrize("case", ["calibrate --report", "calibrate --html", "diagnose --report", "diagnose --html",
                                  "plan --out", "plan --report", "evaluate --html", "calibrate --fixture --report"])
def test_no_output_overwrites_an_included_file(xacro_copy, arm_data, capsys, case):
    """Every output of every command is checked against what the xacro includes, before any fit runs
    (nothing is written: not even --out, which calibrate writes before the report)."""
    folder = xacro_copy.parent
    macros, out = folder / MACROS, folder / "out.urdf"
    before, files = macros.read_bytes(), sorted(p.name for p in folder.iterdir())
    command, flag = case.split(" ", 1)
    outputs = {"--out": str(out), "--report": str(folder / "r.json"), "--html": str(folder / "r.html")}
    outputs[flag.split()[-1]] = str(macros)
    tip = ["--tip-link", KUKA_FLANGE_LINK]
    argv = {
        "calibrate": ["calibrate", str(xacro_copy), str(arm_data[0]), *tip, "--level", "offsets"],
        "diagnose": ["diagnose", str(xacro_copy), str(arm_data[0]), *tip, "--level", "offsets"],
        "plan": ["plan", str(xacro_copy), *tip, "--count", "8", "--sample", "40"],
        "evaluate": ["evaluate", str(xacro_copy), str(folder / "missing.json"), str(arm_data[0])],
    }[command]
    if "--fixture" in flag:  # checked before the data are read: any data file will do
        argv += ["--fixture", str(Path(__file__).parent.parent / "data" / "mukca" / "fixture.csv")]
    keys = {"calibrate": ("--out", "--report", "--html"), "diagnose": ("--out", "--report", "--html"),
            "plan": ("--out", "--report"), "evaluate": ("--html",)}[command]
    argv += [item for key in keys for item in (key, outputs[key])]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is an input of this run" in err and MACROS in err, err
    assert macros.read_bytes() == before and sorted(p.name for p in folder.iterdir()) == files


def test_diagnose_plots_never_overwrite_an_included_file(xacro_copy, arm_data, capsys):
    """--plots DIR gets diagnose_*.png files: an included file of that name in DIR is refused before the fit."""
    folder = xacro_copy.parent
    (folder / MACROS).rename(folder / "diagnose_errors_before_after.png")
    xacro_copy.write_text(xacro_copy.read_text().replace(MACROS, "diagnose_errors_before_after.png"))
    before = (folder / "diagnose_errors_before_after.png").read_bytes()
    assert main(["diagnose", str(xacro_copy), str(arm_data[0]), "--tip-link", KUKA_FLANGE_LINK, "--plots",
                 str(folder), "--out", str(folder.parent / "o.urdf"), "--report", str(folder.parent / "r.json")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gets files named diagnose_*.png" in err, err
    assert (folder / "diagnose_errors_before_after.png").read_bytes() == before
    assert not (folder.parent / "o.urdf").exists()
