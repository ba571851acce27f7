"""Writes ``ur_arm.sdf``, the second arm: six revolute joints with UR5e-like kinematics, holding the
same gripper as ``arm.sdf`` (run once after a change here or in arm.sdf's gripper; the output is
committed, and tests/test_second_arm.py checks that it is this script's output). Usage:
``python models/generate_ur_arm.py`` (needs numpy).

The gripper (links ``gripper`` and ``gripper_finger``, frame ``grasp``, joints ``ft_sensor`` and
``gripper_joint``) is copied from arm.sdf, its weld moved to this arm's flange: one gripper, defined
once. Each link's mass is spread over its solid shapes by volume, and its inertia is theirs about
the link's centre of mass, so masses, centres of mass and inertias agree with what is drawn.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent

# UR5e's kinematics (Universal Robots' DH parameters), m: the shoulder's height above the base,
# the upper arm, the forearm, the lateral offset of the wrist, the wrist's two offsets.
D1, A2, A3, D4, D5, D6 = 0.1625, 0.425, 0.3922, 0.1333, 0.0997, 0.0996
TWO_PI = 6.283185307179586

HOUSING = "0.45 0.65 0.85 1"  # the joint housings: light blue
TUBE = "0.8 0.81 0.83 1"  # the links' tubes: aluminium
DARK = "0.22 0.23 0.25 1"  # the base
SENSOR = "0.3 0.3 0.35 1"  # the wrist force/torque sensor (as on arm.sdf)


@dataclass(frozen=True)
class Cylinder:
    """A solid cylinder along the link frame's ``axis`` ("x", "y" or "z") centred at ``center``."""

    name: str
    axis: str
    radius: float
    length: float
    center: tuple[float, float, float]
    color: str

    @property
    def volume(self) -> float:
        return np.pi * self.radius ** 2 * self.length

    def inertia(self, mass: float) -> np.ndarray:
        """Its rotational inertia (kg m^2) about its centre, in the link frame."""
        across = mass * (3 * self.radius ** 2 + self.length ** 2) / 12
        moments = np.full(3, across)
        moments["xyz".index(self.axis)] = mass * self.radius ** 2 / 2
        return np.diag(moments)

    def pose(self) -> str:
        roll_pitch = {"x": "0 1.5707963267948966 0", "y": "1.5707963267948966 0 0", "z": "0 0 0"}
        return " ".join(f"{c:g}" for c in self.center) + " " + roll_pitch[self.axis]


@dataclass(frozen=True)
class Link:
    """A link: its frame's position in its parent link's frame (frames parallel at q = 0), its
    mass and its shapes."""

    name: str
    p_PL: tuple[float, float, float]
    mass: float
    shapes: tuple[Cylinder, ...]
    parent: str | None = None


@dataclass(frozen=True)
class Joint:
    """A revolute joint: axis in the child link's frame, limits (rad, N m, rad/s), damping
    (N m s/rad) and the PD gains of its actuator."""

    name: str
    parent: str
    child: str
    axis: str
    limit: float
    effort: float
    damping: float
    p: float
    d: float
    velocity: float = 3.14  # UR5e: 180 deg/s at every joint


