"""The world of one episode: the scene and the robot assembled into one MuJoCo model, its data,
and the id tables the picking model and the env read (dm_control's entities, apart from the task).

``build_world(scene, target, ...)`` returns a ``World``. Only mushrooms within ``free_radius`` of
the target keep a free joint and a root weld; with the suction tool each of them also gets an
inactive grip weld to the cup; the floor of its hole in the casing (``add_stem_sockets``; with
the suction tool, ``stem_in_casing``) holds it up once detached, until it is lifted out. Contact
masks (physics.py's bits) are set here once; the picking model changes them as mushrooms detach
and lift. The ``pick`` camera is aimed at the target
(``aim_pick_camera``).
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from sms3d_env import physics as ph
from sms3d_env.robot import (
    CUP_BODY,
    CUP_GEOM,
    TOOL_SITE,
    WRIST_FORCE,
    WRIST_TORQUE,
    RobotSpec,
    attach_robot,
)

_STATE = int(mujoco.mjtState.mjSTATE_INTEGRATION)

#: The camera of ``render()`` by default: aimed at each episode's target by ``aim_pick_camera``.
PICK_CAMERA = "pick"
#: Every camera of the world: the scene's ``overhead`` (the perception camera), a fixed ``side``
#: view of the bed's centre, and ``pick``.
CAMERAS = ("overhead", "side", PICK_CAMERA)
# The pick camera's view (chosen by looking at both robots' picks): 30 cm from a point 3 cm above
# the target's cap top (the cup above the cap stays in the picture), 25 deg above the horizon.
PICK_CAMERA_FOVY_DEG = 45.0
PICK_CAMERA_DISTANCE = 0.30
PICK_CAMERA_ELEVATION_DEG = 25.0
PICK_CAMERA_LOOK_ABOVE = 0.03


@dataclass
class World:
    """Model, data and ids of one episode's world (n mushrooms; arrays indexed by mushroom id
    unless named per geom or per equality).

    Attributes:
        model, data: MuJoCo model and data.
        scene: the ``generator.Scene``.
        tool: ``"suction"`` or ``"hand"``.
        prefix: the robot's name prefix (``"jaco/"``, ``"gantry/"``).
        is_free (n,), free_ids: mushrooms with a free joint (the others are static bodies).
        body_ids, cap_geoms, stem_geoms, cap_top_sites (n,): MuJoCo ids.
        dofadr, root_eq, grip_eq (n,): free-joint dof address, root weld, grip weld (-1 if none).
        is_root_eq (neq,), geom_mushroom (ngeom,: mushroom id or -1), is_cap, robot_geom (ngeom,).
        cup_geom, cup_body: suction cup ids (-1 with the hand).
        tool_site, terrain_geom: site and geom ids.
        arm_qadr, arm_dadr (n,): the robot joints' qpos / dof addresses (``robot.joints``' order).
        wrench_adr (6,): sensordata addresses of the wrist force (3, N) and torque (3, N m).
        cap_radius (n,): m.
        free_aff, lifted_aff: conaffinity of detached mushrooms before and after they clear the
            soil (the holes in the casing add a bit).
        cup_mask: the cup face's (contype, conaffinity) when not sealed.
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    scene: Any
    tool: str
    prefix: str
    is_free: np.ndarray
    free_ids: np.ndarray
    body_ids: np.ndarray
    cap_geoms: np.ndarray
    stem_geoms: np.ndarray
    cap_top_sites: np.ndarray
    dofadr: np.ndarray
    root_eq: np.ndarray
    grip_eq: np.ndarray
    is_root_eq: np.ndarray
    geom_mushroom: np.ndarray
    is_cap: np.ndarray
    robot_geom: np.ndarray
    cup_geom: int
    cup_body: int
    tool_site: int
    terrain_geom: int
    arm_qadr: np.ndarray
    arm_dadr: np.ndarray
    wrench_adr: np.ndarray
    cap_radius: np.ndarray
    free_aff: int
    lifted_aff: int
    cup_mask: tuple[int, int]

    def __getstate__(self) -> dict[str, Any]:
        # A sleeping island's latent state does not pickle (MuJoCo keeps it only through
        # mj_copyData): carry the integration state; the copy wakes every tree.
        state = self.__dict__.copy()
        flat = np.empty(mujoco.mj_stateSize(self.model, _STATE))
        mujoco.mj_getState(self.model, self.data, flat, _STATE)
        state["data"] = flat
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.data = mujoco.MjData(self.model)
        mujoco.mj_setState(self.model, self.data, state["data"], _STATE)
        mujoco.mj_forward(self.model, self.data)


