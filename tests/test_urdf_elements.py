"""The lxml URDF reader and writer give what yourdfpy gave, bit for bit; calibrate imports neither.

pincal read joint origins and wrote corrected URDFs through yourdfpy 0.0.60 until
the calibrate path stopped importing it (and trimesh, networkx: ~0.3 s per run).
The promise kept is byte-identical output, so the reference here is yourdfpy
itself, on every URDF example-robot-data ships (69 files: arms, humanoids,
quadrupeds, mobile manipulators; meshes, transmissions, gazebo tags, mimic
joints) and on the packaged KUKA LWR 4+.
"""

from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from lxml import etree

from pincal.errors import ModelError
from pincal.model import urdf as urdf_module
from pincal.model.description import read_description
from pincal.model.urdf import write_urdf_with_origins
from pincal.model.urdf_elements import joint_origins, parent_joint
from pincal.robots import example_robot_data_urdf, kuka_lwr4plus_urdf

ERD = example_robot_data_urdf("tiago_description/robots/tiago.urdf").parents[2]
ERD_URDFS = sorted(str(p.relative_to(ERD)) for p in ERD.rglob("*.urdf"))
DATA = Path(__file__).resolve().parents[1] / "data"


def _yourdfpy(path: Path) -> yourdfpy.URDF:
    """The URDF as pincal loaded it before: yourdfpy on the checked description, no meshes."""
    return yourdfpy.URDF.load(io.BytesIO(read_description(path).xml), build_scene_graph=False,
                              build_collision_scene_graph=False, load_meshes=False, load_collision_meshes=False,
                              filename_handler=yourdfpy.filename_handler_null)


def _previous_writer(source: Path, origins: dict[str, np.ndarray], comment: str) -> bytes:
    """The bytes pincal wrote before (yourdfpy's ``write_xml``, then the same merge with the source)."""
    description = read_description(source)
    urdf = _yourdfpy(source)
    joints = {joint.name: joint for joint in urdf.robot.joints}
    for name, matrix in origins.items():
        joints[name].origin = matrix.copy()
    out_root = urdf.write_xml().getroot()
    urdf_module._postprocess(description.root(), out_root, origins)
    out_root.addprevious(urdf_module._xml_comment(comment))
    buffer = io.BytesIO()
    out_root.getroottree().write(buffer, xml_declaration=True, encoding="utf-8", pretty_print=True)
    return buffer.getvalue()


#: example-robot-data's URDFs pincal refuses, and the words of the refusal (every other one must load).
REFUSED = {"ur3.urdf": "the <robot> element has no name"}


def _sources() -> list[Path]:
    return [kuka_lwr4plus_urdf()] + [ERD / name for name in ERD_URDFS]


@pytest.mark.parametrize("source", _sources(), ids=lambda p: p.name)
def test_origins_and_written_file_equal_yourdfpy_bit_for_bit(source, tmp_path):
    if source.name in REFUSED:  # refused before any writer runs: in one line, naming why
        with pytest.raises(ModelError, match=REFUSED[source.name]):
            read_description(source)
        return
    description = read_description(source)
    reference = _yourdfpy(source)
    root = description.root()  # one parse: joint_origins and parent_joint only read it
    ours = joint_origins(root)
    assert list(ours) == [joint.name for joint in reference.robot.joints]
    for joint in reference.robot.joints:
        expected = np.eye(4) if joint.origin is None else joint.origin
        # the same doubles, signed zeros included: the corrected origins are computed from them
        assert np.array_equal(ours[joint.name], expected) and np.array_equal(
            np.signbit(ours[joint.name]), np.signbit(expected)), joint.name
    for joint in reference.robot.joints:
        assert parent_joint(root, joint.child) == (joint.name, joint.type == "fixed")

    # corrected origins for three joints (one of them, if any, without an <origin> in the file)
    rng = np.random.default_rng(len(source.name))
    names = list(ours)
    chosen = [names[i] for i in sorted(rng.choice(len(names), size=min(3, len(names)), replace=False))]
    chosen += [j.name for j in reference.robot.joints if j.origin is None][:1]
    new = {}
    for name in chosen:
        delta = np.eye(4)
        delta[:3, :3] = pin.exp3(rng.normal(size=3) * 0.05)
        delta[:3, 3] = rng.normal(size=3) * 0.01
        new[name] = ours[name] @ delta
    out = tmp_path / "corrected.urdf"
    write_urdf_with_origins(source, out, new, comment="pincal test")
    try:
        previous = _previous_writer(source, new, "pincal test")
    except TypeError:  # yourdfpy cannot write a <texture/> without filename (iCub): now written as it was
        assert b"<texture/>" in out.read_bytes() and pin.buildModelFromUrdf(str(out)).njoints > 1
        return
    assert out.read_bytes() == previous