# The arm at q = 0 stands straight up (upper arm and forearm along +z), the wrist's second link out
# towards -x, the flange facing up; the joint axes are z (pan), y (lift, elbow, wrist 1), -x (wrist 2)
# and z (wrist 3). A positive lift or elbow angle tips the arm towards +x. Every link frame is
# parallel to the base's at q = 0, so the gripper's frame is exactly the flange's (K = H exactly).
LINKS = (
    Link("ur_base", (0, 0, 0), 2.5, (Cylinder("base", "z", 0.075, 0.086, (0, 0, 0.043), DARK),)),
    Link("shoulder_link", (0, 0, D1), 3.7, (
        Cylinder("pan_housing", "z", 0.06, 0.095, (0, 0, -0.035), HOUSING),
        Cylinder("lift_housing", "y", 0.06, 0.14, (0, 0, 0), HOUSING)), "ur_base"),
    Link("upper_arm_link", (0, 0, 0), 6.3, (
        Cylinder("upper_arm", "z", 0.045, 0.325, (0, 0, 0.2125), TUBE),
        Cylinder("elbow_cap", "y", 0.05, 0.10, (0, 0, A2), HOUSING)), "shoulder_link"),
    # The wrist's lateral offset D4 is taken at the elbow (any of the three parallel y joints would
    # do): the forearm runs beside the upper arm, so the two fold past each other.
    Link("forearm_link", (0, -D4, A2), 2.8, (
        Cylinder("elbow_housing", "y", 0.048, 0.125, (0, 0.02, 0), HOUSING),
        Cylinder("forearm", "z", 0.038, 0.30, (0, 0, 0.2), TUBE)), "upper_arm_link"),
    Link("wrist_1_link", (0, 0, A3), 1.2, (
        Cylinder("wrist_1_housing", "y", 0.045, 0.10, (0, 0, 0), HOUSING),), "forearm_link"),
    Link("wrist_2_link", (-D5, 0, 0), 1.2, (
        Cylinder("wrist_2_housing", "x", 0.045, 0.10, (0.01, 0, 0), HOUSING),
        Cylinder("wrist_3_housing", "z", 0.045, 0.07, (0, 0, 0.035), HOUSING)), "wrist_1_link"),
    Link("wrist_3_link", (0, 0, 0), 0.35, (
        Cylinder("flange_plate", "z", 0.032, 0.02, (0, 0, 0.08), TUBE),
        Cylinder("ft_sensor", "z", 0.03, 0.0096, (0, 0, D6 - 0.0048), SENSOR)), "wrist_2_link"),
)
# UR5e's joint ranges (+-360 deg, the elbow +-180 deg) and torques (150 N m at the size-3 joints,
# 28 N m at the wrists); damping like arm.sdf's; gains near critical damping for these inertias.
JOINTS = (
    Joint("shoulder_pan_joint", "ur_base", "shoulder_link", "0 0 1", TWO_PI, 150, 0.1, 3000, 200),
    Joint("shoulder_lift_joint", "shoulder_link", "upper_arm_link", "0 1 0", TWO_PI, 150, 0.1, 6000, 300),
    Joint("elbow_joint", "upper_arm_link", "forearm_link", "0 1 0", np.pi, 150, 0.1, 3000, 150),
    Joint("wrist_1_joint", "forearm_link", "wrist_1_link", "0 1 0", TWO_PI, 28, 0.05, 400, 15),
    Joint("wrist_2_joint", "wrist_1_link", "wrist_2_link", "-1 0 0", TWO_PI, 28, 0.05, 300, 10),
    Joint("wrist_3_joint", "wrist_2_link", "wrist_3_link", "0 0 1", TWO_PI, 28, 0.02, 100, 3),
)
# The flange (tool0): D6 out along the wrist 3 axis, its z out of the flange.
FLANGE = f'<frame name="flange" attached_to="wrist_3_link"><pose>0 0 {D6:g} 0 0 0</pose></frame>'


def inertial(link: Link) -> tuple[np.ndarray, np.ndarray]:
    """The link's centre of mass and its rotational inertia about it (link frame)."""
    volumes = np.array([s.volume for s in link.shapes])
    masses = link.mass * volumes / volumes.sum()
    centers = np.array([s.center for s in link.shapes], float)
    com = masses @ centers / link.mass
    inertia = np.zeros((3, 3))
    for shape, m, c in zip(link.shapes, masses, centers, strict=True):
        d = c - com
        inertia += shape.inertia(m) + m * (d @ d * np.eye(3) - np.outer(d, d))
    return com, inertia


def _num(x: float) -> str:
    return f"{x:.6g}" if abs(x) > 1e-12 else "0"


def link_xml(link: Link) -> str:
    com, inertia = inertial(link)
    ixx, iyy, izz, ixy, ixz, iyz = (_num(inertia[i, j]) for i, j in
                                    ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)))
    pose = (f'<pose relative_to="{link.parent}">' + " ".join(_num(c) for c in link.p_PL) + " 0 0 0</pose>"
            if link.parent else "")
    lines = [f'    <link name="{link.name}">{pose}',
             f"      <inertial><pose>{' '.join(_num(c) for c in com)} 0 0 0</pose><mass>{link.mass:g}</mass>",
             f"        <inertia><ixx>{ixx}</ixx><iyy>{iyy}</iyy><izz>{izz}</izz>",
             f"          <ixy>{ixy}</ixy><ixz>{ixz}</ixz><iyz>{iyz}</iyz></inertia>",
             "      </inertial>"]
    for s in link.shapes:
        lines += [f'      <visual name="{s.name}"><pose>{s.pose()}</pose>',
                  f"        <geometry><cylinder><radius>{s.radius:g}</radius><length>{s.length:g}</length>"
                  "</cylinder></geometry>",
                  f"        <material><diffuse>{s.color}</diffuse></material></visual>"]
    return "\n".join(lines + ["    </link>"])