def free_set(scene: Any, target: int, free_radius: float | None) -> set[int]:
    """Mushrooms whose stem base lies within ``free_radius`` (m) of the target's, and the target
    (every mushroom if None)."""
    n = len(scene.instances)
    if free_radius is None:
        return set(range(n))
    base = np.array([np.asarray(inst.position, float) for inst in scene.instances])
    near = np.linalg.norm(base - base[target], axis=1) <= free_radius
    return {int(i) for i in np.nonzero(near)[0]} | {int(target)}


def add_stem_sockets(spec: mujoco.MjSpec, scene: Any, ids: Iterable[int], drop: float = 0.001) -> None:
    """A thin static box ``drop`` below the lowest point of each listed mushroom's stem, felt
    only by detached mushrooms (``physics.SOCKET_CONTYPE``): the floor of the hole in the casing
    around the stem base, which holds a released mushroom up until it is lifted out of it (the
    soil's own contacts wait until its stem is clear of the soil: ``PickingModel.after_step``)."""
    for i in ids:
        inst = scene.instances[i]
        local = np.asarray(inst.model.stem_mesh.vertices) * inst.scale_vector
        world = local @ np.asarray(inst.rotation).T + inst.position
        half = float(np.hypot(local[:, 0], local[:, 1]).max()) + 0.002
        spec.worldbody.add_geom(
            name=f"socket_{i}", type=mujoco.mjtGeom.mjGEOM_BOX, size=[half, half, 0.002],
            pos=[inst.position[0], inst.position[1], world[:, 2].min() - drop - 0.002],
            contype=ph.SOCKET_CONTYPE, conaffinity=0, group=4, rgba=[0.4, 0.3, 0.2, 0])


def aim_pick_camera(model: mujoco.MjModel, cap_top: np.ndarray, mount_pos: Sequence[float]) -> None:
    """Place ``PICK_CAMERA`` in ``model`` (its ``cam_pos`` and ``cam_quat``) beyond the target as
    seen from the robot's mount, looking back at the target's cap top (m, world frame): the robot
    reaches in behind the target instead of between the camera and the target (a Jaco hanging
    beside the bed blocks views from its own side). A target within 2 cm of the mount's foot
    (the gantry's frame origin is the bed's centre) is seen from -y, as the ``side`` camera."""
    lookat = np.asarray(cap_top, float) + [0.0, 0.0, PICK_CAMERA_LOOK_ABOVE]
    outward = lookat[:2] - np.asarray(mount_pos[:2], float)
    norm = np.linalg.norm(outward)
    outward = outward / norm if norm > 0.02 else np.array([0.0, -1.0])
    elevation = np.radians(PICK_CAMERA_ELEVATION_DEG)
    eye = lookat + PICK_CAMERA_DISTANCE * np.r_[np.cos(elevation) * outward, np.sin(elevation)]
    forward = (lookat - eye) / PICK_CAMERA_DISTANCE
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    back = -forward  # a MuJoCo camera looks along its -z, with +y up in the picture
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([right, np.cross(back, right), back]).ravel())
    cam = model.camera(PICK_CAMERA).id
    model.cam_pos[cam], model.cam_quat[cam] = eye, quat


def world_spec(scene: Any, free: set[int], robot: RobotSpec, timestep: float,
               compliant_root: bool = False, stem_in_casing: bool = False) -> mujoco.MjSpec:
    """The scene + robot ``MjSpec`` (grip welds or stem sockets per free mushroom, cameras).
    ``compliant_root``: each root is a ball constraint at the stem base (``connect``) instead of
    a weld, its bending and twist left to :mod:`sms3d_env.roots`' springs, gravity compensated
    while rooted; ``stem_in_casing``: the floor of every free mushroom's hole in the casing
    (``add_stem_sockets``) whatever the tool (else the hand's alone)."""
    from generator.mjcf import scene_to_spec

    spec = scene_to_spec(scene, free_ids=free)
    if compliant_root:
        for i in free:
            root = spec.equality(f"mushroom_{i}_root")
            root.type = mujoco.mjtEq.mjEQ_CONNECT
            root.data[:] = 0.0  # the anchor: body1's (the mushroom's) origin, its stem base
            spec.body(f"mushroom_{i}").gravcomp = 1.0
    attach_robot(spec, robot)
    if robot.tool != "suction" or stem_in_casing:
        add_stem_sockets(spec, scene, sorted(free))
    if robot.tool == "suction":
        for i in sorted(free):
            spec.add_equality(name=f"grip_{i}", type=mujoco.mjtEq.mjEQ_WELD,
                              objtype=mujoco.mjtObj.mjOBJ_BODY, name1=robot.prefix + CUP_BODY,
                              name2=f"mushroom_{i}", active=False)
    else:
        # Friction grasps creep out of MuJoCo's default pyramidal cone (impratio 1): lifted
        # mushrooms slid out of the closed fingers. The elliptic cone with impratio 10 (MuJoCo's
        # remedy for slip) keeps them (9 of 40 picked with the pyramidal cone, 26 grips lost;
        # docs/results-environment.md). Hand only: the suction model
        # stays as its accuracy study measured it.
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        spec.option.impratio = 10.0
    spec.worldbody.add_camera(name="side", pos=[0.0, -0.42, 0.28],
                              xyaxes=[1, 0, 0, 0, 0.6, 0.8], fovy=50)
    spec.worldbody.add_camera(name=PICK_CAMERA, fovy=PICK_CAMERA_FOVY_DEG)  # aimed per episode
    spec.option.timestep = timestep
    # Sleeping islands: rooted mushrooms at rest drop out of the pipeline (constraint rows
    # 48 -> 6 in a 50-mushroom scene, mj_step ~2x faster) and wake, exactly as MuJoCo
    # documents, when the tool touches them or a grip weld joins them to the awake arm (an
    # actuated tree, which never sleeps). The scripted picker's episodes came out the same.
    spec.option.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    return spec