def test_written_file_refuses_what_the_form_cannot_hold(tmp_path):
    text = kuka_lwr4plus_urdf().read_text()
    broken = text.replace("<inertial>", '<visual><material name="m"><color rgba="red"/></material>'
                                        '<geometry><box size="0.1 0.1 0.1"/></geometry></visual><inertial>', 1)
    source = tmp_path / "broken.urdf"
    source.write_text(broken)
    with pytest.raises(ModelError, match="broken.urdf") as info:
        write_urdf_with_origins(source, tmp_path / "out.urdf", {})
    assert "\n" not in str(info.value)
    assert not (tmp_path / "out.urdf").exists()


def test_description_is_parsed_and_checked_once_per_content(tmp_path, monkeypatch):
    source = tmp_path / "kuka.urdf"
    source.write_bytes(kuka_lwr4plus_urdf().read_bytes())
    checks = []
    real = urdf_module.read_description.__globals__["check_urdf_tree"]
    monkeypatch.setitem(urdf_module.read_description.__globals__, "check_urdf_tree",
                        lambda *a, **k: (checks.append(1), real(*a, **k)))
    first = read_description(source)
    assert read_description(source) is first and len(checks) == 1
    source.write_bytes(source.read_bytes().replace(b'name="lwr_joint_1"', b'name="joint_one"'))
    again = read_description(source)  # same path, new content: read and checked again
    assert again is not first and len(checks) == 2 and b"joint_one" in again.xml


#: Modules the calibrate path must not import: yourdfpy and what it pulls in (the corrected URDF is
#: written with lxml), the plots and the HTML report (only with --html), the study's executors, xacro
#: (only for a .xacro), rosbags (pincal extract), and pincal's own modules of other commands.
NOT_ON_CALIBRATE_PATH = ("yourdfpy", "trimesh", "networkx", "matplotlib", "jinja2", "dask", "xacro", "rosbags",
                         "pincal.diagnosis", "pincal.planning.planner", "pincal.fit.level_choice",
                         "pincal.paper.methods", "pincal.simulation.paper", "pincal.study", "pincal.report.html")


def test_calibrate_imports_neither_yourdfpy_nor_plots_nor_other_commands(tmp_path):
    tiago = example_robot_data_urdf("tiago_description/robots/tiago.urdf")
    data = DATA / "tiago_mocap" / "qualisys_2021-11-30_static_postures.csv"
    argv = ["calibrate", str(tiago), str(data), "--tip-link", "wrist_ft_tool_link", "--level", "full",
            "--out", str(tmp_path / "t.urdf"), "--report", str(tmp_path / "R.json"), "--quiet"]
    script = ("import json, sys\nfrom pincal.cli.commands import main\ncode = main(sys.argv[1:])\n"
              "print(json.dumps([code, sorted(sys.modules)]))")
    done = subprocess.run([sys.executable, "-c", script, *argv], capture_output=True, text=True, check=True)
    code, modules = json.loads(done.stdout.strip().splitlines()[-1])
    assert code == 0 and (tmp_path / "t.urdf").is_file()
    loaded = [m for m in modules if any(m == n or m.startswith(n + ".") for n in NOT_ON_CALIBRATE_PATH)]
    assert loaded == []
    etree.parse(str(tmp_path / "t.urdf"))
