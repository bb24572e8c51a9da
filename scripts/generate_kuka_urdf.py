#!/usr/bin/env python3
"""Generate the KUKA LWR 4+ URDF of Table 1 of Franaszek & Marvel (2022).

Writes ``urdf/kuka_lwr4plus.urdf`` (the user-facing file) and
``pincal/robots/kuka_lwr4plus.urdf`` (the packaged copy), byte-identical::

    python scripts/generate_kuka_urdf.py            # (re)write both files
    python scripts/generate_kuka_urdf.py --check    # exit 1 if they are stale

How the file is made: a *template* URDF (links, joints, limits, inertials; every
joint origin the identity) is built programmatically with yourdfpy, then
:func:`pincal.model.dh.urdf.apply_dh_table` — the package's DH → URDF adapter — writes
the joint origins realising ``pincal.model.dh.table.KUKA_LWR4_DH`` (Table 1).

The joint origins come from the one DH-row → joint-origin core,
:func:`pincal.model.dh.table.dh_origin_rows` (through ``DHTable.joint_origins`` and
:func:`pincal.model.dh.table.dh_chain_origins`), which ``pincal urdf-from-dh`` uses too.

Kinematics (see ``pincal/model/dh/table.py``): distal DH,
``F_n = Rz(theta_n + eps_n) Tz(d_n) Tx(r_n) Rx(alpha_n)``. The value of joint
``lwr_joint_n`` is the paper's encoder angle theta_n; ``lwr_base_link`` is DH
frame 0 and ``lwr_flange`` DH frame 7. The URDF child link of joint n,
``lwr_link_n``, has the frame "DH frame n-1 turned by theta_n + eps_n about its z
axis" (origin on joint n's axis), *not* DH frame n: DH frame n is
``lwr_link_n · Tz(d_n) Tx(r_n) Rx(alpha_n)``.

Inertial parameters — sources and what was done to them:

* Link masses and centres of mass: C. Gaz, F. Flacco, A. De Luca, "Extracting
  feasible robot parameters from dynamic coefficients using nonlinear
  optimization methods", IEEE ICRA 2016, pp. 2075–2081 — the feasible parameter
  set they extracted from their reverse-engineered KUKA LWR IV dynamic model
  (Gaz, Flacco, De Luca, ICRA 2014). The numbers were transcribed from the
  model file that cites that paper, ``model/kuka_lwr4_gaz.urdf`` of FloBaRoID
  (github.com/kjyv/FloBaRoID); a second transcription
  (github.com/matteosodano/Faster_Inverse_Dynamics_and_Coefficients_Identification,
  ``load_Kuka_dynamic_pars.m``) has identical values. They are not checked
  against the paper's PDF. The centres of mass are expressed in the link frames
  of Gaz et al.'s standard DH table (alpha = [90, -90, -90, 90, 90, -90, 0] deg,
  d3 = 0.4 m, d5 = 0.39 m, base frame at the shoulder, KUKA zero = arm upright);
  :func:`gaz_to_urdf_link` maps them into the URDF link frames above.
* Rotational inertia: the tensors in those transcriptions are not physically
  valid (zero or bound-valued entries, e.g. I6yy = 0, I7xx = 0, link 1 not
  positive definite), so they are **not used**. Each link's inertia about its
  centre of mass is instead that of a uniform solid cylinder of the link's mass
  lying along the link (lengths from Table 1's geometry, radii assumed, see
  ``CYLINDERS``) — an approximation, positive definite and satisfying the
  triangle inequality by construction.
* Effort and velocity limits: the values of the lwr_defs ROS description of the
  LWR 4 as carried in the same FloBaRoID model file (204/306 N·m alternating,
  110/130/180 deg/s); nominal values, not a KUKA datasheet.
* Position limits: +-170 deg (joints 1, 3, 5, 7) and +-120 deg (joints 2, 4, 6),
  applied to theta_n as specified for pincal. Because of eps_2 = 90 deg, the
  range of theta_2 is *not* centred on the arm's upright pose.

The chain's root (``lwr_base_link``) and the flange frame carry no inertial:
the root is fixed to the world and the flange is a massless frame.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Sequence

import numpy as np
import yourdfpy

from pincal.model.dh.table import KUKA_LWR4_DH, DHTable, rot_x, trans
from pincal.model.dh.urdf import apply_dh_table
from pincal.model.urdf import format_floats
from pincal.robots import (
    KUKA_BASE_LINK,
    KUKA_FLANGE_JOINT,
    KUKA_FLANGE_LINK,
    KUKA_JOINTS,
    KUKA_LINKS,
)

REPO_ROOT = Path(__file__).resolve().parents[1]
#: The two generated files (user-facing, packaged); they must be byte-identical.
OUTPUTS = (
    REPO_ROOT / "urdf" / "kuka_lwr4plus.urdf",
    REPO_ROOT / "pincal" / "robots" / "kuka_lwr4plus.urdf",
)
ROBOT_NAME = "kuka_lwr4plus"

# ----------------------------------------------------------------- Gaz et al. 2016
#: Gaz et al.'s standard-DH table of the LWR (their link frames), rad and m.
GAZ_DH = DHTable(
    alpha=np.radians([90.0, -90.0, -90.0, 90.0, 90.0, -90.0, 0.0]),
    epsilon=np.zeros(7),
    r=np.zeros(7),
    d=np.array([0.0, 0.0, 0.4, 0.0, 0.39, 0.0, 0.0]),
)
#: Link masses [kg], links 1..7.
GAZ_MASS = (
    4.1948152162,
    4.2996847737,
    3.658530333,
    2.3846673548,
    1.7035567183,
    0.4000713156,
    0.6501439811,
)
#: Centres of mass [m] in Gaz et al.'s link frames, links 1..7.
GAZ_COM = (
    (-0.0216387515, 0.01, -0.0376881829),
    (0.0003284751, -0.0041132249, 0.0823647642),
    (0.0002593328, 0.1137431845, -0.000100257),
    (-0.0014648843, -0.0000461, 0.148580959),
    (-0.0003791484, -0.0553526131, -0.0101255137),
    (0.0020739022, 0.0586184696, -0.044799983),
    (-0.0004601303, 0.0014789221, 0.0715608282),
)
#: Gaz et al.'s base frame in DH frame 0 of Table 1: at the shoulder, d_1 above.
GAZ_BASE_IN_TABLE1 = trans(z=float(KUKA_LWR4_DH.d[0]))
#: Their joint angles from Table 1's encoder angles: q = theta - offset (their
#: zero is KUKA's, arm upright; Table 1's theta_2 = 90 deg is upright).
GAZ_JOINT_OFFSET = np.radians([0.0, 90.0, 0.0, 0.0, 0.0, 0.0, 0.0])

#: Solid-cylinder model of each link in Gaz et al.'s link frame n (arm upright):
#: (axis direction, length [m], radius [m]). Lengths follow Table 1 (shoulder at
#: 310.5 mm, joint 3/5 housings splitting the 400/390 mm arms in two, wrist to
#: flange 78 mm); radii are assumed from the LWR's ~120 mm housing diameter.
CYLINDERS = (
    ((0.0, 1.0, 0.0), 0.20, 0.06),  # link 1: base top -> shoulder, vertical = y1
    ((0.0, 0.0, 1.0), 0.20, 0.06),  # link 2: shoulder -> joint 3 housing, z2
    ((0.0, 1.0, 0.0), 0.20, 0.06),  # link 3: joint 3 housing -> elbow, y3
    ((0.0, 0.0, 1.0), 0.20, 0.06),  # link 4: elbow -> joint 5 housing, z4
    ((0.0, 1.0, 0.0), 0.19, 0.06),  # link 5: joint 5 housing -> wrist, y5
    ((0.0, 0.0, 1.0), 0.10, 0.05),  # link 6: wrist block, z6
    ((0.0, 0.0, 1.0), 0.03, 0.04),  # link 7: flange disc, z7
)

# ----------------------------------------------------------------- limits
#: Position limits [rad] (+-170 deg for joints 1, 3, 5, 7; +-120 deg for 2, 4, 6).
POSITION_LIMIT = np.radians([170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 170.0])
#: Effort limits [N m] (lwr_defs ROS description, see module docstring).
EFFORT_LIMIT = (204.0, 306.0, 204.0, 306.0, 204.0, 306.0, 204.0)
#: Velocity limits [rad/s] (110, 110, 130, 130, 180, 180, 180 deg/s; same source).
VELOCITY_LIMIT = tuple(float(v) for v in np.radians([110.0, 110.0, 130.0, 130.0, 180.0, 180.0, 180.0]))


def _snap(matrix: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    """Round entries within ``tol`` of an integer (cos(pi/2) noise) to it."""
    out = np.array(matrix, dtype=float)
    near = np.abs(out - np.round(out)) < tol
    out[near] = np.round(out[near])
    return out + 0.0


def _chain_frames(table: DHTable, theta: np.ndarray) -> list[np.ndarray]:
    """DH frames 1..N of ``table`` at ``theta`` in its frame 0."""
    frames, pose = [], np.eye(4)
    for n in range(table.n_joints):
        pose = pose @ table.link_transform(n, theta[n])
        frames.append(pose)
    return frames


def gaz_frames_in_table1() -> list[np.ndarray]:
    """Constant transforms ``X_n = (Table-1 DH frame n)^-1 · (Gaz frame n)``, n = 1..7.

    Both chains are evaluated at the same physical configuration (Gaz's
    ``q = theta - GAZ_JOINT_OFFSET``); the transform of every link must not depend
    on the configuration, which is checked at a second configuration.
    """

    def relative(theta: np.ndarray) -> list[np.ndarray]:
        ours = _chain_frames(KUKA_LWR4_DH, theta)
        theirs = _chain_frames(GAZ_DH, theta - GAZ_JOINT_OFFSET)
        return [np.linalg.inv(a) @ GAZ_BASE_IN_TABLE1 @ b for a, b in zip(ours, theirs)]

    reference = relative(np.radians([0.0, 90.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    check = relative(np.radians([37.0, 12.0, -81.0, 55.0, 140.0, -33.0, 71.0]))
    for n, (a, b) in enumerate(zip(reference, check), start=1):
        if np.max(np.abs(a - b)) > 1e-12:
            raise RuntimeError(f"Gaz et al.'s link frame {n} does not move with Table 1's link {n}")
    return [_snap(x) for x in reference]


def gaz_to_urdf_link(n: int) -> np.ndarray:
    """``lwr_link_n`` ← Gaz frame n transform (4x4) for link ``n`` in 1..7.

    ``lwr_link_n = DH frame n-1 · Rz(theta_n + eps_n)`` and
    ``DH frame n = lwr_link_n · Tz(d_n) Tx(r_n) Rx(alpha_n)``, so a point p given in
    Gaz frame n is ``Tz(d_n) Tx(r_n) Rx(alpha_n) · X_n · p`` in ``lwr_link_n``.
    """
    i = n - 1
    row = (
        trans(z=float(KUKA_LWR4_DH.d[i]))
        @ trans(x=float(KUKA_LWR4_DH.r[i]))
        @ rot_x(float(KUKA_LWR4_DH.alpha[i]))
    )
    return _snap(row @ gaz_frames_in_table1()[i])


def cylinder_inertia(mass: float, axis: Sequence[float], length: float, radius: float) -> np.ndarray:
    """Inertia tensor [kg m^2] about the centre of a uniform solid cylinder.

    Args:
        mass: [kg]. axis: unit direction of the cylinder axis. length, radius: [m].
    """
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    axial = 0.5 * mass * radius**2
    transverse = mass * (3.0 * radius**2 + length**2) / 12.0
    return transverse * (np.eye(3) - np.outer(a, a)) + axial * np.outer(a, a)


def link_inertials() -> list[tuple[float, np.ndarray, np.ndarray]]:
    """``(mass [kg], COM [m], inertia about COM [kg m^2])`` of lwr_link_1..7 in URDF link frames."""
    out = []
    for n in range(1, 8):
        to_link = gaz_to_urdf_link(n)
        com = (to_link @ np.append(GAZ_COM[n - 1], 1.0))[:3]
        axis, length, radius = CYLINDERS[n - 1]
        inertia_gaz = cylinder_inertia(GAZ_MASS[n - 1], axis, length, radius)
        rot = to_link[:3, :3]
        inertia = rot @ inertia_gaz @ rot.T
        inertia = 0.5 * (inertia + inertia.T)
        out.append((float(GAZ_MASS[n - 1]), np.round(com, 12) + 0.0, np.round(inertia, 15) + 0.0))
    return out


def _table1_text() -> str:
    t = KUKA_LWR4_DH

    def fmt(values: np.ndarray, scale: float) -> str:
        return ", ".join(f"{v * scale:g}" for v in values)

    return (
        f"alpha = [{fmt(t.alpha, 180 / np.pi)}] deg, eps = [{fmt(t.epsilon, 180 / np.pi)}] deg,\n"
        f"    r = [{fmt(t.r, 1000)}] mm, d = [{fmt(t.d, 1000)}] mm"
    )


PROVENANCE = f"""
  Generated by scripts/generate_kuka_urdf.py from Table 1 of Franaszek & Marvel (2022),
  "Using Full Pose Measurement for Serial Robot Calibration". DO NOT EDIT: change the
  script and rerun it (it also writes the packaged copy pincal/robots/kuka_lwr4plus.urdf).

  KUKA LWR 4+, distal DH convention: F_n = Rz(theta_n + eps_n) Tz(d_n) Tx(r_n) Rx(alpha_n),
  Table 1: {_table1_text()}.
  The value of joint lwr_joint_n is the encoder angle theta_n [rad]. lwr_base_link is DH
  frame 0; lwr_link_n is DH frame n-1 turned by theta_n + eps_n about z (not DH frame n);
  lwr_flange (fixed joint lwr_flange_joint) is DH frame 7.

  Joint zeros: with Table 1's eps_2 = 90 deg the zero of joint 2 is NOT KUKA's controller
  zero: at q = 0 the arm is not upright (the upper arm is horizontal); it is upright at
  theta_2 = +90 deg. Position limits +-170/+-120 deg are applied to theta_n as given.

  Inertials: masses and centres of mass from Gaz, Flacco & De Luca, ICRA 2016 (feasible
  parameters of the KUKA LWR IV), transformed into the URDF link frames; inertia tensors
  are uniform solid-cylinder approximations (the published ones are not physically valid).
  Effort/velocity limits: lwr_defs ROS description values. Details in the script.