def build_world(scene: Any, target: int, robot: RobotSpec, free_radius: float | None,
                timestep: float, cache: dict[Any, mujoco.MjModel] | None = None,
                cache_key: Any = None, mushrooms_collide: bool = False, compliant_root: bool = False,
                stem_in_casing: bool = False) -> World:
    """Assemble the world; with ``cache`` and ``cache_key``, the compiled model is kept there
    and copied (3 ms against 45 ms for a compile), as an episode changes its model (contact
    masks, weld data). ``mushrooms_collide``: every mushroom also collides with every other
    (``ValueError`` naming the pair when two of the bed's collision hulls interpenetrate at
    rest by more than ``physics.MAX_REST_PENETRATION``); ``compliant_root``, ``stem_in_casing``:
    see ``world_spec``."""
    n = len(scene.instances)
    free = free_set(scene, target, free_radius)
    suction = robot.tool == "suction"
    compiled = cache is None or cache_key is None or cache_key not in cache
    if cache is not None and cache_key is not None:
        if compiled:
            cache[cache_key] = world_spec(scene, free, robot, timestep, compliant_root, stem_in_casing).compile()
        m = copy.copy(cache[cache_key])
    else:
        m = world_spec(scene, free, robot, timestep, compliant_root, stem_in_casing).compile()
    aim_pick_camera(m, scene.instances[target].cap_top, robot.mount_pos)
    d = mujoco.MjData(m)
    is_free = np.array([i in free for i in range(n)])
    terrain = m.geom("terrain").id
    m.geom_contype[terrain], m.geom_conaffinity[terrain] = ph.SOIL_CONTYPE, ph.SOIL_CONAFFINITY
    body_ids = np.array([m.body(f"mushroom_{i}").id for i in range(n)])
    cap_geoms = np.array([m.geom(f"mushroom_{i}_cap").id for i in range(n)])
    stem_geoms = np.array([m.geom(f"mushroom_{i}_stem").id for i in range(n)])
    root_eq = np.array([m.equality(f"mushroom_{i}_root").id if i in free else -1 for i in range(n)])
    is_root_eq = np.zeros(m.neq, bool)
    is_root_eq[root_eq[root_eq >= 0]] = True
    geom_mushroom = np.full(m.ngeom, -1)
    geom_mushroom[cap_geoms] = np.arange(n)
    geom_mushroom[stem_geoms] = np.arange(n)
    is_cap = np.zeros(m.ngeom, bool)
    is_cap[cap_geoms] = True
    # Free mushrooms touch the robot. Static ones (beyond ``free_radius``) collide with
    # nothing: out of the broadphase, ~25 % off each physics step (50 mushrooms). KNOWN
    # SIMPLIFICATION: the tool passes through mushrooms more than free_radius from the target.
    free_mask = is_free.astype(int)
    each_other = ph.MUSHROOM_CONTACT if mushrooms_collide else 0
    for g in np.concatenate([cap_geoms, stem_geoms]):
        f = free_mask[geom_mushroom[g]]
        m.geom_contype[g] = ph.ROOTED_CONTYPE * f
        m.geom_conaffinity[g] = (ph.ROOTED_CONAFFINITY | each_other) * f
    # The broadphase prunes with per-body unions of the geom masks: keep them in step.
    m.body_contype[body_ids] = ph.ROOTED_CONTYPE * free_mask
    m.body_conaffinity[body_ids] = (ph.ROOTED_CONAFFINITY | each_other) * free_mask
    m.body_contype[0] |= ph.SOIL_CONTYPE
    m.body_conaffinity[0] |= ph.SOIL_CONAFFINITY
    robot_geom = np.zeros(m.ngeom, bool)
    prefix = robot.prefix
    robot_geom[[g for g in range(m.ngeom) if m.geom(g).name.startswith(prefix)]] = True
    cup_geom = m.geom(prefix + CUP_GEOM).id if suction else -1  # -1: the seal test never fires
    force, torque = m.sensor(prefix + WRIST_FORCE), m.sensor(prefix + WRIST_TORQUE)
    socket = ph.SOCKET_CONAFFINITY if stem_in_casing or not suction else 0

    if mushrooms_collide and compiled:  # a cached model's bed passed when it was compiled
        overlaps = interpenetrating_mushrooms(m, geom_mushroom)
        if overlaps:
            if cache is not None:
                cache.pop(cache_key, None)  # refused again at its next draw, not passed as checked
            (i, j), depth = overlaps[0]
            raise ValueError(f"the bed's mushrooms {i} and {j} interpenetrate by {depth * 1000:.1f} mm at rest "
                             f"({len(overlaps)} pairs deeper than {ph.MAX_REST_PENETRATION * 1000:g} mm): with "
                             "PickPhysicsParams.mushrooms_collide every mushroom collides with every other, so the "
                             "bed must not interpenetrate; generate it with placement.overlap_iou = 0 and "
                             "placement.overlap_solids = 'hulls'")
    return World(
        model=m, data=d, scene=scene, tool=robot.tool, prefix=prefix, is_free=is_free,
        free_ids=np.array(sorted(free)), body_ids=body_ids, cap_geoms=cap_geoms,
        stem_geoms=stem_geoms,
        cap_top_sites=np.array([m.site(f"mushroom_{i}_cap_top").id for i in range(n)]),
        dofadr=np.array([m.jnt_dofadr[m.joint(f"mushroom_{i}_joint").id] if i in free else -1
                         for i in range(n)]),
        root_eq=root_eq,
        grip_eq=np.array([m.equality(f"grip_{i}").id if suction and i in free else -1 for i in range(n)]),
        is_root_eq=is_root_eq, geom_mushroom=geom_mushroom, is_cap=is_cap, robot_geom=robot_geom,
        cup_geom=cup_geom, cup_body=m.body(prefix + CUP_BODY).id if suction else -1,
        tool_site=m.site(prefix + TOOL_SITE).id, terrain_geom=terrain,
        arm_qadr=np.array([m.jnt_qposadr[m.joint(prefix + j).id] for j in robot.joints]),
        arm_dadr=np.array([m.jnt_dofadr[m.joint(prefix + j).id] for j in robot.joints]),
        wrench_adr=np.r_[force.adr[0]:force.adr[0] + 3, torque.adr[0]:torque.adr[0] + 3],
        cap_radius=np.array([inst.cap_diameter / 2 for inst in scene.instances]),
        free_aff=ph.FREE_CONAFFINITY | socket | each_other, lifted_aff=ph.LIFTED_CONAFFINITY | socket | each_other,
        cup_mask=(int(m.geom_contype[cup_geom]), int(m.geom_conaffinity[cup_geom])) if suction else (0, 0),
    )


def interpenetrating_mushrooms(model: mujoco.MjModel, geom_mushroom: np.ndarray,
                               tolerance: float = ph.MAX_REST_PENETRATION) -> list[tuple[tuple[int, int], float]]:
    """Pairs of mushrooms whose collision hulls interpenetrate by more than ``tolerance`` (m) in
    ``model``'s rest pose, deepest first, with their depth: collision detection on a scratch
    copy with sleeping off (a sleeping island's bodies are not collided)."""
    scratch = copy.copy(model)
    scratch.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    data = mujoco.MjData(scratch)
    mujoco.mj_forward(scratch, data)
    depth: dict[tuple[int, int], float] = {}
    for c in range(data.ncon):
        i, j = (int(geom_mushroom[g]) for g in data.contact.geom[c])
        if i >= 0 and j >= 0 and i != j and -data.contact.dist[c] > tolerance:
            key = (min(i, j), max(i, j))
            depth[key] = max(depth.get(key, 0.0), float(-data.contact.dist[c]))
    return sorted(depth.items(), key=lambda item: -item[1])
