"""``SMS3DPick-v0``: pick one mushroom from a synthetic bed with a Kinova Jaco, by a suction
tool (default) or the Jaco 3-finger hand.

Per reset: a seeded scene (or one from a list) becomes an ``MjSpec``; the arm is attached (with
the suction tool: one inactive grip weld per free mushroom), and the target is chosen. Per step:
the normalised action becomes a tool twist, mink turns it into joint targets, and ``substeps``
physics steps run with the picking model of ``physics.py`` checked after each.
"""

from __future__ import annotations

import copy
import math
import os
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from generator.gl import open_renderer
from sms3d_env import physics as ph
from sms3d_env.controller import ControllerConfig, IKController
from sms3d_env.hand import HandGrasp, add_stem_sockets
from sms3d_env.physics import PickPhysicsParams
from sms3d_env.pose_source import PoseEstimate, PoseSource, make_pose_source
from sms3d_env.rewards import REWARD_TYPES, RewardState, compute_reward, reward_terms
from sms3d_env.robot import (
    ARM_JOINTS,
    CUP_BODY,
    CUP_GEOM,
    PREFIX,
    TOOL_SITE,
    TOOLS,
    WRIST_FORCE,
    WRIST_TORQUE,
    RobotConfig,
    attach_robot,
)
from sms3d_env.targets import RULES, Reachability, select_target
from sms3d_env.task_obs import TASK_OBS_SIZES, tool_in_target, twist_about

FAILURE_CAUSES = ("no_seal", "grip_lost", "not_detached", "bruised", "neighbour_disturbed",
                  "unreachable", "timeout", "unstable_simulation")
_EQ = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)
_BADQACC = int(mujoco.mjtWarning.mjWARN_BADQACC)
_STATE = int(mujoco.mjtState.mjSTATE_INTEGRATION)
# State observation entries and their sizes, in the order of the flat vector they are cut from.
_OBS_SIZES = {"joint_pos": 6, "joint_vel": 6, "tool_pose": 7, "suction": 3, "target_pose": 6,
              "target_rel": 3}
SUCTION_MODES = ("momentary", "latched")


def _slices(sizes: dict[str, int]) -> dict[str, slice]:
    ends = np.cumsum(list(sizes.values())).tolist()
    return {k: slice(end - n, end) for (k, n), end in zip(sizes.items(), ends, strict=True)}


def _check_args(pose_source: Any, pose_error_deg: Any, position_noise: Any, target_rule: Any,
                image_size: Any, render_size: Any, max_tilt_deg: Any, free_radius: Any,
                scene_config: Any) -> None:
    """Refuse arguments the env could not honour or would silently ignore (ValueError/TypeError
    naming the argument)."""
    for name, v in (("pose_error_deg", pose_error_deg), ("position_noise", position_noise)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")
    if pose_source != "noisy" and (pose_error_deg or position_noise):
        raise ValueError(f"pose_error_deg and position_noise apply to pose_source='noisy' only; with "
                         f"pose_source={pose_source!r} they would be ignored (got pose_error_deg="
                         f"{pose_error_deg!r}, position_noise={position_noise!r})")
    if target_rule not in RULES:
        raise ValueError(f"target_rule must be one of {RULES}, got {target_rule!r}")
    for name, size in (("image_size", image_size), ("render_size", render_size)):
        ok = (isinstance(size, (tuple, list)) and len(size) == 2
              and all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1 for n in size))
        if not ok:
            raise ValueError(f"{name} must be two integers >= 1 (height, width), got {size!r}")
    if isinstance(max_tilt_deg, bool) or not isinstance(max_tilt_deg, (int, float)) \
            or not (math.isfinite(max_tilt_deg) and 0 <= max_tilt_deg <= 90):
        raise ValueError(f"max_tilt_deg must be a finite number in [0, 90], got {max_tilt_deg!r}")
    if free_radius is not None and (isinstance(free_radius, bool) or not isinstance(free_radius, (int, float))
                                    or not (math.isfinite(free_radius) and free_radius > 0)):
        raise ValueError(f"free_radius must be None or a finite number > 0 (m), got {free_radius!r}")
    if scene_config is not None:
        from generator.config import SceneConfig

        if not isinstance(scene_config, SceneConfig):
            raise TypeError(f"scene_config must be a generator.SceneConfig or None, got "
                            f"{type(scene_config).__name__} {scene_config!r}")


@dataclass
class _EpisodeState:
    target: int = 0
    reachable: bool = True
    estimate: PoseEstimate | None = None
    target_pose: np.ndarray = field(default_factory=lambda: np.zeros(6))  # estimate: cap top, axis
    grip: int = -1  # mushroom id held (sealed by the cup, or pinched by the fingers), -1 if none
    grip_util: float = 0.0  # suction: seal load as a fraction of its capacity
    finger_force: float = 0.0  # hand: finger normal force on the target (N)
    tool_on: bool = False  # suction on, or hand commanded more closed than half
    ever_gripped_target: bool = False
    held_detached: bool = False  # hand: the target was held after its detachment
    finger_touch_step: int = -1  # hand: last env step in which a finger touched the target
    target_detached: bool = False
    grip_lost: bool = False
    bruised: set[int] = field(default_factory=set)
    detached: set[int] = field(default_factory=set)
    disturbed: set[int] = field(default_factory=set)
    unstable: bool = False
    max_lift: float = 0.0
    root_util: float = 0.0  # target root load / capacity in the last physics step (reward only)
    seal_step: int = -1  # env step at which the current seal formed (-1: none)
    seal_tool_x: np.ndarray | None = None  # tool x axis (world) when it formed
    done: bool = False  # the episode terminated or was truncated


