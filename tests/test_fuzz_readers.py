"""Fuzzed readers: CSV v1 measurements and joint columns, DH tables, URDF and xacro files.

Each reader is fed clean files turned into the variants real files have (UTF-8 BOM,
Windows line endings, quoted headers and cells, trailing commas, whitespace around
cells, blank lines) — these must read exactly as the clean file — and files mutated
into junk (truncated, bytes flipped or inserted, latin-1 / UTF-16 / UTF-32 encodings,
huge or non-finite numbers, duplicated, missing or renamed columns, empty files,
binary noise; URDFs with a kinematic loop, a missing parent link, a duplicate joint,
non-numeric origins, truncated XML). Those must either read or raise pincal's
one-line error (:class:`pincal.errors.PincalError`): never another exception, never
a hang (hypothesis' deadline fails any example slower than 5 s; a read takes ~10 ms).

Hypothesis runs derandomized and without an example database, so CI sees the same
examples every run.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
from datetime import timedelta
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pincal.cli.commands import main
from pincal.errors import PincalError
from pincal.measurements.csv_v1 import read_joint_columns, read_measurements
from pincal.measurements.data import JointSpec
from pincal.model.chain import KinematicChain
from pincal.model.description import read_description
from pincal.model.dh.files import read_dh_csv
from pincal.model.urdf import load_urdf
from pincal.robots import KUKA_FLANGE_LINK, kuka_lwr4plus_urdf

XACRO_DIR = Path(__file__).parent / "data" / "kuka_lwr4plus_xacro"
FUZZ = settings(
    max_examples=60,
    deadline=timedelta(seconds=5),  # a hang or a pathological slowdown, not timing noise (a read is ~10 ms)
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
_COUNTER = itertools.count()

# ------------------------------------------------------------------ clean files

JOINTS = (
    JointSpec("j1", "revolute", -2.0, 2.0),
    JointSpec("slide", "prismatic", 0.0, 0.35),
    JointSpec("wheel", "continuous", -math.inf, math.inf),
)
MEASUREMENTS = [
    ["j1", "slide", "wheel", "x", "y", "z", "qx", "qy", "qz", "qw", "role", "temp_c"],
    ["0.1", "0.1", "5.0", "0.5", "0.2", "1.0", "0", "0", "0", "1", "cpa", "21.5"],
    ["-0.3", "0.2", "-7.0", "0.6", "0.1", "1.1", "0.7071067811865476", "0", "0", "0.7071067811865476", "", "21.7"],
    ["0.0", "0.0", "0.0", "0.4", "0.0", "0.9", "0", "0.6", "0", "0.8", "validation", ""],
    ["1.5", "0.3", "12.0", "-0.4", "1.2", "0.3", "0.5", "0.5", "0.5", "0.5", "calibration", "22.0"],
]
DH_TABLE = [
    ["joint", "a", "alpha", "d", "theta", "type", "lower", "upper"],
    ["j1", "0", "-1.5707963267948966", "0.3105", "3.141592653589793", "revolute", "-2.96", "2.96"],
    ["j2", "0.05", "-1.5707963267948966", "0", "1.5707963267948966", "", "-2.09", "2.09"],
    ["j3", "0", "0", "0.4", "0", "prismatic", "0", "0.3"],
]
URDF = """<?xml version="1.0"?>
<robot name="fuzzbot">
  <link name="base"/>
  <link name="l1">
    <inertial><origin xyz="0 0 0.1" rpy="0 0 0"/><mass value="2.0"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>
    <visual><origin xyz="0 0 0.1"/><geometry><cylinder radius="0.05" length="0.2"/></geometry></visual>
    <collision><geometry><box size="0.1 0.1 0.2"/></geometry></collision>
  </link>
  <link name="l2"/>
  <link name="l3"/>
  <link name="tip"/>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3" rpy="0 0 1.5707963267948966"/><axis xyz="0 0 1"/>
    <limit lower="-2.9" upper="2.9" effort="100" velocity="2"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="l1"/><child link="l2"/>
    <origin xyz="0.05 0 0.2" rpy="-1.5707963267948966 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="100" velocity="2"/>
  </joint>
  <joint name="j3" type="prismatic">
    <parent link="l2"/><child link="l3"/>
    <origin xyz="0 0.1 0" rpy="0 0.3 0"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="0.3" effort="100" velocity="0.5"/>
  </joint>
  <joint name="tip_joint" type="fixed">
    <parent link="l3"/><child link="tip"/>
    <origin xyz="0 0 0.08" rpy="0 0 0"/>
  </joint>
