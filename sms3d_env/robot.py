"""Robot assembly: the Kinova Jaco arm (dm_control's bundled model) or the Cartesian gantry
harvester (:mod:`sms3d_env.gantry`), with a suction tool or the Jaco 3-finger hand.

The Jaco (and the hand) are loaded from the dm_control wheel (BSD-3, see ``assets/NOTICE.txt``),
given gravity compensation and joint position actuators, fitted with a tool, and attached to a
scene ``MjSpec`` through a frame at the mount pose. Every name in the assembled model carries the
robot's prefix (``jaco/``, ``gantry/``). Actuators: the six arm joints first, then (hand) the
three fingers. ``RobotConfig`` registers itself as ``"jaco"`` (:mod:`sms3d_env.robot_registry`);
MuJoCo is imported where a robot is built, so that listing the robots' names loads none.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar, Literal

import numpy as np

from sms3d_env.robot_registry import RobotSpec, register_robot

if TYPE_CHECKING:
    import mujoco

PREFIX = "jaco/"
ARM_JOINTS: tuple[str, ...] = tuple(f"joint_{i}" for i in range(1, 7))
TOOL_SITE = "cup_site"  # suction: the cup face, +z out of the cup; hand: the grip site
# Wrist force/torque sensor between the last link and the tool (a real arm's wrist F/T, e.g. an
# ATI Mini40 under the tool flange): force and torque the tool exerts on the wrist, site frame.
WRIST_SITE, WRIST_FORCE, WRIST_TORQUE = "wrist_ft", "wrist_force", "wrist_torque"
CUP_BODY = "cup"
CUP_GEOM = "cup_face"
Tool = Literal["suction", "hand"]
TOOLS: tuple[str, ...] = ("suction", "hand")
#: How the scripted pickers bring the tool to the stand-off point (``RobotConfig.approach``).
APPROACHES: tuple[str, ...] = ("cartesian", "joint")
#: The suction tool's frame on the Jaco's last link (its -z is the approach axis); the hand's
#: own frame is the link's.
JACO_TOOL_QUAT = (0.0, 0.70710678, 0.70710678, 0.0)
# The hand's finger joints (one per finger; the distal segment is rigid) and, per finger, the
# bodies whose geoms touch an object.
FINGER_JOINTS: tuple[str, ...] = tuple(f"hand_finger_{i}" for i in range(1, 4))
FINGER_BODIES: tuple[tuple[str, str], ...] = tuple(
    (f"hand_b_finger_{i}", f"hand_b_finger_tip_{i}") for i in range(1, 4))

# Collision bitmasks shared by robot, soil and mushrooms (see physics.py for the mushroom side).
ROBOT_CONTYPE, ROBOT_CONAFFINITY = 2, 4
# Tool geoms also carry bit 8, the only bit the soil accepts, and so do the Jaco's links: every
# link collides with the soil and with mushrooms, never with another link or the tool (no robot
# geom accepts bits 2 or 8). (SMS3DPick-v0's Jaco, removed, had five links colliding with nothing.)
TOOL_CONTYPE = ROBOT_CONTYPE | 8
# Home posture (rad) of the Jaco hanging above the bed with the right-angle adapter: the cup 20 cm
# above the patch centre, pointing down (solved by least squares from random starts, the best
# conditioned).
HOME_Q = np.array([0.364, 1.227, 0.811, -0.691, -2.037, 3.415])


def kinova_dir() -> str:
    """Directory of dm_control's bundled Kinova Jaco assets."""
    import dm_control

    return os.path.join(os.path.dirname(dm_control.__file__), "third_party", "kinova")


