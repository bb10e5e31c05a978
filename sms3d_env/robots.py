"""The robots of ``SMS3DPick-v1`` by name: ``"gantry"`` (the Cartesian harvester) and ``"jaco"``
(the Kinova Jaco with every link colliding)."""

from __future__ import annotations

from sms3d_env.gantry import GantryConfig
from sms3d_env.robot import RobotConfig, RobotSpec

ROBOTS: tuple[str, ...] = ("gantry", "jaco")
#: The Jaco of ``SMS3DPick-v1``: hanging upside down 0.8 m above the soil, 0.25 m from the patch
#: centre (an ASSUMPTION chosen by measurement: mounted beside the bed at or below the soil, as in
#: v0, its upper arm and forearm pass through the soil and the caps once they collide; hanging at
#: 0.75-0.85 m, 21-23 of 24 exact-pose picks succeeded with every link colliding). Home: the cup
#: 20 cm above the patch centre, pointing down (solved by least squares, as ``robot.HOME_Q``).
HANGING_JACO = RobotConfig(mount_pos=(-0.25, 0.0, 0.80), mount_roll_deg=180.0, all_links_collide=True,
                           home_q=(-2.8197, 3.1131, 1.0698, -2.7805, -1.2937, 3.5666))


def make_robot(robot: str | RobotSpec) -> RobotSpec:
    """``robot`` as a configuration: a name in ``ROBOTS``, or a configuration as it is
    (``ValueError`` naming the argument and the choices)."""
    if not isinstance(robot, str):
        if not isinstance(robot, (RobotConfig, GantryConfig)):
            raise ValueError(f"robot must be one of {ROBOTS} or a RobotConfig / GantryConfig, got {robot!r}")
        if isinstance(robot, RobotConfig) and not robot.all_links_collide:
            raise ValueError("robot: a RobotConfig with all_links_collide=False has links that pass through the "
                             "soil and the mushrooms; set all_links_collide=True (v0's Jaco is robot=None)")
        return robot
    if robot == "gantry":
        return GantryConfig()
    if robot == "jaco":
        return HANGING_JACO
    raise ValueError(f"robot must be one of {ROBOTS}, got {robot!r}")