</robot>
"""
URDF_Q = np.array([[0.3, -0.7, 0.1], [-1.2, 1.1, 0.25], [0.0, 0.0, 0.0]])
SPECIAL_NUMBERS = ["1e308", "-1e308", "1e400", "-1e400", "nan", "NaN", "inf", "-Infinity", "1e-400", "0x10",
                   "1_000", "1,5", "", " ", "abc", "1 2", "--1", "+.5", "١", "∞", "1e", "e5", '"', "\x00"]


def table_text(rows, *, quote_header=False, quote_cells=False, trailing="none", spaces=False,
               blank_lines=False, newline="\n") -> str:
    """CSV text of ``rows`` in one of the forms real files take."""

    def cell(text: str, quoted: bool) -> str:
        if quoted:
            text = f'"{text}"'
            return f" {text} " if spaces else text
        return f" {text} \t" if spaces else text

    lines = []
    for i, row in enumerate(rows):
        line = ",".join(cell(c, quote_header if i == 0 else quote_cells) for c in row)
        if trailing == "all" or (trailing == "data" and i > 0) or (trailing == "header" and i == 0):
            line += ","
        lines.append(line)
        if blank_lines and i == 1:
            lines.append("" if not spaces else " , ")
    return newline.join(lines) + newline


@st.composite
def valid_forms(draw) -> dict:
    """Options of :func:`table_text` (and a BOM) that a correct reader accepts unchanged."""
    return {
        "bom": draw(st.booleans()),
        "quote_header": draw(st.booleans()),
        "quote_cells": draw(st.booleans()),
        "trailing": draw(st.sampled_from(["none", "all", "data", "header"])),
        "spaces": draw(st.booleans()),
        "blank_lines": draw(st.booleans()),
        "newline": draw(st.sampled_from(["\n", "\r\n"])),
    }


def render(rows, form: dict) -> bytes:
    options = {k: v for k, v in form.items() if k != "bom"}
    return (("\ufeff" if form["bom"] else "") + table_text(rows, **options)).encode("utf-8")


# ------------------------------------------------------------------ mutations


@st.composite
def mutated_rows(draw, rows):
    """``rows`` with cells replaced by special numbers, columns duplicated, dropped or renamed."""
    rows = [list(r) for r in rows]
    for _ in range(draw(st.integers(0, 3))):
        kind = draw(st.sampled_from(["cell", "duplicate", "drop", "rename", "short_row", "extra_cell"]))
        column = draw(st.integers(0, len(rows[0]) - 1))
        row = draw(st.integers(0, len(rows) - 1))
        if kind == "cell" and column < len(rows[row]):
            rows[row][column] = draw(st.sampled_from(SPECIAL_NUMBERS) | st.text(max_size=6))
        elif kind == "duplicate":
            for r in rows:
                r.append(r[column] if column < len(r) else "")
        elif kind == "drop" and len(rows[0]) > 1:
            for r in rows:
                del r[column: column + 1]
        elif kind == "rename":
            rows[0][column] = draw(st.sampled_from(["", "x", "j1", "ROLE", "x1", "q x", "joint"]))
        elif kind == "short_row" and len(rows[row]) > 1:
            rows[row].pop()
        elif kind == "extra_cell":
            rows[row].append(draw(st.sampled_from(["", "1.0", "junk"])))
    return rows


@st.composite
def mangled_bytes(draw, data: bytes) -> bytes:
    """``data`` truncated, re-encoded, or with bytes flipped, inserted or deleted; or replaced by noise."""
    kind = draw(st.sampled_from(["truncate", "flip", "insert", "delete", "latin-1", "utf-16", "utf-32",
                                 "empty", "noise", "nul", "keep"]))
    if kind == "truncate":
        return data[: draw(st.integers(0, len(data)))]
    if kind in ("flip", "insert", "delete"):
        out = bytearray(data)
        for _ in range(draw(st.integers(1, 4))):
            at = draw(st.integers(0, max(len(out) - 1, 0)))
            if kind == "flip" and out:
                out[at] = draw(st.integers(0, 255))
            elif kind == "insert":
                out[at:at] = draw(st.binary(min_size=1, max_size=8))
            elif out:
                del out[at: at + draw(st.integers(1, 16))]
        return bytes(out)
    text = data.decode("utf-8", errors="replace")
    if kind == "latin-1":
        return text.replace("e", "é", 2).encode("latin-1", errors="replace")
    if kind in ("utf-16", "utf-32"):
        return text.encode(kind)
    if kind == "empty":
        return draw(st.sampled_from([b"", b"\xef\xbb\xbf", b"\n\n", b" \r\n\t", b",,,\n,,\n"]))
    if kind == "noise":
        return draw(st.binary(max_size=300))
    if kind == "nul":
        return data.replace(b",", b"\x00,", 3)
    return data


def write(directory: Path, data: bytes, suffix: str) -> Path:
    path = directory / f"case{next(_COUNTER)}{suffix}"
    path.write_bytes(data)
    return path


def reads_or_one_line_error(read, path: Path):
    """``read(path)``'s value, or None when it raised pincal's error with a one-line message naming the file."""
    try:
        return read(path)
    except PincalError as exc:
        message = str(exc)
        assert message and "\n" not in message and "\r" not in message, repr(message)
        assert path.name in message, message
        return None


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fuzz")


# ------------------------------------------------------------------ CSV v1


def _measurements(path):
    return read_measurements(path, JOINTS)[0]


def _same_measurements(a, b, lines: bool) -> None:
    assert a.joint_names == b.joint_names
    np.testing.assert_array_equal(a.q, b.q)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.rotations, b.rotations)
    assert list(a.roles) == list(b.roles)
    assert sorted(a.extra) == sorted(b.extra)
    for name in a.extra:
        np.testing.assert_array_equal(a.extra[name], b.extra[name])
    if lines:
        np.testing.assert_array_equal(a.lines, b.lines)


@FUZZ
@given(form=valid_forms())
def test_measurement_variants_read_as_the_clean_file(workdir, form):
    clean = _measurements(write(workdir, table_text(MEASUREMENTS).encode(), ".csv"))
    variant = _measurements(write(workdir, render(MEASUREMENTS, form), ".csv"))
    _same_measurements(variant, clean, lines=not form["blank_lines"])
    q, lines = read_joint_columns(write(workdir, render(MEASUREMENTS, form), ".csv"), JOINTS)
    np.testing.assert_array_equal(q, clean.q)


@FUZZ
@given(data=st.data(), form=valid_forms())
def test_mutated_measurement_files_read_or_fail_in_one_line(workdir, data, form):
    rows = data.draw(mutated_rows(MEASUREMENTS))
    raw = data.draw(mangled_bytes(render(rows, form)))
    path = write(workdir, raw, ".csv")
    reads_or_one_line_error(_measurements, path)
    reads_or_one_line_error(lambda p: read_joint_columns(p, JOINTS), path)


# ------------------------------------------------------------------ DH tables


def _dh(path):
    robot, _ = read_dh_csv(path, "standard")
    return robot


@FUZZ
@given(form=valid_forms())
def test_dh_variants_read_as_the_clean_table(workdir, form):
    clean = _dh(write(workdir, table_text(DH_TABLE).encode(), ".csv"))
    variant = _dh(write(workdir, render(DH_TABLE, form), ".csv"))
    assert (variant.names, variant.types) == (clean.names, clean.types)
    for field in ("alpha", "a", "theta", "d", "lower", "upper", "velocity", "effort"):
        np.testing.assert_array_equal(getattr(variant, field), getattr(clean, field), err_msg=field)


@FUZZ
@given(data=st.data(), form=valid_forms())
def test_mutated_dh_tables_read_or_fail_in_one_line(workdir, data, form):
    rows = data.draw(mutated_rows(DH_TABLE))
    raw = data.draw(mangled_bytes(render(rows, form)))
    reads_or_one_line_error(_dh, write(workdir, raw, ".csv"))


def test_cells_with_line_breaks_give_one_line_errors(workdir):
    """A quoted cell may hold a line break; a message quoting it stays on one line."""
    rows = [list(r) for r in DH_TABLE]
    rows[2][5] = "revo\nlute"
    path = write(workdir, table_text(rows, quote_cells=True).encode(), ".csv")
    with pytest.raises(PincalError, match="revo") as info:
        _dh(path)
    assert "\n" not in str(info.value)


# ------------------------------------------------------------------ URDF and xacro


def _fk(path) -> np.ndarray:
    chain = KinematicChain.from_urdf(path, "tip")
    poses = chain.poses(URDF_Q)
    return np.concatenate([poses.tool_positions.ravel(), poses.tool_rotations.ravel()])


URDF_STRUCTURE = {
    "loop": ('<joint name="tip_joint"', '<joint name="back" type="fixed"><parent link="tip"/><child link="base"/>'
             '</joint>\n  <joint name="tip_joint"'),
    "two parents": ('<joint name="tip_joint"', '<joint name="again" type="fixed"><parent link="base"/>'
                    '<child link="l2"/></joint>\n  <joint name="tip_joint"'),
    "missing parent": ('<parent link="l2"/>', '<parent link="l9"/>'),
    "missing child": ('<child link="tip"/>', '<child link="nowhere"/>'),
    "duplicate joint": ('<joint name="j3"', '<joint name="j2"'),
    "duplicate link": ('<link name="l3"/>', '<link name="l3"/><link name="l3"/>'),
    "no parent element": ('<parent link="l1"/>', ''),
    "non-numeric origin": ('xyz="0.05 0 0.2"', 'xyz="0.05 zero 0.2"'),
    "short origin": ('rpy="0 0.3 0"', 'rpy="0 0.3"'),
    "nan origin": ('xyz="0 0.1 0"', 'xyz="0 nan 0"'),
    "huge origin": ('xyz="0 0.1 0"', 'xyz="0 1e400 0"'),
    "no limit": ('<limit lower="-2" upper="2" effort="100" velocity="2"/>', ''),
    "zero axis": ('<axis xyz="0 0 1"/>\n    <limit lower="0"', '<axis xyz="0 0 0"/>\n    <limit lower="0"'),
    "bad type": ('type="prismatic"', 'type="spherical"'),
    "bad mass": ('<mass value="2.0"/>', '<mass value="two"/>'),
    "bad box": ('size="0.1 0.1 0.2"', 'size="0.1 0.1"'),
    "not a robot": ('<robot name="fuzzbot">', '<sdf name="fuzzbot">'),
    "xacro markup": ('<link name="l2"/>', '<xacro:property xmlns:xacro="http://www.ros.org/wiki/xacro" '
                     'name="a" value="1"/><link name="l2"/>'),
    "unnamed link": ('<link name="l2"/>', '<link/>'),
    "unnamed robot": ('<robot name="fuzzbot">', '<robot>'),
}


@pytest.mark.parametrize("case", sorted(URDF_STRUCTURE))
def test_broken_urdf_structure_is_one_line_error(workdir, case):
    old, new = URDF_STRUCTURE[case]
    assert URDF.count(old) >= 1
    path = write(workdir, URDF.replace(old, new, 1).encode(), ".urdf")
    for read in (_fk, load_urdf):
        with pytest.raises(PincalError) as info:
            read(path)
        assert "\n" not in str(info.value) and path.name in str(info.value)


def test_urdf_forms_load_as_the_clean_file(workdir):
    clean = _fk(write(workdir, URDF.encode(), ".urdf"))
    forms = {
        "bom": b"\xef\xbb\xbf" + URDF.encode(),
        "crlf": URDF.replace("\n", "\r\n").encode(),
        "whitespace and comments": URDF.replace("><", ">\n \t <!-- c -->\n<").encode(),
        "utf-16": URDF.replace('<?xml version="1.0"?>', '<?xml version="1.0" encoding="UTF-16"?>').encode("utf-16"),
    }
    for name, raw in forms.items():
        np.testing.assert_array_equal(_fk(write(workdir, raw, ".urdf")), clean, err_msg=name)


@FUZZ
@given(data=st.data())
def test_mutated_urdfs_load_or_fail_in_one_line(workdir, data):
    text = URDF
    for _ in range(data.draw(st.integers(0, 2))):
        old, new = URDF_STRUCTURE[data.draw(st.sampled_from(sorted(URDF_STRUCTURE)))]
        text = text.replace(old, new, 1)
    if data.draw(st.booleans()):  # one attribute value replaced by a special number or text
        values = [m for m in ("0.3", "0.05 0 0.2", "-2", "0.01", "2.0", "0 0 1", "0.1 0.1 0.2") if m in text]
        if values:
            value = data.draw(st.sampled_from(values))
            text = text.replace(f'"{value}"', f'"{data.draw(st.sampled_from(SPECIAL_NUMBERS))}"', 1)
    raw = data.draw(mangled_bytes(text.encode()))
    path = write(workdir, raw, ".urdf")
    fk = reads_or_one_line_error(_fk, path)
    assert fk is None or np.all(np.isfinite(fk))  # an accepted model has finite kinematics
    urdf = reads_or_one_line_error(load_urdf, path)
    if urdf is not None:  # ... and finite joint origins, one parent per link
        assert all(j.origin is None or np.all(np.isfinite(j.origin)) for j in urdf.robot.joints)
        children = [j.child for j in urdf.robot.joints]
        assert len(children) == len(set(children))


def test_xacro_expands_to_the_packaged_urdf_to_1e_12():
    """FK of the xacro test description equals the packaged URDF's (it is a faithful xacro of it)."""
    q = np.random.default_rng(7).uniform(-2.0, 2.0, (40, 7))
    xacro = KinematicChain.from_urdf(XACRO_DIR / "kuka_lwr4plus.urdf.xacro", KUKA_FLANGE_LINK).poses(q)
    plain = KinematicChain.from_urdf(kuka_lwr4plus_urdf(), KUKA_FLANGE_LINK).poses(q)
    assert np.abs(xacro.tool_positions - plain.tool_positions).max() <= 1e-12
    assert np.abs(xacro.tool_rotations - plain.tool_rotations).max() <= 1e-12