@register_robot("jaco")
@dataclass(frozen=True)
class RobotConfig:
    """Where and how the arm is mounted and driven.

    Attributes:
        mount_pos: arm base position in the world (m). The bed patch is centred on the origin with
            the soil near z = 0; the base hangs 0.7 m above the soil, 0.25 m from the patch centre,
            so that most of the patch is reachable with the tool pointing down
            (``targets.select_target`` flags each target's reach in ``info["reachable"]``; the
            study counts only reachable targets). Why hanging: :data:`sms3d_env.robots.HANGING_JACO`.
        mount_yaw_deg: base rotation about world z.
        mount_roll_deg: base rotation about its own x after the yaw (180: hanging upside down).
        tool: ``"suction"`` (default) or ``"hand"`` (the Jaco 3-finger hand on finger position
            actuators).
        cup_radius: suction cup radius (m), 10 mm as in docs/physics.md (20 mm cup).
        tube_length: length of the tube between the wrist flange and the cup (m). ASSUMPTION.
        tool_tilt_deg: the angle between the tool's approach axis and the wrist's last joint
            axis (deg): 0 an inline tool; 90 (default) a right-angle adapter, which keeps the Jaco's wrist
            bent (away from its singularity, wrist joints 4 and 6 aligned) while the cup points
            down. ASSUMPTION: angled suction adapters are common on arm-mounted pickers; no
            published mushroom harvester with a Jaco sets the angle.
        kp_large, kp_small: position gains of the shoulder/elbow and wrist actuators (N m/rad).
            ASSUMPTION chosen for ~50 ms tracking with the model's armature.
        force_large, force_small: actuator torque limits (N m). ASSUMPTION near Jaco's ratings.
        finger_kp, finger_force: finger position gain (N m/rad) and torque limit (N m).
            ASSUMPTION: about 4 N at a fingertip 6 cm from its joint, above the 3.2 N shear force
            that grips and twists a mushroom (docs/physics.md), far below the bruising force.
        finger_damping, finger_armature: finger joint damping (N m s/rad) and armature (kg m^2).
            ASSUMPTION replacing dm_control's 0.75 and 0.1, which with this torque would close a
            finger in ~6 s and hit a cap like a 1.4 kg mass: now ~2.4 rad/s, 0.3 kg at the tip.
        approach: how the scripted pickers (``ScriptedPicker.for_env``) bring the tool to the
            stand-off point above the target: ``"cartesian"`` straight towards it, the cup
            turned onto the axis on the way; ``"joint"`` (default) first along a straight
            joint-space path to the arm configuration there (:mod:`sms3d_env.pickers.joint_path`), for an
            arm whose straight Cartesian approach crosses a singularity.
    """

    name: ClassVar[str] = "jaco"
    prefix: ClassVar[str] = PREFIX
    joints: ClassVar[tuple[str, ...]] = ARM_JOINTS

    mount_pos: tuple[float, float, float] = (-0.25, 0.0, 0.70)
    mount_yaw_deg: float = 0.0
    mount_roll_deg: float = 180.0
    tool: Tool = "suction"
    cup_radius: float = 0.010
    tube_length: float = 0.09
    tool_tilt_deg: float = 90.0
    kp_large: float = 1500.0
    kp_small: float = 500.0
    force_large: float = 40.0
    force_small: float = 15.0
    finger_kp: float = 2.0
    finger_force: float = 0.25
    finger_damping: float = 0.1
    finger_armature: float = 0.001
    home_q: tuple[float, ...] = field(default=tuple(HOME_Q))
    approach: str = "joint"

    def __post_init__(self) -> None:
        check_tool_fields(self)
        if self.approach not in APPROACHES:
            raise ValueError(f"{type(self).__name__}.approach must be one of {APPROACHES}, got {self.approach!r}")
        if len(self.home_q) != len(self.joints):
            raise ValueError(f"{type(self).__name__}.home_q must have {len(self.joints)} entries, got {len(self.home_q)}")
        if not (isinstance(self.tool_tilt_deg, (int, float)) and 0.0 <= self.tool_tilt_deg <= 90.0):
            raise ValueError(f"{type(self).__name__}.tool_tilt_deg must be an angle in [0, 90] degrees, "
                             f"got {self.tool_tilt_deg!r}")

    def build_spec(self) -> mujoco.MjSpec:
        return build_arm_spec(self)


def check_tool_fields(cfg: RobotSpec) -> None:
    """The tool fields every robot configuration shares (``ValueError`` naming the field)."""
    name = type(cfg).__name__
    if cfg.tool not in TOOLS:
        raise ValueError(f"{name}.tool must be one of {TOOLS}, got {cfg.tool!r}")
    if not 0.003 <= cfg.cup_radius <= 0.05:
        raise ValueError(f"{name}.cup_radius must be in [3, 50] mm, got {cfg.cup_radius!r}")


