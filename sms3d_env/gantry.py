"""The Cartesian gantry harvester: x/y rails over the bed, a vertical lift and a three-axis wrist
(``assets/gantry.xml``), carrying the same tools as the Jaco.

Most published and commercial mushroom harvesters travel over the shelf on rails (docs/physics.md,
"Harvesters"): a gantry's links stay above the bed, and its wrist axes meet at one point, so the
only singularity (a 90 degree tilt) lies outside the wrist's range. The dimensions, masses, gains
and speeds are ASSUMPTIONs for a small belt-driven gantry, set below.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, ClassVar

from sms3d_env.robot import Tool, add_drives, check_tool_fields, mount_tool
from sms3d_env.robot_registry import register_robot

if TYPE_CHECKING:
    import mujoco

GANTRY_PREFIX = "gantry/"
GANTRY_JOINTS: tuple[str, ...] = ("rail_x", "rail_y", "lift_z", "wrist_roll", "wrist_pitch", "tool_spin")
GANTRY_XML = os.path.join(os.path.dirname(__file__), "assets", "gantry.xml")
_SLIDES = GANTRY_JOINTS[:3]


@register_robot("gantry")
@dataclass(frozen=True)
class GantryConfig:
    """The gantry's drives and tool.

    At ``home_q`` (all zeros) the cup is 20 cm above the patch centre, pointing down, as for the
    Jaco. Every link collides with the soil and the mushrooms.

    Attributes:
        tool, cup_radius, tube_length, finger_*: the tool, as in ``RobotConfig``.
        slide_kp: position gain of the x, y and lift drives (N/m). ASSUMPTION: ~40 ms tracking
            of the ~10 kg the x drive moves, with ``slide_armature``. Every moving body is
            gravity-compensated (``gravcomp``), as the Jaco's links are, so the drives' force
            limits never carry weight.
        slide_force: force limit of the x and y drives (N). ASSUMPTION: a small belt axis.
        lift_force: force limit of the lift (N): what the cup can press a cap with. ASSUMPTION:
            20 N, below the 25 N bruising force, as a force-limited (compliant) z axis. Measured
            why: with the lift at ``slide_force``, driving into the soil at full speed pressed
            46.7 N (the command leads by the slide lead plus a step's motion).
        slide_armature: reflected rotor inertia of each slide (kg). ASSUMPTION.
        wrist_kp, wrist_force: wrist position gain (N m/rad) and torque limit (N m). ASSUMPTION:
            hobby-to-industrial servo class; 6 N m holds the tool at any tilt.
        wrist_armature: reflected rotor inertia of each wrist joint (kg m^2). ASSUMPTION: a
            geared servo (rotor ~1e-6 kg m^2 through ~200:1). Measured why it matters: at
            0.005 the spin's first twist step put 0.024 N m on the seal (capacity 0.02) and 9 of
            10 exact-pose picks lost their grip; at 0.05, 10 of 10 picked.
        (The controller's speed and lead limits on the slides: ``ControllerConfig``.)
    """

    name: ClassVar[str] = "gantry"
    prefix: ClassVar[str] = GANTRY_PREFIX
    joints: ClassVar[tuple[str, ...]] = GANTRY_JOINTS
    # Straight Cartesian approaches: the wrist's only singularity (90 deg tilt) is out of its range.
    approach: ClassVar[str] = "cartesian"

    mount_pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mount_yaw_deg: float = 0.0
    mount_roll_deg: float = 0.0
    tool: Tool = "suction"
    cup_radius: float = 0.010
    tube_length: float = 0.09
    slide_kp: float = 6000.0
    slide_force: float = 150.0
    lift_force: float = 20.0
    slide_armature: float = 1.0
    wrist_kp: float = 60.0
    wrist_force: float = 6.0
    wrist_armature: float = 0.05
    finger_kp: float = 2.0
    finger_force: float = 0.25
    finger_damping: float = 0.1
    finger_armature: float = 0.001
    home_q: tuple[float, ...] = field(default=(0.0,) * 6)

    def __post_init__(self) -> None:
        check_tool_fields(self)
        if len(self.home_q) != len(self.joints):
            raise ValueError(f"{type(self).__name__}.home_q must have {len(self.joints)} entries, got {len(self.home_q)}")
        for name in ("slide_kp", "slide_force", "lift_force", "slide_armature", "wrist_kp", "wrist_force",
                     "wrist_armature"):
            value = getattr(self, name)
            if not value > 0:
                raise ValueError(f"{type(self).__name__}.{name} must be > 0, got {value!r}")

    def build_spec(self) -> mujoco.MjSpec:
        import mujoco

        spec = mujoco.MjSpec.from_file(GANTRY_XML)
        drives = []
        for jname in GANTRY_JOINTS:
            slide = jname in _SLIDES
            spec.joint(jname).armature = self.slide_armature if slide else self.wrist_armature
            limit = self.lift_force if jname == "lift_z" else self.slide_force if slide else self.wrist_force
            drives.append((jname, self.slide_kp if slide else self.wrist_kp, limit))
        # Everything that moves (world and the static frame aside) is gravity-compensated.
        add_drives(spec, [b.name for b in spec.bodies[2:]], drives)
        mount_tool(spec, spec.body("flange"), self, (1.0, 0.0, 0.0, 0.0))
        return spec