def joint_xml(j: Joint) -> str:
    return "\n".join([
        f'    <joint name="{j.name}" type="revolute">',
        f"      <parent>{j.parent}</parent><child>{j.child}</child>",
        f"      <axis><xyz>{j.axis}</xyz>",
        f"        <limit><lower>{-j.limit:.6f}</lower><upper>{j.limit:.6f}</upper>"
        f"<effort>{j.effort:g}</effort><velocity>{j.velocity:g}</velocity></limit>",
        f"        <dynamics><damping>{j.damping:g}</damping></dynamics></axis>",
        f'      <drake:controller_gains p="{j.p:g}" d="{j.d:g}"/>',
        "    </joint>"])


def _element(text: str, pattern: str) -> str:
    found = re.findall(pattern, text, re.S)
    if len(found) != 1:
        raise ValueError(f"arm.sdf: expected one element matching {pattern!r}, found {len(found)}")
    return found[0]


def gripper_xml(arm_sdf: str, last_link: str) -> str:
    """arm.sdf's gripper and its F/T weld, the weld's parent ``last_link`` and the gripper at the
    flange."""
    ft_sensor = _element(arm_sdf, r'<joint name="ft_sensor".*?</joint>')
    ft_sensor = re.sub(r"<parent>\w+</parent>", f"<parent>{last_link}</parent>", ft_sensor)
    gripper = _element(arm_sdf, r'<link name="gripper">.*?</link>')
    gripper = re.sub(r'^<link name="gripper"><pose relative_to="\w+">[^<]*</pose>',
                     '<link name="gripper"><pose relative_to="flange"/>', gripper)
    parts = [gripper, ft_sensor, _element(arm_sdf, r'<frame name="grasp".*?</frame>'),
             _element(arm_sdf, r'<link name="gripper_finger">.*?</link>'),
             _element(arm_sdf, r'<joint name="gripper_joint".*?</joint>')]
    return "\n".join("    " + p for p in parts)


HEADER = """<?xml version="1.0"?>
<!--
  Generated by generate_ur_arm.py from its tables and arm.sdf's gripper: edit those, not this file.
  A 6-DOF arm with UR5e-like kinematics (shoulder 0.1625 m above the base, upper arm 0.425 m,
  forearm 0.3922 m, wrist offsets 0.1333 / 0.0997 / 0.0996 m) and its own look (round aluminium
  tubes, light blue joint housings). Joints: shoulder_pan_joint (z), shoulder_lift_joint (y),
  elbow_joint (y), wrist_1_joint (y), wrist_2_joint (-x), wrist_3_joint (z), all PD-controlled
  actuators (drake:controller_gains). At q = 0 the arm stands straight up, the wrist's second link
  points to -x and the flange faces up.
  The flange frame (tool0) is on wrist_3_link, z out of the flange; the F/T sensor weld ft_sensor
  (wrist_3_link -> gripper) puts arm.sdf's gripper on it, so K = H = the gripper body frame and
  the grasp frame is where tools attach, as on arm.sdf.
-->
<sdf version="1.9">
  <model name="ur_arm">
"""


def sdf_text() -> str:
    """The text of ur_arm.sdf."""
    arm_sdf = (HERE / "arm.sdf").read_text(encoding="utf-8")
    body = [link_xml(link) for link in LINKS] + [joint_xml(j) for j in JOINTS] + [
        "    " + FLANGE, gripper_xml(arm_sdf, LINKS[-1].name)]
    return HEADER + "\n".join(body) + "\n  </model>\n</sdf>\n"


def main() -> None:
    (HERE / "ur_arm.sdf").write_text(sdf_text(), encoding="utf-8")


if __name__ == "__main__":
    main()
