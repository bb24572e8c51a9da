"""A mistyped link, joint or column: one line that names the closest real ones (difflib), and a list cut
to :data:`pincal.errors.LISTED` names instead of every link of the robot (79 on TIAGo)."""

from __future__ import annotations

import pytest

from pincal.cli.commands import main
from pincal.errors import LISTED, did_you_mean
from pincal.robots import KUKA_FLANGE_LINK, example_robot_data_urdf, kuka_lwr4plus_urdf

TIAGO = example_robot_data_urdf("tiago_description/robots/tiago.urdf")


def test_the_closest_names_first_and_a_short_list():
    links = [f"link_{i}" for i in range(40)] + ["wrist_ft_tool_link"]
    text = did_you_mean("wrist_ft_tol_link", links, "links")
    assert text.startswith("did you mean 'wrist_ft_tool_link'? links: link_0, ")
    assert text.endswith(f"… and {len(links) - LISTED} more")
    assert did_you_mean("zzz", ["a", "b"], "joints") == "joints: a, b"  # nothing close: no guess
    assert did_you_mean("x", [], "columns") == "columns: none"


def _run(tmp_path, capsys, urdf, data_text, *flags):
    data = tmp_path / "data.csv"
    data.write_text(data_text, encoding="utf-8")
    code = main(["calibrate", str(urdf), str(data), "--out", str(tmp_path / "o.urdf"),
                 "--report", str(tmp_path / "r.json"), *flags])
    return code, capsys.readouterr().err.strip()


def test_a_mistyped_tip_link(tmp_path, capsys):
    code, err = _run(tmp_path, capsys, TIAGO, "x,y,z\n0,0,0\n", "--tip-link", "wrist_ft_tol_link")
    assert code == 2 and len(err.splitlines()) == 1
    assert "did you mean 'wrist_ft_tool_link'" in err and "more" in err and len(err) < 600


def test_a_mistyped_joint_column(tmp_path, capsys):
    header = "lwr_joint_1,lwr_joint_2,lwr_jiont_3,lwr_joint_4,lwr_joint_5,lwr_joint_6,lwr_joint_7,x,y,z"
    code, err = _run(tmp_path, capsys, kuka_lwr4plus_urdf(), header + "\n" + ",".join(["0"] * 10) + "\n",
                     "--tip-link", KUKA_FLANGE_LINK)
    assert code == 2 and len(err.splitlines()) == 1
    assert "missing joint column(s) lwr_joint_3 (rename the file's column 'lwr_jiont_3' to 'lwr_joint_3'?)" in err


def test_a_mistyped_sigma_column(tmp_path, capsys):
    """extract writes spread_mm; --sigma-column spred_mm names it."""
    header = ",".join(f"lwr_joint_{i}" for i in range(1, 8)) + ",x,y,z,spread_mm"
    rows = "\n".join(",".join([f"{0.1 * (k + i):.2f}" for i in range(7)]
                              + [f"{0.5 + 0.01 * k}", f"{0.1 + 0.002 * k * k}", f"{0.2 + 0.03 * (k % 3)}", "0.08"])
                     for k in range(12))
    code, err = _run(tmp_path, capsys, kuka_lwr4plus_urdf(), header + "\n" + rows + "\n",
                     "--tip-link", KUKA_FLANGE_LINK, "--sigma-column", "spred_mm")
    assert code == 2 and len(err.splitlines()) == 1
    assert "no column 'spred_mm' for --sigma-column; did you mean 'spread_mm'?" in err


@pytest.mark.parametrize("flag, value, expected", [("--effect", "compliance:lwr_jiont_2:2e-4", "lwr_joint_2")])
def test_a_mistyped_joint_in_an_effect(tmp_path, capsys, flag, value, expected):
    code = main(["simulate", "--out", str(tmp_path / "sim"), flag, value])
    err = capsys.readouterr().err.strip()
    assert code == 2 and f"did you mean '{expected}'" in err and len(err.splitlines()) == 1