def _add_suction_tool(parent: mujoco.MjsBody, cfg: RobotSpec,
                      tool_quat: tuple[float, ...]) -> None:
    """A flange, a tube and a compliant cup along the tool frame's -z (``tool_quat`` on ``parent``)."""
    import mujoco

    tool = parent.add_body(name="tool", quat=list(tool_quat))
    kw = dict(contype=TOOL_CONTYPE, conaffinity=ROBOT_CONAFFINITY)
    tool.add_geom(name="flange", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.03, 0.008, 0],
                  pos=[0, 0, -0.008], mass=0.08, rgba=[0.7, 0.7, 0.7, 1], **kw)
    half = cfg.tube_length / 2
    tool.add_geom(name="tube", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.006, half, 0],
                  pos=[0, 0, -0.016 - half], mass=0.03, rgba=[0.8, 0.8, 0.8, 1], **kw)
    z_cup = -0.016 - cfg.tube_length
    cup = tool.add_body(name=CUP_BODY, pos=[0, 0, z_cup])
    # Compliant cup: soft contact (solref time constant 20 ms, wide solimp) stands in for the bellows.
    cup.add_geom(name=CUP_GEOM, type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                 size=[cfg.cup_radius, 0.004, 0], pos=[0, 0, -0.004], mass=0.01,
                 rgba=[0.15, 0.35, 0.8, 1], solref=[0.02, 1.0], solimp=[0.9, 0.95, 0.005, 0.5, 2],
                 friction=[1.0, 0.02, 0.001], condim=4, **kw)
    # Site on the cup face; +z points out of the cup (along the approach direction).
    cup.add_site(name=TOOL_SITE, pos=[0, 0, -0.008], quat=[0, 1, 0, 0], size=[0.004, 0, 0])


def _add_wrist_sensor(spec: mujoco.MjSpec, tool_root: mujoco.MjsBody) -> None:
    """F/T at ``tool_root``'s origin: MuJoCo's force/torque sensors read the interaction of the
    site's body (with everything it carries) and its parent, here the wrist link. Outputs only:
    sensors feed nothing back into the simulation."""
    import mujoco

    tool_root.add_site(name=WRIST_SITE, size=[0.002, 0, 0])
    for name, kind in ((WRIST_FORCE, mujoco.mjtSensor.mjSENS_FORCE),
                       (WRIST_TORQUE, mujoco.mjtSensor.mjSENS_TORQUE)):
        spec.add_sensor(name=name, type=kind, objtype=mujoco.mjtObj.mjOBJ_SITE, objname=WRIST_SITE)


def _add_hand_tool(parent: mujoco.MjsBody, spec: mujoco.MjSpec, cfg: RobotSpec,
                   tool_quat: tuple[float, ...]) -> None:
    """The Jaco 3-finger hand: palm and fingers collide like the suction tool (soil, mushrooms;
    not the arm), each finger joint on a position actuator over its full range. Its frame is
    placed so that its approach axis is the suction tool's for the same ``tool_quat``."""
    import mujoco

    hand = mujoco.MjSpec.from_file(os.path.join(kinova_dir(), "jaco_hand.xml"))
    for g in hand.geoms:
        g.contype, g.conaffinity = TOOL_CONTYPE, ROBOT_CONAFFINITY
    for j in hand.joints:
        j.damping[0], j.armature, j.frictionloss = cfg.finger_damping, cfg.finger_armature, 0.01
    hand_quat = np.empty(4)
    jaco_tool_inverse = np.empty(4)
    mujoco.mju_negQuat(jaco_tool_inverse, np.asarray(JACO_TOOL_QUAT))
    mujoco.mju_mulQuat(hand_quat, np.asarray(tool_quat, float), jaco_tool_inverse)
    frame = parent.add_frame(quat=list(hand_quat))
    frame.attach_body(hand.body("hand"), "hand_", "")
    grip = spec.site("hand_gripsite")
    palm = spec.body("hand_hand")
    # The grip site re-created as the tool site (+z out of the palm, between the fingertips).
    palm.add_site(name=TOOL_SITE, pos=list(grip.pos), quat=[0, 1, 0, 0], size=[0.004, 0, 0])
    for body in ("hand_hand", *(b for pair in FINGER_BODIES for b in pair)):
        spec.body(body).gravcomp = 1.0
    for jname in FINGER_JOINTS:
        act = spec.add_actuator(name=f"act_{jname}", target=jname, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=cfg.finger_kp)
        act.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = list(spec.joint(jname).range)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-cfg.finger_force, cfg.finger_force]


