"""``package://`` collision meshes (``plan --min-distance``): found through ``--package-dir``,
``ROS_PACKAGE_PATH``, the ament index or this Python's install prefix (pip's example-robot-data) when the
URDF is not inside its package, ``package:///NAME/...`` (TALOS's) read as ``package://NAME/...``, and a
missing one named exactly, with where it was looked for and what to give. Each route gives the plan the
URDF in its own package gives (the same candidates refused)."""

from __future__ import annotations

import json
import shutil

import pytest

from pincal.cli.commands import main
from pincal.errors import ModelError
from pincal.model import packages
from pincal.model.packages import resolve_mesh, with_resolved_meshes
from pincal.robots import example_robot_data_urdf
from pincal.simulation.humanoid import TALOS_URDF

UR5 = example_robot_data_urdf("ur_description/urdf/ur5_robot.urdf")
PACKAGE = "example-robot-data"
PACKAGE_DIR = next(p for p in UR5.parents if p.name == PACKAGE)  # the URDF sits inside its package
MESH = f"package://{PACKAGE}/robots/ur_description/meshes/ur5/collision/base.stl"


def _refused(tmp_path, urdf, *flags) -> tuple[int, str, int | None]:
    out = tmp_path / f"run{len(list(tmp_path.glob('run*')))}"
    code = main(["plan", str(urdf), "--tip-link", "tool0", "--count", "8", "--sample", "120", "--measure", "pose",
                 "--min-distance", "0.01", "--quiet", "--out", str(out / "PLAN.csv"), "--report", str(out / "P.json"),
                 *flags])
    refused = json.loads((out / "P.json").read_text())["candidates"]["clearance"]["refused"] if code == 0 else None
    return code, "", refused


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """Candidates refused with the URDF where example-robot-data keeps it (its package around it)."""
    return _refused(tmp_path_factory.mktemp("ref"), UR5)[2]


@pytest.fixture
def copied(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    monkeypatch.setattr(packages, "installed_prefixes", list)  # not pip's example-robot-data either
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(UR5, urdf)
    return urdf


def test_a_missing_mesh_is_named_with_what_to_give(copied, tmp_path, capsys):
    code, _, _ = _refused(tmp_path, copied)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert f"collision mesh '{MESH}' not found" in err and f"--package-dir {PACKAGE}=DIR" in err


def test_package_dir_ros_package_path_and_the_ament_index_find_the_package(copied, tmp_path, reference,
                                                                           monkeypatch):
    assert reference is not None and reference > 0
    assert _refused(tmp_path, copied, "--package-dir", f"{PACKAGE}={PACKAGE_DIR}")[2] == reference
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(PACKAGE_DIR.parent))
    assert _refused(tmp_path, copied)[2] == reference
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    prefix = tmp_path / "install"
    (prefix / "share" / "ament_index" / "resource_index" / "packages").mkdir(parents=True)
    (prefix / "share" / "ament_index" / "resource_index" / "packages" / PACKAGE).touch()
    (prefix / "share" / PACKAGE).symlink_to(PACKAGE_DIR)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(prefix))
    assert _refused(tmp_path, copied)[2] == reference


def test_a_package_dir_that_is_not_a_folder_is_a_usage_error(copied, tmp_path, capsys):
    with pytest.raises(SystemExit) as caught:
        _refused(tmp_path, copied, "--package-dir", f"{PACKAGE}={tmp_path / 'nowhere'}")
    assert caught.value.code == 2 and "is not a folder" in capsys.readouterr().err


def test_a_copied_urdf_finds_its_meshes_where_pip_installed_them(tmp_path, reference, monkeypatch):
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(UR5, urdf)
    assert resolve_mesh(MESH, urdf) == (PACKAGE_DIR / MESH.split(PACKAGE + "/", 1)[1]).resolve()
    assert _refused(tmp_path, urdf)[2] == reference


def test_an_empty_authority_names_the_package_as_pinocchio_reads_it(tmp_path, monkeypatch):
    """TALOS's ``package:///example-robot-data/robots/talos_data/meshes/...``: Pinocchio joins what follows
    ``package://`` to each package folder, so the first segment is the package; a missing one is named."""
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    urdf = tmp_path / "ur5.urdf"
    shutil.copy(UR5, urdf)
    assert resolve_mesh(MESH.replace("package://", "package:///"), urdf) == resolve_mesh(MESH, urdf)
    monkeypatch.setattr(packages, "installed_prefixes", list)
    tried = resolve_mesh(MESH.replace("package://", "package:///"), urdf, {PACKAGE: tmp_path / "nowhere"})
    assert isinstance(tried, list) and tried[0] == tmp_path / "nowhere" / MESH.split(PACKAGE + "/", 1)[1]


def test_talos_copied_out_checks_self_collision_by_default(tmp_path, monkeypatch):
    """``pincal example talos`` copies TALOS's URDF out of example-robot-data: its 52 collision meshes
    (``package:///example-robot-data/...``) are found where pip installed them, so ``plan`` checks it."""
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    urdf = tmp_path / "talos_full_v2.urdf"
    shutil.copy(example_robot_data_urdf(TALOS_URDF), urdf)
    text = urdf.read_text(encoding="utf-8")
    resolved = with_resolved_meshes(text, urdf)
    assert text.count("package:///") > 0 and "package:///" not in resolved.split("<visual")[0]
    assert resolved.count("_collision.STL") == text.count("_collision.STL") > 0
    monkeypatch.setattr(packages, "installed_prefixes", list)
    with pytest.raises(ModelError, match=f"'package:///{PACKAGE}/robots/talos_data/meshes/.*' not found .*"
                                         f"--package-dir {PACKAGE}=DIR"):
        with_resolved_meshes(text, urdf)
