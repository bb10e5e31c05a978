"""The robot protocol (:class:`RobotSpec`) and the registry of robot classes by name, in the style
of ManiSkill3's ``@register_agent``: a robot's own module registers its class
(``@register_robot("gantry")`` in :mod:`sms3d_env.gantry`, ``"jaco"`` in :mod:`sms3d_env.robot`).

Import the registry through :mod:`sms3d_env.robots` (``make_robot``, ``registered_robots``,
``register_robot``), which imports the built-in robots' modules and so registers them; this module
imports no robot (they import it) and no MuJoCo, so command-line parsers list the names cheaply.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar, Protocol, TypeVar, runtime_checkable

if TYPE_CHECKING:
    import mujoco


@runtime_checkable
class RobotSpec(Protocol):
    """What the world, the controller and the env read of a robot's configuration
    (``sms3d_env.robot.RobotConfig``: the Jaco; ``sms3d_env.gantry.GantryConfig``: the gantry)."""

    name: ClassVar[str]  # the name it is registered under
    prefix: ClassVar[str]  # of every name the robot adds to the world
    joints: ClassVar[tuple[str, ...]]  # the joints the controller drives, actuators in this order
    mount_pos: tuple[float, float, float]
    mount_yaw_deg: float
    mount_roll_deg: float
    tool: str  # one of sms3d_env.robot.TOOLS
    cup_radius: float
    tube_length: float
    finger_kp: float
    finger_force: float
    finger_damping: float
    finger_armature: float
    home_q: tuple[float, ...]  # one angle (rad) or position (m) per joint
    approach: str  # one of APPROACHES: how the scripted pickers reach the stand-off point

    def build_spec(self) -> mujoco.MjSpec:
        """The robot with its tool, actuators and wrist sensor, unprefixed, its base the
        worldbody's first body."""
        ...


#: Every member of :class:`RobotSpec`, in its order: what a robot must have.
ROBOT_MEMBERS: tuple[str, ...] = (*RobotSpec.__annotations__, "build_spec")
#: The members a robot class carries itself (class variables and the method), checked when the
#: class is registered; the rest are checked on each configuration ``make_robot`` returns.
CLASS_MEMBERS: tuple[str, ...] = ("name", "prefix", "joints", "build_spec")

_ROBOTS: dict[str, type] = {}
R = TypeVar("R", bound=type)


def missing_members(robot: Any, members: tuple[str, ...] = ROBOT_MEMBERS) -> list[str]:
    """The members of :class:`RobotSpec` that ``robot`` (a configuration or a class) lacks."""
    return [m for m in members if not hasattr(robot, m) or (m == "build_spec" and not callable(robot.build_spec))]


def check_robot(robot: Any) -> Any:
    """``robot`` if it meets :class:`RobotSpec` (``TypeError`` naming the members it lacks;
    ``ValueError`` if ``home_q`` does not give one value per joint)."""
    if isinstance(robot, type):
        raise TypeError(f"robot must be a registered name {registered_robots()} or a robot configuration, got "
                        f"the class {robot.__qualname__} (build one: {robot.__qualname__}())")
    missing = missing_members(robot)
    if missing:
        raise TypeError(f"robot must be a registered name {registered_robots()} or meet "
                        f"sms3d_env.robots.RobotSpec; {robot!r} lacks {', '.join(missing)} (docs/add-a-robot.md)")
    joints = robot.joints
    if not joints or not all(isinstance(j, str) for j in joints):
        raise ValueError(f"{type(robot).__name__}.joints must be joint names, got {joints!r}")
    if len(robot.home_q) != len(joints):
        raise ValueError(f"{type(robot).__name__}.home_q must have one entry per joint ({len(joints)}), "
                         f"got {len(robot.home_q)}")
    return robot


def register_robot(name: str, cls: type | None = None) -> Callable[[R], R] | type:
    """Register the robot class ``cls`` under ``name``: ``make_robot(name)`` then returns
    ``cls()``. As a decorator, ``@register_robot("my_gantry")`` above the class.

    The class must carry ``name`` (equal to the name it registers under), ``prefix``, ``joints``
    and ``build_spec``, and build with no arguments; ``make_robot`` checks the rest of
    :class:`RobotSpec` on each configuration. ``TypeError`` for a class that lacks a member,
    ``ValueError`` for a name already registered or a class whose ``name`` differs."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"a robot's name must be a non-empty string, got {name!r}")

    def add(robot_cls: R) -> R:
        if not isinstance(robot_cls, type):
            raise TypeError(f"register_robot({name!r}) registers a class, got {robot_cls!r}")
        missing = missing_members(robot_cls, CLASS_MEMBERS)
        if missing:
            raise TypeError(f"{robot_cls.__qualname__} is not a robot class: it lacks {', '.join(missing)} "
                            f"of sms3d_env.robots.RobotSpec")
        if robot_cls.name != name:
            raise ValueError(f"{robot_cls.__qualname__}.name is {robot_cls.name!r}: a robot class registers under "
                             f"its own name (set name: ClassVar[str] = {name!r})")
        if name in _ROBOTS:
            raise ValueError(f"a robot named {name!r} is already registered ({_ROBOTS[name].__qualname__}); "
                             f"registered robots: {', '.join(registered_robots())}")
        _ROBOTS[name] = robot_cls
        return robot_cls

    return add if cls is None else add(cls)


def registered_robots() -> tuple[str, ...]:
    """The names registered so far, sorted (not in the order of registration, which depends on
    which module a process imports first)."""
    return tuple(sorted(_ROBOTS))


def robot_class(name: str) -> type:
    """The class registered under ``name`` (``ValueError`` listing the registered names)."""
    try:
        return _ROBOTS[name]
    except (KeyError, TypeError):
        raise ValueError(f"robot must be one of the registered robots {registered_robots()}, got {name!r} "
                         f"(sms3d_env.robots.register_robot adds one)") from None