def build_arm_spec(cfg: RobotConfig) -> mujoco.MjSpec:
    """The Jaco arm with the chosen tool, gravity compensation and position actuators (no prefix)."""
    import mujoco

    spec = mujoco.MjSpec.from_file(os.path.join(kinova_dir(), "jaco_arm.xml"))
    add_drives(spec, ("b_1", "b_2", "b_3", "b_4", "b_5", "b_6"),
               [(j, cfg.kp_large, cfg.force_large) if i < 3 else (j, cfg.kp_small, cfg.force_small)
                for i, j in enumerate(ARM_JOINTS)])
    mount_tool(spec, spec.body("b_6"), cfg, _tilted(JACO_TOOL_QUAT, cfg.tool_tilt_deg))
    return spec


def add_drives(spec: mujoco.MjSpec, moving_bodies: Sequence[str],
               drives: Sequence[tuple[str, float, float]]) -> None:
    """What every robot's ``build_spec`` does to its model: the ``moving_bodies`` gravity-compensated,
    every geom given ``TOOL_CONTYPE`` / ``ROBOT_CONAFFINITY`` (it collides with the soil and the
    mushrooms, not with another link), and per ``(joint, kp, force limit)`` of ``drives``, in
    their order, a critically damped position actuator ``act_<joint>`` limited to that force."""
    import mujoco

    for body in moving_bodies:
        spec.body(body).gravcomp = 1.0
    for g in spec.geoms:
        g.contype, g.conaffinity = TOOL_CONTYPE, ROBOT_CONAFFINITY
    for jname, kp, limit in drives:
        act = spec.add_actuator(name=f"act_{jname}", target=jname, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=kp, dampratio=1.0)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-limit, limit]


def _tilted(tool_quat: tuple[float, ...], tilt_deg: float) -> tuple[float, ...]:
    """``tool_quat`` turned by ``tilt_deg`` about its own x axis (an angled tool adapter)."""
    import mujoco

    half = np.radians(tilt_deg) / 2
    quat = np.empty(4)
    mujoco.mju_mulQuat(quat, np.asarray(tool_quat, float), np.array([np.cos(half), np.sin(half), 0.0, 0.0]))
    return tuple(float(v) for v in quat)


def mount_tool(spec: mujoco.MjSpec, parent: mujoco.MjsBody, cfg: RobotSpec,
               tool_quat: tuple[float, ...]) -> None:
    """``cfg.tool`` on ``parent`` (its approach axis the -z of ``tool_quat`` there), with the
    wrist force/torque sensor at its root."""
    if cfg.tool == "suction":
        _add_suction_tool(parent, cfg, tool_quat)
        _add_wrist_sensor(spec, spec.body("tool"))
    else:
        _add_hand_tool(parent, spec, cfg, tool_quat)
        _add_wrist_sensor(spec, spec.body("hand_hand"))


def attach_robot(scene: mujoco.MjSpec, cfg: RobotSpec) -> mujoco.MjsFrame:
    """Attach the robot to ``scene`` at its mount pose; names gain the robot's prefix."""
    import mujoco

    arm = cfg.build_spec()
    yaw, roll = np.deg2rad(cfg.mount_yaw_deg), np.deg2rad(cfg.mount_roll_deg)
    quat = np.empty(4)
    mujoco.mju_mulQuat(quat, np.array([np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)]),
                       np.array([np.cos(roll / 2), np.sin(roll / 2), 0, 0]))
    frame = scene.worldbody.add_frame(pos=list(cfg.mount_pos), quat=quat.tolist())
    frame.attach_body(arm.worldbody.first_body(), cfg.prefix, "")
    return frame


def arm_only_model(cfg: RobotSpec) -> mujoco.MjModel:
    """The arm alone at its mount pose (used by the IK: 6 DoF instead of the scene's hundreds)."""
    import mujoco

    world = mujoco.MjSpec()
    attach_robot(world, cfg)
    return world.compile()
