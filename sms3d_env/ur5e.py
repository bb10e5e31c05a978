"""A UR5e-class six-joint arm on a pedestal beside the bed (``assets/ur5e.xml``), with the same
tools as the other robots: the third built-in robot, and the template for adding one
(docs/add-a-robot.md, "A third robot: the UR5e").

The model is written from Universal Robots' published DH table and link masses (the sources and
what is ASSUMED: the header of ``assets/ur5e.xml`` and ``assets/NOTICE.txt``); nothing is
downloaded. Everything the rest of the package needs of the robot is here: its name, prefix,
joints, mount, home posture, gains and how the scripted picker approaches.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from sms3d_env.robot import APPROACHES, Tool, add_drives, check_tool_fields, mount_tool
from sms3d_env.robot_registry import register_robot

if TYPE_CHECKING:
    import mujoco

UR5E_PREFIX = "ur5e/"
UR5E_JOINTS: tuple[str, ...] = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
UR5E_XML = os.path.join(os.path.dirname(__file__), "assets", "ur5e.xml")
# The moving links (the base stands on the pedestal).
_LINKS = ("shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link")
# The suction tool's frame on the flange: turned half a turn about x, so that the tool's -z (its
# approach axis) is the flange's +z, out of the flange.
UR5E_TOOL_QUAT = (0.0, 1.0, 0.0, 0.0)
# Home (rad): elbow up over the bed, the cup 20 cm above the patch centre pointing down, the
# wrist bent (wrist_2 at -pi/2, away from the wrist singularity at wrist_2 = 0). Solved by least
# squares from UR's tool-down posture turned to face the bed, (pi, -1.2, 1.8, -2.17, -pi/2, 0).
UR5E_HOME_Q: tuple[float, ...] = (2.8409, -0.915, 2.3039, -2.9597, -1.5708, 0.1052)


@register_robot("ur5e")
@dataclass(frozen=True)
class UR5eConfig:
    """The UR5e's mount, drives and tool.

    Attributes:
        mount_pos: the base on a pedestal beside the bed (m): 0.45 m from the patch centre along
            -x (its 149 mm foot 25 mm outside the 0.7 m patch), 0.30 m above the soil, so that
            the 850 mm reach covers the patch with the tool pointing down. Why there: hanging
            above the bed puts part of the patch under the base, where a UR arm's shoulder is
            singular (the wrist on the base's axis); beside it the arm reaches over the bed
            elbow up, its links above the caps, and the tool pointing down keeps the wrist bent
            (wrist_2 near -90 deg), far from the wrist singularity. ASSUMPTION: the pedestal's
            place and height, chosen by measurement (scripted picker, the first 100 held-out
            beds): at 0.55 m out and 0.10 m up every exact-pose pick succeeded, but at a 10 to
            30 deg pose error 2 to 3 approaches stopped short: for near targets whose estimated
            axis leans away from the base the elbow came down onto the soil, for far ones leaning
            towards it the elbow was stretched straight (its singularity). Here: none at 10 deg,
            1 at 20 deg, 2 at 30 deg, where the estimated pose has no IK solution within the
            joint limits: a target 0.26 m from the base's axis leaning away from the base (the
            wrist would have to pass over the base), one 0.64 m out leaning 62 deg towards it
            (past the reach).
        mount_yaw_deg, mount_roll_deg: base rotation (deg), 0: standing upright, q = 0 along -x.
        tool, cup_radius, tube_length, finger_*: the tool, as in ``RobotConfig``.
        kp_large, kp_small: position gains of the shoulder/elbow and wrist actuators
            (N m/rad). ASSUMPTION: ~40 ms tracking with ``armature``.
        force_large, force_small: torque limits (N m): 150 for the base, shoulder and elbow,
            28 for the wrists. ASSUMPTION: the rated torques of UR's size-3 and size-1 joints
            as MuJoCo Menagerie's UR5e model uses them; the controller never asks for more
            than a fraction (the links are gravity-compensated, as the Jaco's are).
        armature: reflected rotor inertia of each joint (kg m^2), set in ``assets/ur5e.xml``.
            ASSUMPTION: 0.1, a harmonic drive's rotor through ~100:1.
        approach: how the scripted pickers reach the stand-off point (``RobotConfig.approach``).
    """

    name: ClassVar[str] = "ur5e"
    prefix: ClassVar[str] = UR5E_PREFIX
    joints: ClassVar[tuple[str, ...]] = UR5E_JOINTS

    mount_pos: tuple[float, float, float] = (-0.45, 0.0, 0.30)
    mount_yaw_deg: float = 0.0
    mount_roll_deg: float = 0.0
    tool: Tool = "suction"
    cup_radius: float = 0.010
    tube_length: float = 0.09
    kp_large: float = 2000.0
    kp_small: float = 500.0
    force_large: float = 150.0
    force_small: float = 28.0
    finger_kp: float = 2.0
    finger_force: float = 0.25
    finger_damping: float = 0.1
    finger_armature: float = 0.001
    home_q: tuple[float, ...] = UR5E_HOME_Q
    approach: str = "cartesian"

    def __post_init__(self) -> None:
        check_tool_fields(self)
        if self.approach not in APPROACHES:
            raise ValueError(f"{type(self).__name__}.approach must be one of {APPROACHES}, got {self.approach!r}")
        if len(self.home_q) != len(self.joints):
            raise ValueError(f"{type(self).__name__}.home_q must have {len(self.joints)} entries, got {len(self.home_q)}")
        for name in ("kp_large", "kp_small", "force_large", "force_small"):
            value = getattr(self, name)
            if not value > 0:
                raise ValueError(f"{type(self).__name__}.{name} must be > 0, got {value!r}")

    def build_spec(self) -> mujoco.MjSpec:
        import mujoco

        spec = mujoco.MjSpec.from_file(UR5E_XML)
        # Every link collides with the soil and the mushrooms; the shoulder, upper arm and elbow
        # drives are the large ones.
        add_drives(spec, _LINKS, [(j, self.kp_large, self.force_large) if i < 3 else (j, self.kp_small, self.force_small)
                                  for i, j in enumerate(UR5E_JOINTS)])
        mount_tool(spec, spec.body("flange"), self, UR5E_TOOL_QUAT)
        return spec