class SMS3DPickEnv(gym.Env):
    """Gymnasium environment for picking one target mushroom with a suction cup or a hand.

    Action: tool twist (3 linear, 3 angular, normalised) and a tool command: suction on if > 0;
    for the hand, the fingers' position target from -1 (open) to +1 (closed). Observation
    ``suction``: suction (on, sealed, seal load / capacity); hand (measured closure 0-1, holding
    the target or another mushroom with at least two fingers, finger normal force on the target
    in N). The hand grips by contact friction only; success needs the target detached, lifted and
    held with the hand closed (command > 0). ``failure_cause`` ``"no_seal"`` then means that the
    hand never held the target.

    Args:
        render_mode: ``"rgb_array"`` or ``"depth_array"`` (metric depth in metres).
        scene_config: ``generator.SceneConfig`` for a new seeded scene per reset (default: 25
            mushrooms). Ignored when ``scenes`` is given.
        scenes: a fixed list of ``generator.Scene`` objects, or the folder of a ``sms3d generate``
            dataset; one is drawn per reset (``options={"scene": k}`` picks one).
        pose_source: ``"oracle"``, ``"noisy"`` or a callable ``(scene, id, rng) -> PoseEstimate``.
        pose_error_deg, position_noise: the ``"noisy"`` source's rotation error (deg) and
            position noise standard deviation (m).
        target_rule: ``"tallest"``, ``"largest"``, ``"index"`` (with ``target_index``),
            ``"random"``; ``options={"target": i}`` overrides it for one reset.
        free_radius: only mushrooms whose stem base lies within this distance (m) of the
            target's keep a free joint and a root weld (they can be disturbed or detached); the
            others are static bodies, which makes the simulation several times faster. ``None``:
            every mushroom is free.
        reward_type: ``"dense"`` or ``"sparse"``.
        tool: ``"suction"`` or ``"hand"``; overrides ``robot.tool`` (default: ``"suction"``).
        control_dt, substeps: control period (s) and physics steps per control step.
        image_obs: add ``rgb`` (uint8) and ``depth`` (float32, m) of ``image_size`` to the
            observation, from ``camera``.
        suction_mode: ``"momentary"`` (default: any command <= 0 releases the seal) or
            ``"latched"`` (the vacuum valve holds its state: once a seal forms it stays on
            whatever the command, as a picker's valve does after its vacuum switch trips).
        end_on_dead_end: also terminate (as a failure) when the episode can no longer succeed:
            the target detached but not held, or (latched suction) a seal on another mushroom.
        task_obs: add the entries of :mod:`sms3d_env.task_obs`: ``tool_in_target`` (tool offset
            and axis in the *estimated* target frame, their angle), ``progress`` (time since
            reset and since the seal, twist since the seal) and ``wrist_wrench`` (wrist F/T).
        horizon: control steps per episode that the staged reward's success bonus assumes (the
            registered time limit, 250).
        scene_pool: > 0: draw each reset's bed from a pool of this many ``scene_config`` beds
            (seeds ``pool_seed .. pool_seed + scene_pool - 1``, each generated on first use and
            kept) instead of generating a new one: training resets cost physics, not placement.
            Combine with ``target_rule="random"`` for a fresh target per reset.

    Training options (``SMS3DPickTrain-v0`` sets them all: ``suction_mode="latched"``,
    ``reward_type="staged"``, ``end_on_dead_end=True``, ``task_obs=True``): see
    ``sms3d_env.rewards.reward_terms`` for the staged reward's table. Its terms are reported in
    ``info`` as ``reward_stage``, ``reward_progress`` and ``reward_success_bonus``.
    """

    metadata = {"render_modes": ["rgb_array", "depth_array"], "render_fps": 25}

    def __init__(
        self,
        render_mode: str | None = None,
        scene_config: Any = None,
        scenes: Sequence[Any] | None = None,
        pose_source: str | PoseSource = "oracle",
        pose_error_deg: float = 0.0,
        position_noise: float = 0.0,
        target_rule: str = "tallest",
        target_index: int = 0,
        reward_type: str = "dense",
        physics: PickPhysicsParams | None = None,
        robot: RobotConfig | None = None,
        controller: ControllerConfig | None = None,
        control_dt: float = 0.04,
        substeps: int = 20,
        image_obs: bool = False,
        image_size: tuple[int, int] = (64, 64),
        camera: str = "overhead",
        render_size: tuple[int, int] = (480, 640),
        max_tilt_deg: float = 45.0,
        free_radius: float | None = 0.10,
        tool: str | None = None,
        suction_mode: str = "momentary",
        end_on_dead_end: bool = False,
        task_obs: bool = False,
        horizon: int = 250,
        scene_pool: int = 0,
        pool_seed: int = 0,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        if reward_type not in REWARD_TYPES:
            raise ValueError(f"reward_type must be one of {REWARD_TYPES}, got {reward_type!r}")
        if not (np.isfinite(control_dt) and control_dt > 0):
            raise ValueError(f"control_dt must be > 0, got {control_dt!r}")
        if not isinstance(substeps, int) or substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1, got {substeps!r}")
        if tool is not None and tool not in TOOLS:
            raise ValueError(f"tool must be one of {TOOLS}, got {tool!r}")
        if suction_mode not in SUCTION_MODES:
            raise ValueError(f"suction_mode must be one of {SUCTION_MODES}, got {suction_mode!r}")
        if isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
            raise ValueError(f"horizon must be an integer >= 1, got {horizon!r}")
        for name, v in (("scene_pool", scene_pool), ("pool_seed", pool_seed)):
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {v!r}")
        if scene_pool and scenes is not None:
            raise ValueError("scene_pool draws generated beds; with scenes given it would be ignored")
        _check_args(pose_source, pose_error_deg, position_noise, target_rule, image_size,
                    render_size, max_tilt_deg, free_radius, scene_config)
        self.robot_cfg = robot or RobotConfig()
        if tool is not None:
            self.robot_cfg = replace(self.robot_cfg, tool=tool)
        self.tool = self.robot_cfg.tool
        if self.tool != "suction" and suction_mode != "momentary":
            raise ValueError(f"suction_mode={suction_mode!r} applies to the suction tool only (tool={self.tool!r})")
        if scenes is not None and len(scenes) == 0:
            raise ValueError("scenes must be a non-empty sequence")
        self.render_mode = render_mode
        self.scene_config = scene_config
        if isinstance(scenes, (str, os.PathLike)):
            from generator.dataset.readers import load_scenes

            scenes = load_scenes(scenes)
            if not scenes:
                raise ValueError("scenes: the dataset folder holds no complete scene")
        self.scenes = list(scenes) if scenes is not None else None
        self.pose_source = make_pose_source(pose_source, pose_error_deg, position_noise)
        self.target_rule, self.target_index = target_rule, target_index
        self.reward_type = reward_type
        self.params = physics or PickPhysicsParams(cup_radius=self.robot_cfg.cup_radius)
        self.ctrl_cfg = controller or ControllerConfig()
        self.control_dt, self.substeps = float(control_dt), substeps
        self.image_obs, self.image_size = image_obs, tuple(image_size)
        self.camera, self.render_size = camera, tuple(render_size)
        self.max_tilt_deg = max_tilt_deg
        self.free_radius = free_radius
        self.suction_mode, self.end_on_dead_end = suction_mode, bool(end_on_dead_end)
        self.task_obs, self.horizon = bool(task_obs), horizon
        self.scene_pool, self.pool_seed = scene_pool, pool_seed
        self._pool: dict[int, Any] = {}
        self._pool_models: dict[tuple[int, int], mujoco.MjModel] = {}

        self.ik = IKController(self.robot_cfg, self.ctrl_cfg, self.control_dt)
        self.home_q = np.asarray(self.robot_cfg.home_q, float)
        self.reach = Reachability(self.ik.model, self.ik.arm_qadr, self.home_q)
        self.action_space = spaces.Box(-1.0, 1.0, (7,), np.float32)
        self._twist_scale = np.repeat([self.ctrl_cfg.max_linear_speed, self.ctrl_cfg.max_angular_speed], 3)
        inf = np.inf
        self._obs_sizes = {**_OBS_SIZES, **(TASK_OBS_SIZES if self.task_obs else {})}
        self._obs_slices = _slices(self._obs_sizes)
        obs = {k: spaces.Box(-inf, inf, (n,), np.float64) for k, n in self._obs_sizes.items()}
        if image_obs:
            h, w = self.image_size
            obs["rgb"] = spaces.Box(0, 255, (h, w, 3), np.uint8)
            obs["depth"] = spaces.Box(0.0, inf, (h, w, 1), np.float32)
        self.observation_space = spaces.Dict(obs)
        self.model: mujoco.MjModel | None = None
        self.hand: HandGrasp | None = None
        self.data: mujoco.MjData | None = None
        self.scene: Any = None
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._ep = _EpisodeState()

    # ------------------------------------------------------------------ model assembly
    def _scene_for_reset(self, options: dict[str, Any]) -> tuple[Any, int | None]:
        """The reset's scene, and its pool slot (None outside a pool)."""
        if self.scenes is not None:
            k = options.get("scene")
            k = int(self.np_random.integers(len(self.scenes))) if k is None else int(k)
            return self.scenes[k], None
        import generator

        cfg = self.scene_config
        if cfg is None:
            cfg = generator.SceneConfig().replace(placement__num_mushrooms=25)
        if not self.scene_pool:
            return generator.generate_scene(cfg, seed=int(self.np_random.integers(2**31 - 1))), None
        k = int(self.np_random.integers(self.scene_pool))
        if k not in self._pool:
            self._pool[k] = generator.generate_scene(cfg, seed=self.pool_seed + k)
        return self._pool[k], k

    def _compile(self, scene: Any, free: set[int], pool_key: tuple[int, int] | None) -> mujoco.MjModel:
        """The scene + robot model; in a pool, compiled once per (bed, target) and copied (3 ms
        against 45 ms), as the episode changes the model (contact masks, weld data)."""
        cached = self._pool_models.get(pool_key) if pool_key is not None else None
        if cached is None:
            cached = self._spec(scene, free).compile()
            if pool_key is not None:
                self._pool_models[pool_key] = cached
        return copy.copy(cached) if pool_key is not None else cached

    def _spec(self, scene: Any, free: set[int]) -> mujoco.MjSpec:
        from generator.mjcf import scene_to_spec

        spec = scene_to_spec(scene, free_ids=free)
        attach_robot(spec, self.robot_cfg)
        suction = self.tool == "suction"
        if suction:
            for i in sorted(free):
                spec.add_equality(name=f"grip_{i}", type=mujoco.mjtEq.mjEQ_WELD,
                                  objtype=mujoco.mjtObj.mjOBJ_BODY, name1=PREFIX + CUP_BODY,
                                  name2=f"mushroom_{i}", active=False)
        else:
            add_stem_sockets(spec, scene, sorted(free))
            # Friction grasps creep out of MuJoCo's default pyramidal cone (impratio 1): lifted
            # mushrooms slid out of the closed fingers. The elliptic cone with impratio 10 (MuJoCo's
            # remedy for slip) keeps them (benchmarks/RESULTS.md). Hand only: the suction model
            # stays as its accuracy study measured it.
            spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
            spec.option.impratio = 10.0
        spec.worldbody.add_camera(name="side", pos=[0.0, -0.42, 0.28],
                                  xyaxes=[1, 0, 0, 0, 0.6, 0.8], fovy=50)
        spec.option.timestep = self.control_dt / self.substeps
        # Sleeping islands: rooted mushrooms at rest drop out of the pipeline (constraint rows
        # 48 -> 6 in a 50-mushroom scene, mj_step ~2x faster) and wake, exactly as MuJoCo
        # documents, when the tool touches them or a grip weld joins them to the awake arm (an
        # actuated tree, which never sleeps). Same picker outcomes (benchmarks/RESULTS.md).
        spec.option.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
        return spec

    def _build(self, scene: Any, target: int, pool_key: tuple[int, int] | None = None) -> None:
        n = len(scene.instances)
        base = np.array([np.asarray(inst.position, float) for inst in scene.instances])
        if self.free_radius is None:
            free = set(range(n))
        else:
            near = np.linalg.norm(base - base[target], axis=1) <= self.free_radius
            free = {int(i) for i in np.nonzero(near)[0]} | {int(target)}
        self.is_free = np.array([i in free for i in range(n)])
        self.free_ids = np.array(sorted(free))
        suction = self.tool == "suction"
        socket = 0 if suction else ph.SOCKET_CONAFFINITY
        self._free_aff, self._lifted_aff = ph.FREE_CONAFFINITY | socket, ph.LIFTED_CONAFFINITY | socket
        self._disown_renderers()
        m = self._compile(scene, free, pool_key)
        d = mujoco.MjData(m)
        terrain = self.terrain_geom = m.geom("terrain").id
        m.geom_contype[terrain], m.geom_conaffinity[terrain] = ph.SOIL_CONTYPE, ph.SOIL_CONAFFINITY
        self.body_ids = np.array([m.body(f"mushroom_{i}").id for i in range(n)])
        self.dofadr = np.array([m.jnt_dofadr[m.joint(f"mushroom_{i}_joint").id] if i in free else -1
                                for i in range(n)])
        self.cap_geoms = np.array([m.geom(f"mushroom_{i}_cap").id for i in range(n)])
        self.stem_geoms = np.array([m.geom(f"mushroom_{i}_stem").id for i in range(n)])
        self.cap_top_sites = np.array([m.site(f"mushroom_{i}_cap_top").id for i in range(n)])
        self.root_eq = np.array([m.equality(f"mushroom_{i}_root").id if i in free else -1
                                 for i in range(n)])
        self.grip_eq = np.array([m.equality(f"grip_{i}").id if suction and i in free else -1
                                 for i in range(n)])
        self.is_root_eq = np.zeros(m.neq, bool)
        self.is_root_eq[self.root_eq[self.root_eq >= 0]] = True
        self.geom_mushroom = np.full(m.ngeom, -1)
        self.geom_mushroom[self.cap_geoms] = np.arange(n)
        self.geom_mushroom[self.stem_geoms] = np.arange(n)
        self.is_cap = np.zeros(m.ngeom, bool)
        self.is_cap[self.cap_geoms] = True
        # Free mushrooms touch the robot. Static ones (beyond ``free_radius``) collide with
        # nothing: out of the broadphase, ~25 % off each physics step (50 mushrooms). KNOWN
        # SIMPLIFICATION: the tool passes through mushrooms more than free_radius from the target.
        free_mask = self.is_free.astype(int)
        for g in np.concatenate([self.cap_geoms, self.stem_geoms]):
            f = free_mask[self.geom_mushroom[g]]
            m.geom_contype[g] = ph.ROOTED_CONTYPE * f
            m.geom_conaffinity[g] = ph.ROOTED_CONAFFINITY * f
        # The broadphase prunes with per-body unions of the geom masks: keep them in step.
        m.body_contype[self.body_ids] = ph.ROOTED_CONTYPE * free_mask
        m.body_conaffinity[self.body_ids] = ph.ROOTED_CONAFFINITY * free_mask
        m.body_contype[0] |= ph.SOIL_CONTYPE
        m.body_conaffinity[0] |= ph.SOIL_CONAFFINITY
        self.robot_geom = np.zeros(m.ngeom, bool)
        self.robot_geom[[g for g in range(m.ngeom) if m.geom(g).name.startswith(PREFIX)]] = True
        if suction:
            self.cup_geom = m.geom(PREFIX + CUP_GEOM).id
            self._cup_mask = (int(m.geom_contype[self.cup_geom]), int(m.geom_conaffinity[self.cup_geom]))
            self.cup_body = m.body(PREFIX + CUP_BODY).id
            self.hand = None
        else:
            self.cup_geom = -1  # no geom id: the seal test never fires
            self.hand = HandGrasp(m)
        self.tool_site = m.site(PREFIX + TOOL_SITE).id
        force, torque = m.sensor(PREFIX + WRIST_FORCE), m.sensor(PREFIX + WRIST_TORQUE)
        self._wrench_adr = np.r_[force.adr[0]:force.adr[0] + 3, torque.adr[0]:torque.adr[0] + 3]
        self.arm_qadr = np.array([m.jnt_qposadr[m.joint(PREFIX + j).id] for j in ARM_JOINTS])
        self.arm_dadr = np.array([m.jnt_dofadr[m.joint(PREFIX + j).id] for j in ARM_JOINTS])
        self.cap_radius = np.array([inst.cap_diameter / 2 for inst in scene.instances])
        self._qfrc = np.zeros(m.nv)
        self.model, self.data, self.scene = m, d, scene

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        scene, slot = self._scene_for_reset(options)
        ep = _EpisodeState()
        if "target" in options:
            ep.target, ep.reachable = select_target(scene, "index", self.np_random, self.reach,
                                                    index=int(options["target"]),
                                                    max_tilt_deg=self.max_tilt_deg)
        else:
            ep.target, ep.reachable = select_target(scene, self.target_rule, self.np_random,
                                                    self.reach, index=self.target_index,
                                                    max_tilt_deg=self.max_tilt_deg)
        ep.estimate = self.pose_source(scene, ep.target, self.np_random)
        ep.target_pose = np.concatenate([ep.estimate.cap_top, ep.estimate.stem_axis])
        self._build(scene, ep.target, None if slot is None else (slot, ep.target))
        m, d = self.model, self.data
        self._ep = ep
        d.qpos[self.arm_qadr] = self.home_q
        d.ctrl[:6] = self.home_q
        if self.hand is not None:
            self.hand.open(d)
        # Posture target of the IK: the arm's configuration at a pre-grasp pose above the
        # *estimated* target (the pose the policy sees). Home holds the cup pointing down near the
        # Jaco's wrist singularity (joint 5 ~ 0, joints 4 and 6 aligned); a posture target at home
        # let the differential IK stall there, centimetres short of some pre-grasp poses.
        q_pre = self.reach.solve(ep.estimate.cap_top, ep.estimate.stem_axis, (0.05, 0.03))
        self.ik.reset(self.home_q, self.home_q if q_pre is None else q_pre)
        mujoco.mj_forward(m, d)
        for _ in range(max(1, int(round(self.params.settle_time / m.opt.timestep)))):
            mujoco.mj_step(m, d)
        self.init_xpos = d.xpos[self.body_ids].copy()
        self.init_cap_top = d.site_xpos[self.cap_top_sites[ep.target]].copy()
        self.steps = 0
        return self._obs(), self._info()

    def step(self, action: np.ndarray):
        if self.data is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (7,):
            raise ValueError(f"action must have shape (7,), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action contains NaN or inf: {a.tolist()}")
        a = a.clip(-1.0, 1.0)
        m, d, ep = self.model, self.data, self._ep
        if ep.done:
            warnings.warn("step() called after the episode ended (terminated or truncated); call "
                          "reset(). The episode stays ended.", stacklevel=2)
        # A latched valve stays open while the seal it made holds, whatever the command.
        ep.tool_on = bool(a[6] > 0) or (self.suction_mode == "latched" and ep.grip >= 0)
        ep.root_util = 0.0
        if self.hand is not None:
            self.hand.command(d, float(a[6]))
        elif not ep.tool_on and ep.grip >= 0:
            self._release()
        try:
            d.ctrl[:6] = self.ik.step(a[:6] * self._twist_scale, d.qpos[self.arm_qadr])
        except Exception:  # mink raises when the QP has no solution: hold the last command
            pass
        badqacc = d.warning[_BADQACC]
        # The hand's grip is read from each physics step's contacts, also when there are none.
        every = self.hand is not None
        for _ in range(self.substeps):
            mujoco.mj_step(m, d)
            if every or d.ncon > 0 or ep.grip >= 0:
                if badqacc.number > 0:
                    break
                self._picking_physics()
        if badqacc.number > 0 or not np.isfinite(d.qpos).all():
            ep.unstable = True
        if ep.held_detached and ep.finger_touch_step < self.steps:
            ep.grip_lost = True  # hand: the detached target left the fingers for a whole step
        self.steps += 1
        self._update_neighbours()
        success = self._success()
        terminated = (success or bool(ep.bruised) or (ep.target_detached and ep.grip_lost)
                      or (self.end_on_dead_end and self._dead_end()) or ep.done)
        truncated = ep.unstable
        ep.done = terminated or truncated
        reward, terms = self._reward(success)
        info = self._info(success)
        info.update({f"reward_{k}": v for k, v in terms.items()})
        if ep.unstable:
            mujoco.mj_resetData(m, d)  # keep later calls finite; the episode is over
            mujoco.mj_forward(m, d)
        return self._obs(), reward, terminated, truncated, info

    # ------------------------------------------------------------------ physics
    def _picking_physics(self) -> None:
        m, d, ep, p = self.model, self.data, self._ep, self.params
        touched: set[int] = set()
        ncon = d.ncon
        if ncon:
            geoms = d.contact.geom[:ncon]
            mush = self.geom_mushroom[geoms]
            rows = np.nonzero((mush >= 0).any(axis=1))[0]
            f6 = np.zeros(6)
            for c in rows:
                g1, g2 = geoms[c]
                mujoco.mj_contactForce(m, d, int(c), f6)
                fn = abs(f6[0])
                for g, other in ((g1, g2), (g2, g1)):
                    k = self.geom_mushroom[g]
                    if k < 0:
                        continue
                    if self.robot_geom[other]:
                        touched.add(int(k))
                        if self.hand is not None:
                            self.hand.add(int(other), int(k), fn)
                    if self.is_cap[g] and fn > p.bruise_force:
                        ep.bruised.add(int(k))
                    if (other == self.cup_geom and self.is_cap[g] and ep.tool_on
                            and ep.grip < 0 and fn >= p.seal_force and self.grip_eq[k] >= 0):
                        normal = d.contact.frame[c][:3] * (1.0 if g1 == self.cup_geom else -1.0)
                        if self._seals(int(k), d.contact.pos[c], normal):
                            self._grip(int(k), d.contact.pos[c].copy())
        if self.hand is not None:
            self._hand_grip()
        if ep.grip >= 0:
            touched.add(ep.grip)
        rooted = [k for k in touched if self.root_eq[k] >= 0 and d.eq_active[self.root_eq[k]]]
        if rooted:
            self._check_roots(rooted)
        if ep.grip >= 0 and self.hand is None:
            self._check_grip()

    def _hand_grip(self) -> None:
        """Hand: what the fingers hold after this physics step (held = at least two fingers on
        it while the hand is commanded closed), then forget the step's contacts."""
        ep, hand = self._ep, self.hand
        ep.grip = hand.held(ep.target) if ep.tool_on else -1
        ep.finger_force = hand.force.get(ep.target, 0.0)
        if ep.target in hand.fingers:
            ep.finger_touch_step = self.steps
        if ep.grip == ep.target:
            ep.ever_gripped_target = True
            ep.held_detached |= ep.target_detached
        hand.clear()

    def _seals(self, k: int, point: np.ndarray, normal_cup_to_cap: np.ndarray) -> bool:
        """Seal test: cup axis vs. cap normal at the contact, and contact on the cap top."""
        d, p = self.data, self.params
        z = d.site_xmat[self.tool_site].reshape(3, 3)[:, 2]
        cos = float(z @ normal_cup_to_cap)
        if cos < np.cos(np.deg2rad(p.seal_angle_deg)):
            return False
        b = self.body_ids[k]
        axis = d.xmat[b].reshape(3, 3)[:, 2]
        rel = point - d.xpos[b]
        radial = np.linalg.norm(rel - (rel @ axis) * axis)
        return bool(radial <= p.seal_region * self.cap_radius[k])

    def _grip(self, k: int, point: np.ndarray | None = None) -> None:
        """Seal the cup on mushroom ``k``: a weld anchored at the contact ``point`` (world)."""
        m, d, ep = self.model, self.data, self._ep
        e = self.grip_eq[k]
        b = self.body_ids[k]
        if point is None:
            point = d.site_xpos[self.tool_site]
        # Anchor (body2 = mushroom frame) at the cup-cap contact: the weld is the seal itself.
        # MuJoCo's weld joins the point eq_data[:3] in body2's frame to the point eq_data[3:6] in
        # body1's (the cup's) frame: both are the contact point now; eq_data[6:10] is the
        # relative orientation.
        point = np.asarray(point, float)
        m.eq_data[e, :3] = d.xmat[b].reshape(3, 3).T @ (point - d.xpos[b])
        m.eq_data[e, 3:10] = ph.weld_relpose(m, d, self.cup_body, b)
        m.eq_data[e, 3:6] = d.xmat[self.cup_body].reshape(3, 3).T @ (point - d.xpos[self.cup_body])
        m.eq_data[e, 10] = 1.0
        d.eq_active[e] = 1
        # While sealed, the weld is the cup-cap interface: the cup face stops colliding with
        # mushrooms (otherwise contact and weld fight and load the seal with internal forces).
        m.geom_conaffinity[self.cup_geom] = 0
        m.geom_contype[self.cup_geom] = ph.SOIL_CONAFFINITY
        ep.grip = k
        ep.seal_step, ep.seal_tool_x = self.steps, d.site_xmat[self.tool_site, 0::3].copy()
        if k == ep.target:
            ep.ever_gripped_target = True

    def _release(self) -> None:
        ep = self._ep
        self.data.eq_active[self.grip_eq[ep.grip]] = 0
        self.model.geom_contype[self.cup_geom] = self._cup_mask[0]
        self.model.geom_conaffinity[self.cup_geom] = self._cup_mask[1]
        ep.grip, ep.grip_util, ep.seal_step, ep.seal_tool_x = -1, 0.0, -1, None

    def _eq_wrench(self, rows: np.ndarray) -> np.ndarray:
        return ph.wrench_from_rows(self.model, self.data, rows, self._qfrc)

    def _check_roots(self, ks: list[int]) -> None:
        m, d, ep = self.model, self.data, self._ep
        nefc = d.nefc
        eq = d.efc_type[:nefc] == _EQ
        rows = eq & self.is_root_eq[np.where(eq, d.efc_id[:nefc], 0)]
        q = self._eq_wrench(rows)
        for k in ks:
            rot = d.xmat[self.body_ids[k]].reshape(3, 3)
            force, torque = ph.free_body_wrench(q, self.dofadr[k], rot)
            axis = rot[:, 2]
            tension = max(0.0, -float(force @ axis))
            tw, bend = ph.axial_split(torque, axis)
            u = ph.root_utilisation(tension, bend, abs(tw), self.params)
            if u >= 1.0:
                d.eq_active[self.root_eq[k]] = 0
                for g in (self.cap_geoms[k], self.stem_geoms[k]):
                    m.geom_contype[g], m.geom_conaffinity[g] = ph.FREE_CONTYPE, self._free_aff
                b = self.body_ids[k]
                m.body_contype[b], m.body_conaffinity[b] = ph.FREE_CONTYPE, self._free_aff
                ep.detached.add(k)
                if k == ep.target:
                    ep.target_detached = True
            if k == ep.target:
                ep.root_util = max(ep.root_util, u)

    def grip_wrench(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Load the seal carries: world force the cup exerts on the gripped mushroom, its moment
        about the cup contact point (the tool site on the cup face), and the cup axis."""
        d, k = self.data, self._ep.grip
        nefc = d.nefc
        rows = (d.efc_type[:nefc] == _EQ) & (d.efc_id[:nefc] == self.grip_eq[k])  # eq ids only
        q = self._eq_wrench(rows)
        b = self.body_ids[k]
        force, torque = ph.free_body_wrench(q, self.dofadr[k], d.xmat[b].reshape(3, 3))
        moment = ph.moment_about(force, torque, d.xpos[b], d.site_xpos[self.tool_site])
        return force, moment, d.site_xmat[self.tool_site].reshape(3, 3)[:, 2].copy()

    def _check_grip(self) -> None:
        ep = self._ep
        k = ep.grip
        force, torque_c, z = self.grip_wrench()
        fz, shear = ph.axial_split(force, z)
        tz, bend = ph.axial_split(torque_c, z)
        u = ph.grip_utilisation(max(0.0, -fz), shear, bend, abs(tz), self.params)
        ep.grip_util = u
        if u >= 1.0:
            if k == ep.target and ep.target_detached:
                ep.grip_lost = True
            self._release()

    def _update_neighbours(self) -> None:
        ep = self._ep
        # Only mushrooms with a free joint can move (the others are static bodies).
        free = self.free_ids
        moved = self.data.xpos[self.body_ids[free]] - self.init_xpos[free]
        for k in free[np.einsum("ij,ij->i", moved, moved) > self.params.disturb_tolerance**2]:
            if k != ep.target:
                ep.disturbed.add(int(k))
        ep.disturbed |= {k for k in ep.detached if k != ep.target}
        m = self.model
        for k in ep.detached:
            b = self.body_ids[k]
            if (m.body_conaffinity[b] != self._lifted_aff
                    and self.data.xpos[b, 2] - self.init_xpos[k, 2] > ph.SOIL_CLEARANCE):
                self._set_soil_contact(k, True)
                # Only once the stem's collision hull is out of the soil: switching contacts on
                # while it still penetrates (a sloped or tilted stem base) throws the mushroom
                # out of the cup.
                if self._penetrates_soil(k):
                    self._set_soil_contact(k, False)
        lift = float(self.data.site_xpos[self.cap_top_sites[ep.target], 2] - self.init_cap_top[2])
        ep.max_lift = max(ep.max_lift, lift)

    def _set_soil_contact(self, k: int, on: bool) -> None:
        m = self.model
        aff = self._lifted_aff if on else self._free_aff
        for g in (self.cap_geoms[k], self.stem_geoms[k]):
            m.geom_conaffinity[g] = aff
        m.body_conaffinity[self.body_ids[k]] = aff

    def _penetrates_soil(self, k: int) -> bool:
        """Whether mushroom ``k`` penetrates the soil now (runs the collision detector; the
        next physics step recomputes the contacts from scratch)."""
        m, d = self.model, self.data
        mujoco.mj_collision(m, d)
        ncon = d.ncon
        if ncon == 0:
            return False
        geoms = d.contact.geom[:ncon]
        mine = (self.geom_mushroom[geoms] == k).any(axis=1) & (geoms == self.terrain_geom).any(axis=1)
        return bool(np.any(d.contact.dist[:ncon][mine] < 0.0))

    # ------------------------------------------------------------------ outputs
    def _lift(self) -> float:
        return float(self.data.site_xpos[self.cap_top_sites[self._ep.target], 2] - self.init_cap_top[2])

    def _success(self) -> bool:
        ep = self._ep
        return bool(ep.target_detached and ep.grip == ep.target and not ep.bruised
                    and not ep.unstable and self._lift() >= self.params.lift_height)

    def _dead_end(self) -> bool:
        """The episode can no longer succeed: the target is off its roots and not held (suction;
        the hand detaches a cap as its fingers close, before it holds it), or a latched seal
        holds another mushroom."""
        ep = self._ep
        if self.hand is not None:
            return False
        knocked_off = ep.target_detached and ep.grip != ep.target
        wrong_seal = self.suction_mode == "latched" and ep.grip >= 0 and ep.grip != ep.target
        return knocked_off or wrong_seal

    def _reward(self, success: bool) -> tuple[float, dict[str, float]]:
        """The step's reward and its terms (the staged reward's; empty for the others)."""
        d, ep = self.data, self._ep
        s = RewardState(
            tool_pos=d.site_xpos[self.tool_site], tool_axis=d.site_xmat[self.tool_site, 2::3],
            est_cap_top=ep.target_pose[:3], est_axis=ep.target_pose[3:],
            gripped_target=ep.grip == ep.target, target_detached=ep.target_detached,
            lift=self._lift(), lift_goal=self.params.lift_height, success=success,
            bruised=bool(ep.bruised), root_utilisation=ep.root_util,
            steps_left=self.horizon - self.steps)
        if self.reward_type == "staged":
            terms = reward_terms(s)
            return sum(terms.values()), terms
        return compute_reward(s, self.reward_type), {}

    def failure_cause(self) -> str | None:
        """Why the episode is not (yet) a success, or None on success."""
        ep = self._ep
        if self._success():
            return None
        if ep.unstable:
            return "unstable_simulation"
        if not ep.reachable:
            return "unreachable"
        if ep.bruised:
            return "bruised"
        if ep.grip_lost:
            return "grip_lost"
        if not ep.ever_gripped_target:
            return "neighbour_disturbed" if ep.disturbed else "no_seal"
        if not ep.target_detached:
            return "not_detached"
        if ep.disturbed:
            return "neighbour_disturbed"
        return "timeout"

    def _info(self, success: bool = False) -> dict[str, Any]:
        ep = self._ep
        return {
            "is_success": bool(success),
            "failure_cause": None if success else self.failure_cause(),
            "target": ep.target,
            "reachable": ep.reachable,
            "gripped": ep.grip >= 0,
            "gripped_target": ep.grip == ep.target,
            "target_detached": ep.target_detached,
            "bruised": sorted(ep.bruised),
            "neighbours_disturbed": len(ep.disturbed),
            "lift": self._lift(),
            "unstable_simulation": ep.unstable,
        }

    def _obs(self) -> dict[str, np.ndarray]:
        d, ep = self.data, self._ep
        pos = d.site_xpos[self.tool_site]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, d.site_xmat[self.tool_site])
        # One flat vector, one finiteness check, then views per entry (small-array numpy calls
        # dominate here, not arithmetic).
        if self.hand is None:
            tool = (float(ep.tool_on), float(ep.grip >= 0), ep.grip_util)
        else:
            tool = (self.hand.closure(d), float(ep.grip >= 0), ep.finger_force)
        parts = [d.qpos[self.arm_qadr], d.qvel[self.arm_dadr], pos, quat, tool, ep.target_pose,
                 ep.target_pose[:3] - pos]
        if self.task_obs:
            parts += self._task_obs()
        flat = np.concatenate(parts)
        if not np.isfinite(flat).all():
            flat = np.nan_to_num(flat)
        obs = {k: flat[sl] for k, sl in self._obs_slices.items()}
        if self.image_obs:
            h, w = self.image_size
            rgb = self._render(h, w, depth=False)
            depth = self._render(h, w, depth=True)
            obs["rgb"] = rgb
            obs["depth"] = depth[..., None].astype(np.float32)
        return obs

    def _task_obs(self) -> list[np.ndarray]:
        """The ``task_obs`` entries (see :mod:`sms3d_env.task_obs`)."""
        d, ep = self.data, self._ep
        rot = d.site_xmat[self.tool_site]
        cap_top, axis = ep.target_pose[:3], ep.target_pose[3:]
        sealed = ep.seal_step >= 0
        twist = twist_about(axis, ep.seal_tool_x, rot[0::3]) if sealed else 0.0
        since_seal = (self.steps - ep.seal_step) * self.control_dt if sealed else 0.0
        return [tool_in_target(d.site_xpos[self.tool_site], rot[2::3], cap_top, axis),
                np.array([self.steps * self.control_dt, since_seal, twist]),
                d.sensordata[self._wrench_adr]]

    # ------------------------------------------------------------------ rendering
    def _disown_renderers(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers = {}

    def _render(self, h: int, w: int, depth: bool) -> np.ndarray:
        os.environ.setdefault("MUJOCO_GL", "egl")
        key = (h, w)
        r = self._renderers.get(key)
        if r is None:
            r = open_renderer(self.model, h, w)
            self._renderers[key] = r
        if depth:
            r.enable_depth_rendering()
        else:
            r.disable_depth_rendering()
        r.update_scene(self.data, camera=self.camera)
        out = r.render()
        return out.copy()

    def render(self) -> np.ndarray | None:
        if self.render_mode is None or self.data is None:
            return None
        h, w = self.render_size
        return self._render(h, w, depth=self.render_mode == "depth_array")

    def close(self) -> None:
        self._disown_renderers()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderers"] = {}
        if self.data is not None:
            # A sleeping island's latent state does not pickle (MuJoCo keeps it only through
            # mj_copyData): carry the integration state; the copy wakes every tree.
            flat = np.empty(mujoco.mj_stateSize(self.model, _STATE))
            mujoco.mj_getState(self.model, self.data, flat, _STATE)
            state["data"] = flat
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        if self.data is not None:
            self.data = mujoco.MjData(self.model)
            mujoco.mj_setState(self.model, self.data, state["data"], _STATE)
            mujoco.mj_forward(self.model, self.data)