"""


def build_template(path: Path) -> None:
    """Write the template URDF (identity joint origins) to ``path``."""
    inertials = link_inertials()
    links = [yourdfpy.Link(name=KUKA_BASE_LINK)]
    for name, (mass, com, inertia) in zip(KUKA_LINKS, inertials):
        origin = np.eye(4)
        origin[:3, 3] = com
        links.append(
            yourdfpy.Link(
                name=name,
                inertial=yourdfpy.Inertial(origin=origin, mass=mass, inertia=inertia),
            )
        )
    links.append(yourdfpy.Link(name=KUKA_FLANGE_LINK))

    joints = []
    parents = (KUKA_BASE_LINK,) + KUKA_LINKS[:-1]
    for n, (name, parent, child) in enumerate(zip(KUKA_JOINTS, parents, KUKA_LINKS)):
        joints.append(
            yourdfpy.Joint(
                name=name,
                type="revolute",
                parent=parent,
                child=child,
                origin=np.eye(4),
                axis=np.array([0.0, 0.0, 1.0]),
                limit=yourdfpy.Limit(
                    effort=float(EFFORT_LIMIT[n]),
                    velocity=float(VELOCITY_LIMIT[n]),
                    lower=-float(POSITION_LIMIT[n]),
                    upper=float(POSITION_LIMIT[n]),
                ),
            )
        )
    joints.append(
        yourdfpy.Joint(
            name=KUKA_FLANGE_JOINT,
            type="fixed",
            parent=KUKA_LINKS[-1],
            child=KUKA_FLANGE_LINK,
            origin=np.eye(4),
        )
    )
    robot = yourdfpy.Robot(name=ROBOT_NAME, links=links, joints=joints)
    tree = yourdfpy.URDF(robot=robot, build_scene_graph=False, load_meshes=False).write_xml()
    # yourdfpy writes the inertial origins through a matrix -> RPY round trip
    # ("0.0 -0.0 0.0"); give them their exact text.
    for (_, com, _), name in zip(inertials, KUKA_LINKS):
        origin = tree.getroot().find(f"link[@name='{name}']/inertial/origin")
        origin.attrib.clear()
        origin.attrib.update({"xyz": format_floats(com), "rpy": "0 0 0"})
    tree.write(str(path), xml_declaration=True, encoding="utf-8", pretty_print=True)


def generate_urdf_bytes() -> bytes:
    """The generated URDF file content (deterministic)."""
    with tempfile.TemporaryDirectory() as tmp:
        template = Path(tmp) / "template.urdf"
        output = Path(tmp) / "kuka_lwr4plus.urdf"
        build_template(template)
        apply_dh_table(
            template,
            output,
            KUKA_LWR4_DH,
            KUKA_JOINTS,
            KUKA_FLANGE_JOINT,
            comment=PROVENANCE,
        )
        return output.read_bytes()


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--check",
        action="store_true",
        help="do not write; exit 1 if a committed file differs from the generated content",
    )
    args = parser.parse_args(argv)
    content = generate_urdf_bytes()
    if args.check:
        stale = [p for p in OUTPUTS if not p.is_file() or p.read_bytes() != content]
        for path in stale:
            print(f"stale or missing: {path.relative_to(REPO_ROOT)}", file=sys.stderr)
        if stale:
            print("run: python scripts/generate_kuka_urdf.py", file=sys.stderr)
            return 1
        print("KUKA URDF files are up to date")
        return 0
    for path in OUTPUTS:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content)
        print(f"wrote {path.relative_to(REPO_ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