@FUZZ
@given(data=st.data())
def test_mutated_xacros_expand_or_fail_in_one_line(workdir, data):
    top = (XACRO_DIR / "kuka_lwr4plus.urdf.xacro").read_text()
    macros = XACRO_DIR / "kuka_lwr4plus_macros.xacro"
    top = top.replace('filename="kuka_lwr4plus_macros.xacro"', f'filename="{macros}"')
    raw = data.draw(mangled_bytes(top.encode()))
    args = data.draw(st.dictionaries(st.sampled_from(["prefix", "flange_length", "unknown"]),
                                     st.sampled_from(SPECIAL_NUMBERS[:12] + ["a_", "<", "&", "0.1", ""]),
                                     max_size=2))
    path = write(workdir, raw, ".urdf.xacro")
    reads_or_one_line_error(lambda p: read_description(p, args), path)


# ------------------------------------------------------------------ command line


def _cli_one_line(capfd, argv, name: str) -> str:
    """Run ``pincal ARGV`` in this process: exit 2, one stderr line naming ``name``, no traceback."""
    code = main(argv)
    out, err = capfd.readouterr()
    assert code == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("pincal: error: ") and name in lines[0], err
    return lines[0]


def test_cli_reports_broken_inputs_in_one_line(workdir, capfd):
    kuka = str(kuka_lwr4plus_urdf())
    out = ["--out", str(workdir / "out.urdf"), "--report", str(workdir / "out.json")]
    header = ",".join(f"lwr_joint_{n}" for n in range(1, 8)) + ",x,y,z\n"
    utf16 = write(workdir, (header + "0,0,0,0,0,0,0,1,2,3\n").encode("utf-16"), ".csv")
    truncated = write(workdir, (header + "0,0,0,0,0,0,0,1,2,3\n0,0,0,0.1,").encode(), ".csv")
    loop = write(workdir, URDF.replace(*URDF_STRUCTURE["loop"], 1).encode(), ".urdf")
    dh = write(workdir, b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", ".csv")
    assert "UTF-16" in _cli_one_line(capfd, ["calibrate", kuka, str(utf16), "--tip-link", KUKA_FLANGE_LINK, *out],
                                     utf16.name)
    for argv, name in [
        (["calibrate", kuka, str(truncated), "--tip-link", KUKA_FLANGE_LINK, *out], truncated.name),
        (["calibrate", str(loop), str(truncated), "--tip-link", "tip", *out], loop.name),
        (["urdf-from-dh", str(dh), "--convention", "standard", "--out", str(workdir / "dh.urdf")], dh.name),
    ]:
        _cli_one_line(capfd, argv, name)
    assert not (workdir / "out.urdf").exists() and not (workdir / "dh.urdf").exists()


def test_cli_subprocess_broken_urdf_one_line_no_traceback(workdir):
    """The console script itself: Pinocchio's C++ parser must not add lines of its own on stderr."""
    bad = write(workdir, URDF.replace(*URDF_STRUCTURE["missing parent"], 1).encode(), ".urdf")
    result = subprocess.run(
        [sys.executable, "-m", "pincal", "plan", str(bad), "--tip-link", "tip", "--count", "3",
         "--out", str(workdir / "plan.csv"), "--report", str(workdir / "plan.json")],
        capture_output=True, text=True, timeout=120,
    )
    assert result.returncode == 2
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr, result.stderr
    assert bad.name in result.stderr and "l9" in result.stderr
