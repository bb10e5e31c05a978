"""The robots by name: each robot's module registers its class (``@register_robot``, in the style
of ManiSkill3's ``@register_agent``), and importing this module imports the built-in ones:
``"gantry"`` (the Cartesian harvester, the default; :mod:`sms3d_env.gantry`), ``"jaco"`` (the
Kinova Jaco hanging above the bed, every link colliding; :mod:`sms3d_env.robot`) and ``"ur5e"``
(a UR5e-class arm on a pedestal beside the bed; :mod:`sms3d_env.ur5e`). How to add one:
docs/add-a-robot.md. Importing it loads no MuJoCo: building a robot does."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sms3d_env.gantry import GantryConfig
from sms3d_env.robot import RobotConfig
from sms3d_env.robot_registry import (
    RobotSpec,
    check_robot,
    register_robot,
    registered_robots,
    robot_class,
)
from sms3d_env.ur5e import UR5eConfig

__all__ = ["GantryConfig", "HANGING_JACO", "ROBOTS", "RobotSpec", "UR5eConfig", "make_robot", "register_robot",
           "registered_robots"]

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


class RegisteredNames(Sequence[str]):
    """The registered robots' names, read from the registry on every use (so a robot registered
    later is among them): ``"jaco" in ROBOTS``, ``choices=ROBOTS``, ``list(ROBOTS)``."""

    def __getitem__(self, index: Any) -> Any:
        return registered_robots()[index]

    def __len__(self) -> int:
        return len(registered_robots())

    def __eq__(self, other: object) -> bool:
        return tuple(self) == (tuple(other) if isinstance(other, Sequence) and not isinstance(other, str) else other)

    def __repr__(self) -> str:
        return repr(registered_robots())


#: The registered robots' names, sorted (the built-in: gantry, jaco, ur5e).
ROBOTS = RegisteredNames()


def make_robot(robot: str | RobotSpec) -> RobotSpec:
    """``robot`` as a configuration: a registered name (the registered class built with its
    defaults), or any object that meets :class:`~sms3d_env.robot_registry.RobotSpec`, as it is.
    ``ValueError`` for an unknown name (listing the registered ones), ``TypeError`` naming the
    members an object lacks."""
    if isinstance(robot, str):
        return check_robot(robot_class(robot)())
    return check_robot(robot)
