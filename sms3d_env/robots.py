"""The robots by name: ``"gantry"`` (the Cartesian harvester, the default) and ``"jaco"`` (the
Kinova Jaco hanging above the bed, every link colliding)."""

from __future__ import annotations

from sms3d_env.gantry import GantryConfig
from sms3d_env.robot import RobotConfig, RobotSpec
from sms3d_env.robot_names import ROBOTS

#: The Jaco (``RobotConfig()``'s defaults): hanging upside down 0.7 m above the soil, 0.25 m from
#: the patch centre, with a right-angle suction adapter (``tool_tilt_deg=90``). ASSUMPTIONS chosen
#: by measurement: mounted beside the bed at or below the soil, as in v0, its upper arm and forearm
#: pass through the soil and the caps once they collide; hanging with an inline cup, pointing the
#: cup down straightens the wrist into its singularity, where the differential IK stopped short of
#: 20 % of the approaches at a 30° orientation error (``not_reached``); the right-angle adapter
#: keeps the wrist bent (scripted picker, 100 held-out 25-mushroom beds per error: 98 / 97 / 93 /
#: 84 % at 0 / 10 / 20 / 30°, one approach stopping short in the 400). Home: the cup 20 cm above the
#: patch centre, pointing down (solved by least squares from random starts, the best conditioned).
#: Approach: along a straight joint-space path (``approach="joint"``); the straight Cartesian
#: approach stopped short of 10 / 10 / 8 / 20 of 400 targets at 0 / 10 / 20 / 30° where the arm
#: folded under its shoulder or straightened its wrist on the way, the joint-space path of none.
HANGING_JACO = RobotConfig()


def make_robot(robot: str | RobotSpec) -> RobotSpec:
    """``robot`` as a configuration: a name in ``ROBOTS``, or a configuration as it is
    (``ValueError`` naming the argument and the choices)."""
    if not isinstance(robot, str):
        if not isinstance(robot, (RobotConfig, GantryConfig)):
            raise ValueError(f"robot must be one of {ROBOTS} or a RobotConfig / GantryConfig, got {robot!r}")
        return robot
    if robot == "gantry":
        return GantryConfig()
    if robot == "jaco":
        return HANGING_JACO
    raise ValueError(f"robot must be one of {ROBOTS}, got {robot!r}")
