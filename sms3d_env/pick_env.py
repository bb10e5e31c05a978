"""``SMS3DPick-v2``: pick one mushroom from a synthetic bed with a Cartesian gantry harvester, a
Kinova Jaco or a UR5e-class arm, by a suction tool (default) or the Jaco 3-finger hand.

The env holds the gym API only: spaces, reset/step, observation, reward assembly and rendering.
Its options are records checked where they are defined (:mod:`sms3d_env.env_args` checks the
rest and reads the options of earlier versions). The beds come from :mod:`sms3d_env.scene_source`;
the arm's start from :mod:`sms3d_env.start_states`; the IK's posture target from
:mod:`sms3d_env.posture`; the world (scene + robot model and its id tables) is
:mod:`sms3d_env.world`; the picking rules (roots, bruising, neighbours, success and
failure) are :mod:`sms3d_env.picking_model`, called after every physics substep, with each tool's
own (suction: valve, seal, grip; hand: fingers) in :mod:`sms3d_env.tools`; the reward terms are
:mod:`sms3d_env.rewards`.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces
from mink.exceptions import NoSolutionFound

from generator.gl import open_renderer
from sms3d_env.cameras import ImageObservation, RenderCamera
from sms3d_env.controller import ControllerConfig, IKController
from sms3d_env.env_args import RENDER_MODES, SUCTION_MODES, check_env_args, pose_error_of
from sms3d_env.physics_params import PickPhysicsParams, physics_for
from sms3d_env.picking_model import FAILURE_CAUSES, PickingModel
from sms3d_env.pose_sources import PoseEstimate, PoseSource, make_pose_source
from sms3d_env.posture import IKPosture
from sms3d_env.records import record_of
from sms3d_env.rewards import RewardConfig, RewardState, compute_reward, reward_terms
from sms3d_env.robot import RobotSpec
from sms3d_env.robots import make_robot
from sms3d_env.scene_source import SceneSource, scene_source_config
from sms3d_env.start_states import PregraspStart, check_share
from sms3d_env.targets import Reachability, TargetRule, pickable, select_target
from sms3d_env.task_obs import TASK_OBS_SIZES, tool_in_target, twist_about
from sms3d_env.viewer import PassiveViewer
from sms3d_env.world import PICK_CAMERA, PICK_CAMERA_DISTANCE, World, aim_pick_camera, build_world

__all__ = ["FAILURE_CAUSES", "SUCTION_MODES", "SMS3DPickEnv"]

_BADQACC = int(mujoco.mjtWarning.mjWARN_BADQACC)
# State observation entries after the joints' (one entry per robot joint each: ``joint_pos``,
# ``joint_vel``) and their sizes, in the order of the flat vector they are cut from.
_OBS_SIZES = {"tool_pose": 7, "suction": 3, "target_pose": 6, "target_rel": 3}


def _slices(sizes: dict[str, int]) -> dict[str, slice]:
    ends = np.cumsum(list(sizes.values())).tolist()
    return {k: slice(end - n, end) for (k, n), end in zip(sizes.items(), ends, strict=True)}


class SMS3DPickEnv(gym.Env):
    """Gymnasium environment for picking one target mushroom with a suction cup or a hand.

    ## Action space
    ``Box(-1, 1, (7,), float32)``:

    | index | meaning | scale |
    | --- | --- | --- |
    | 0–2 | tool linear velocity (world) | × ``ControllerConfig.max_linear_speed`` (m/s) |
    | 3–5 | tool angular velocity (world) | × ``max_angular_speed`` (rad/s) |
    | 6 | suction on if > 0 (``suction_mode="latched"``: held once sealed); hand: fingers' target, −1 open … +1 closed | |

    mink's differential IK turns the twist into joint targets every ``ControllerConfig.control_dt``.
    NaN/inf raise.

    ## Observation space
    A ``Dict`` (SB3's ``MultiInputPolicy``); all float64 unless noted:

    | key | size | content |
    | --- | --- | --- |
    | ``joint_pos``, ``joint_vel`` | one per robot joint (6 for each built-in robot) | the robot's driven joints, ``robot.joints`` (rad or m, rad/s or m/s) |
    | ``tool_pose`` | 7 | tool site position (m) and quaternion (w, x, y, z) |
    | ``suction`` | 3 | suction: (on, sealed, seal load / capacity); hand: (closure 0–1, holding with ≥ 2 fingers, finger force on the target N) |
    | ``target_pose`` | 6 | the *estimated* cap top (m) and stem axis (from the pose source) |
    | ``target_rel`` | 3 | estimated cap top − tool position (m) |
    | ``tool_in_target``, ``progress``, ``wrist_wrench`` | 7, 3, 6 | with ``task_obs=True``: see :mod:`sms3d_env.task_obs` |
    | ``rgb``, ``depth`` | H × W × 3 uint8, H × W × 1 float32 | with ``image_obs`` (``ImageObservation``: size, by default the ``"overhead"`` camera) |

    Nothing in the observation is privileged: no true pose, no root or seal loads beyond what a
    vacuum sensor reports.

    ## Reward
    ``"dense"`` (default), ``"sparse"`` (0 on success, −1 otherwise) or ``"staged"`` (bounded per
    step, maximal at success; terms in ``info["reward_stage"|"reward_progress"|"reward_success_bonus"]``),
    see :mod:`sms3d_env.rewards`. Their approach terms pull towards the estimated pose; the staged
    success bonus is the steps left until ``RewardConfig.horizon``.

    ## Episode end
    | | when |
    | --- | --- |
    | terminated, success | target picked (detached, held, lifted ``PickPhysicsParams.lift_height``), no cap bruised; with ``PickPhysicsParams.clean_pick`` no neighbour disturbed |
    | terminated, failure | the target picked with a neighbour disturbed (``clean_pick``); a cap bruised; the detached target's grip lost; with ``end_on_dead_end``: the target knocked off and not held, or a latched seal on a neighbour |
    | truncated | the simulation went unstable; the registered time limit (250 steps) |

    ``info``: ``is_success``, ``failure_cause`` (one of ``FAILURE_CAUSES``), ``target``,
    ``reachable``, ``gripped``, ``gripped_target``, ``target_detached``, ``bruised``,
    ``neighbours_disturbed``, ``lift``, ``unstable_simulation`` (the picking model's
    ``evaluate()``), ``start`` (``"home"``, or ``"pregrasp"`` for a ``PregraspStart`` reset),
    ``time_s`` (simulated seconds since reset; at success, the pick's cycle time),
    ``time_gripped_s`` and ``time_detached_s`` (when the target was first held and when its root
    let go; None before: the cycle's phases whatever the policy), plus the
    staged reward's terms. ``failure_cause="not_reached"``: the tool never came within 1 cm of
    the target's true cap top (the approach stopped short); ``"no_seal"``: it did, and no seal
    formed; ``"seal_overloaded"``: the seal let go under the twist or bend before the root did;
    ``"not_detached"``: the root held through the whole twist.

    ## Arguments
    Each record argument also takes its mapping form (field name -> value, e.g.
    ``controller={"posture_target": "tool"}``), so that an env spec stays JSON: Minari datasets,
    RL Zoo recipes and a saved policy's ``config.json`` rebuild the env from it. Options of earlier
    versions are read by :func:`sms3d_env.env_args.translate_legacy_options`.

    | Parameter | Type | Default | Description |
    | --- | --- | --- | --- |
    | ``render_mode`` | ``str`` or None | None | ``"rgb_array"``, ``"depth_array"`` (metric depth in metres) or ``"human"`` (MuJoCo's passive viewer, synced at every reset and step, closed by ``close()``; it needs a display, see :mod:`sms3d_env.viewer`, else ``DisplayUnavailableError``) |
    | ``robot`` | ``str``, a robot configuration (``RobotSpec``: ``GantryConfig``, ``RobotConfig``, ...) or None | ``"gantry"`` | a registered robot's name (``sms3d_env.registered_robots()``): ``"gantry"`` (the Cartesian harvester of :mod:`sms3d_env.gantry`), ``"jaco"`` (the Kinova Jaco hanging above the bed), ``"ur5e"`` (a UR5e-class arm on a pedestal beside it, :mod:`sms3d_env.ur5e`) or one added with ``sms3d_env.register_robot`` (docs/add-a-robot.md); or a robot configuration; every link of every built-in robot collides with the soil and the mushrooms. None: the default, ``"gantry"`` |
    | ``tool`` | ``str`` or None | None | ``"suction"`` or ``"hand"``; overrides the robot's tool (default: ``"suction"``) |
    | ``scene`` | ``SceneSourceConfig``, ``generator.SceneConfig``, a list of ``generator.Scene``, a dataset folder, or None | None | where each reset's bed comes from and which mushrooms can move (:class:`~sms3d_env.scene_source.SceneSourceConfig`: generated beds, a fixed list, a pool, ``free_radius``). A ``SceneConfig`` (or its mapping form, e.g. ``{"placement": {"num_mushrooms": 10}}``): a new bed of it per reset; scenes or a ``sms3d generate`` folder (checksums verified): one drawn per reset (``options={"scene": k}``); None: a new 25-mushroom bed per reset, every mushroom free |
    | ``target`` | ``str`` or ``TargetRule`` | ``"harvest_ready"`` | which mushroom is picked (:class:`~sms3d_env.targets.TargetRule`), drawn uniformly within a class: ``"harvest_ready"`` (a reachable cap of at least ``harvest_diameter``, 50 mm: what a farm picks now), ``"isolated"``, ``"crowded"``, ``"approach_blocked"``, ``"small"``; or ``"tallest"`` (v1's), ``"largest"``, ``"random"``, ``"index"`` with its ``index``; ``max_tilt_deg``; ``options={"target": i}`` picks mushroom ``i`` for one reset |
    | ``pose_source`` | ``str`` or ``PoseSource`` | ``"oracle"`` | the target estimate in the observation: ``"oracle"``, ``"noisy"``, ``"perception"`` or a callable ``(scene, id, rng) -> PoseEstimate`` (e.g. ``NoisyPose(error_deg, position_std=0.002)``, ``PerceptionPose(detector=...)``) |
    | ``pose_error_deg`` | ``float`` or ``(low, high)`` | 0.0 | the ``"noisy"`` source's rotation error (deg), or a pair: drawn per episode uniformly in it (``UniformNoisyPose``); refused with any other source |
    | ``reward_type`` | ``str`` or ``RewardConfig`` | ``"dense"`` | ``"dense"``, ``"sparse"`` or ``"staged"``, or :class:`~sms3d_env.rewards.RewardConfig` (``kind``, the staged reward's ``horizon``) |
    | ``physics`` | ``PickPhysicsParams``, its mapping form or None | None | the picking model: the cup (``vacuum``, ``cup_radius``, ``lip_compliance``, ``evacuation_time``), the root (``pull_force``, ``bend_moment``, ``twist_torque`` and the angles they are reached at), bruising, what a clean pick is (None or fields left out: the defaults, the robot's cup radius); ``SMS3DPick-v1``'s is ``V1_PHYSICS`` |
    | ``controller`` | ``ControllerConfig`` or None | None | :class:`~sms3d_env.controller.ControllerConfig`: control period and physics substeps, the IK's speeds and weights, and its posture target (``posture_target``, :mod:`sms3d_env.posture`) |
    | ``start`` | ``PregraspStart`` or None | None | where the arm starts (:mod:`sms3d_env.start_states`): None at home; ``PregraspStart(share)`` that share of resets on the way to a pre-grasp pose (a reverse curriculum; ``set_pregrasp_start`` changes the share between episodes) |
    | ``suction_mode`` | ``str`` | ``"momentary"`` | ``"momentary"`` (any command <= 0 releases the seal) or ``"latched"`` (the vacuum valve holds its state: once a seal forms it stays on whatever the command, as a picker's valve does after its vacuum switch trips) |
    | ``end_on_dead_end`` | ``bool`` | False | also terminate (as a failure) when the episode can no longer succeed |
    | ``task_obs`` | ``bool`` | False | add ``tool_in_target``, ``progress`` and ``wrist_wrench`` to the observation |
    | ``image_obs`` | ``bool`` or ``ImageObservation`` | False | RGB-D observations: True for :class:`~sms3d_env.cameras.ImageObservation`'s defaults (64 × 64 from ``"overhead"``), or the record (``size``, ``camera``) |
    | ``render_camera`` | ``str``, ``RenderCamera`` or None | None | what ``render()`` shows: a camera of ``world.CAMERAS``, or :class:`~sms3d_env.cameras.RenderCamera` (``name``, ``size``, default 480 × 640); None: the ``"pick"`` camera, placed at each reset beyond the target as seen from the robot's mount, looking at its cap top |

    ``SMS3DPickTrain-v1`` sets the training options: ``suction_mode="latched"``,
    ``reward_type="staged"``, ``end_on_dead_end=True``, ``task_obs=True``.

    ## Version history
    - v2: the outcome is set by the mushroom and the cup, not by the simulator's rules
      (``PickPhysicsParams``). The seal is judged on the cup's whole lip (``lip_seal``: every lip
      point over the target's cap within the lip's compliance, 5 mm), and its holding force rises
      over the vacuum's evacuation time; the root bends and twists before it lets go
      (``compliant_root``: a ball constraint at the stem base and springs reaching their limits
      after 15 deg of bend and 30 deg of twist); every mushroom collides with every other
      (``mushrooms_collide``; generated beds are placed so that no two collision hulls
      interpenetrate, ``placement.overlap_solids="hulls"``, ``overlap_iou=0``); a cap also
      bruises by slip-shear (``slip_bruising``); success is a clean pick (``clean_pick``: no
      neighbour moved more than 5 mm or knocked off its roots), ``info["target_picked"]`` says
      whether the target itself was; the target is drawn among the harvest-ready mushrooms
      (``target="harvest_ready"``); a released mushroom meets the casing at once
      (``stem_in_casing``: its stem rests in its hole, its cap on the soil; it fell through the
      casing when let go before rising 5 mm); the cup is rated at 60 kPa, friction 0.3 on a moist cap,
      twist-off torque 0.03 N m (Xu et al. 2025's range). ``info`` gains ``time_gripped_s`` and
      ``time_detached_s``. The class's defaults are v2's.
    - v1: the robot is physically honest. A Cartesian gantry harvester (``robot="gantry"``, the
      default) or a Jaco hanging above the bed with a right-angle suction adapter
      (``robot="jaco"``; its scripted picker reaches the stand-off point along a straight
      joint-space path, ``RobotConfig.approach="joint"``, where the straight Cartesian approach
      stalled at the arm's shoulder and wrist singularities), every link of either
      colliding with the soil and with every mushroom; every mushroom is free and rooted
      (``SceneSourceConfig.free_radius=None``), so any link that touches a cap is judged by the
      same bruise and disturbed-neighbour rules as the tool. ``info`` gains ``time_s``; the
      failure cause ``not_reached`` separates approaches that stopped short from seals that
      failed. The seal's grip-loss rule reads its load over a 20 ms response time and counts
      the cup's pressing force in its capacities (``PickPhysicsParams.seal_response_time``,
      ``seal_preload``), and the physics steps at 4 ms (``ControllerConfig.substeps=10``): read
      per 2 ms step, one step's load peak when a root let go decided picks, and the outcome
      depended on the step size. The constructor's arguments were regrouped into 16, the options of one concern
      in one record (``scene``, ``target``, ``reward_type``, ``controller``, ``start``,
      ``image_obs``, ``render_camera``); the same ids make the same episodes. ``step()`` after
      the episode ended returns its last outcome with no reward (it simulated on, and ``info``
      turned into a ``timeout`` failure); ``SMS3DPickEnv()`` and ``robot=None`` are the gantry
      (they were v0's Jaco). The physics options of the coming v2 (``PickPhysicsParams``
      ``lip_seal``, ``mushrooms_collide``, ``slip_bruising``, ``clean_pick``; the
      ``"harvest_ready"`` target) are off in v1.
    - v0: the Jaco beside the bed below the soil line; its base, shoulder, upper arm, forearm and
      first wrist link collide with nothing, and only the mushrooms within 10 cm of the target
      collide with anything (``free_radius=0.10``); 20 physics steps of 2 ms per control step,
      and the seal let go on one step's load. Superseded by v1 and removed (its ids are no longer
      registered; ``gym.make`` names the latest version); its measurements stay in the results
      history and the changelog.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 25}

    def __init__(
        self,
        render_mode: str | None = None,
        robot: str | RobotSpec | None = "gantry",
        tool: str | None = None,
        scene: Any = None,
        target: str | TargetRule | Mapping[str, Any] = "harvest_ready",
        pose_source: str | PoseSource = "oracle",
        pose_error_deg: float | tuple[float, float] = 0.0,
        reward_type: str | RewardConfig | Mapping[str, Any] = "dense",
        physics: PickPhysicsParams | Mapping[str, Any] | None = None,
        controller: ControllerConfig | Mapping[str, Any] | None = None,
        start: PregraspStart | Mapping[str, Any] | None = None,
        suction_mode: str = "momentary",
        end_on_dead_end: bool = False,
        task_obs: bool = False,
        image_obs: bool | ImageObservation | Mapping[str, Any] = False,
        render_camera: str | RenderCamera | Mapping[str, Any] | None = None,
    ) -> None:
        self.robot_cfg = make_robot("gantry" if robot is None else robot)
        check_env_args(render_mode=render_mode, tool=tool or self.robot_cfg.tool, suction_mode=suction_mode,
                       pose_source=pose_source, pose_error_deg=pose_error_deg, end_on_dead_end=end_on_dead_end,
                       task_obs=task_obs)
        if tool is not None:
            self.robot_cfg = replace(self.robot_cfg, tool=tool)
        self.tool = self.robot_cfg.tool
        self.render_mode = render_mode
        self.params = physics_for(physics, self.robot_cfg.cup_radius)
        touching = self.params.mushrooms_collide
        self.scene_source = SceneSource(scene_source_config(scene, touching), touching)
        self.target_rule = record_of(TargetRule, target, "target", shorthand="rule")
        self.pose_source = make_pose_source(pose_source, pose_error_of(pose_error_deg))
        self.reward_config = record_of(RewardConfig, reward_type, "reward_type", shorthand="kind")
        self.ctrl_cfg = ControllerConfig() if controller is None else record_of(ControllerConfig, controller,
                                                                               "controller")
        self.start = None if start is None else record_of(PregraspStart, start, "start")
        self.suction_mode, self.end_on_dead_end, self.task_obs = suction_mode, bool(end_on_dead_end), bool(task_obs)
        if isinstance(image_obs, (bool, np.bool_)):
            self.image_obs = ImageObservation() if image_obs else None
        elif isinstance(image_obs, (ImageObservation, Mapping)):
            self.image_obs = record_of(ImageObservation, image_obs, "image_obs")
        else:  # by truthiness, image_obs="no" would switch the images on
            raise TypeError(f"image_obs must be True or False, an ImageObservation or its mapping form, got "
                            f"{type(image_obs).__name__} {image_obs!r}")
        camera = RenderCamera() if render_camera is None else record_of(RenderCamera, render_camera, "render_camera",
                                                                       shorthand="name")
        self.render_camera = replace(camera, name=camera.name or PICK_CAMERA)  # None: the per-episode pick camera

        self.ik = IKController(self.robot_cfg, self.ctrl_cfg)
        self.home_q = np.asarray(self.robot_cfg.home_q, float)
        self.reach = Reachability(self.ik.model, self.ik.site, self.ik.arm_qadr, self.home_q)
        self.posture = IKPosture(self.ik, self.reach, self.home_q)
        self.action_space = spaces.Box(-1.0, 1.0, (7,), np.float32)
        self._twist_scale = np.repeat([self.ctrl_cfg.max_linear_speed, self.ctrl_cfg.max_angular_speed], 3)
        self._n_joints = n = len(self.robot_cfg.joints)
        self._obs_sizes = {"joint_pos": n, "joint_vel": n, **_OBS_SIZES, **(TASK_OBS_SIZES if self.task_obs else {})}
        self._obs_slices = _slices(self._obs_sizes)
        obs = {k: spaces.Box(-np.inf, np.inf, (n,), np.float64) for k, n in self._obs_sizes.items()}
        if self.image_obs is not None:
            h, w = self.image_obs.size
            obs["rgb"] = spaces.Box(0, 255, (h, w, 3), np.uint8)
            obs["depth"] = spaces.Box(0.0, np.inf, (h, w, 1), np.float32)
        self.observation_space = spaces.Dict(obs)
        self.world: World | None = None
        self.picking: PickingModel | None = None
        self.target_pose = np.zeros(6)  # the estimate in the observation: cap top, stem axis
        self._start_label = "home"  # info["start"] of the episode
        self.done = False  # the episode terminated or was truncated
        self._end_on_bruise = True  # a bruised cap ends the episode (start_pick may say otherwise)
        self._renderers: dict[tuple[int, int], mujoco.Renderer] = {}
        self._viewer = PassiveViewer(self.control_dt) if render_mode == "human" else None

    # The world's model, data and scene (None before the first reset).
    @property
    def model(self) -> mujoco.MjModel | None:
        return None if self.world is None else self.world.model

    @property
    def data(self) -> mujoco.MjData | None:
        return None if self.world is None else self.world.data

    @property
    def scene(self) -> Any:
        return None if self.world is None else self.world.scene

    @property
    def steps(self) -> int:
        """Control steps taken in this episode."""
        return self.picking.steps

    @property
    def control_dt(self) -> float:
        """The control period (s): ``ControllerConfig.control_dt``."""
        return self.ctrl_cfg.control_dt

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        scene, slot = self.scene_source.draw(self.np_random, options)
        rule = self.target_rule
        kind, index = ("index", int(options["target"])) if "target" in options else (rule.rule, rule.index)
        target, reachable = select_target(scene, kind, self.np_random, self.reach, index=index,
                                          max_tilt_deg=rule.max_tilt_deg, harvest_diameter=rule.harvest_diameter)
        estimate = self.pose_source(scene, target, self.np_random)
        self.target_pose = np.concatenate([estimate.cap_top, estimate.stem_axis])
        self._disown_renderers()
        ctrl = self.ctrl_cfg
        self.world = w = build_world(scene, target, self.robot_cfg, self.scene_source.config.free_radius,
                                     ctrl.control_dt / ctrl.substeps, self.scene_source.models,
                                     self._model_key(slot, target), self.params.mushrooms_collide,
                                     self.params.compliant_root, self.params.stem_in_casing)
        self.picking = PickingModel(w, self.params, target, reachable, self.suction_mode == "latched")
        self.done, self._end_on_bruise = False, True
        m, d = w.model, w.data
        q_start, self._start_label = (self.home_q, "home") if self.start is None else self.start.configuration(
            self.np_random, self.reach, self.home_q, estimate.cap_top, estimate.stem_axis)
        d.qpos[w.arm_qadr] = q_start
        d.ctrl[:self._n_joints] = q_start  # the joints' actuators come first, in the joints' order
        self.picking.tool.reset()
        self.posture.reset(q_start, estimate.cap_top, estimate.stem_axis)
        mujoco.mj_forward(m, d)
        self._settle()
        self.picking.settled()
        if self.render_mode == "human":
            self.render()
        return self._obs(), {**self.picking.evaluate(self.control_dt), "start": self._start_label}

    def step(self, action: np.ndarray):
        if self.world is None:
            raise RuntimeError("call reset() before step()")
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (7,):
            raise ValueError(f"action must have shape (7,), got {a.shape}")
        if not np.isfinite(a).all():
            raise ValueError(f"action contains NaN or inf: {a.tolist()}")
        a = a.clip(-1.0, 1.0)
        w, picking = self.world, self.picking
        m, d, ep = w.model, w.data, picking.state
        if self.done:  # nothing moves: the last transition's outcome stands, with no more reward
            warnings.warn("step() called after the episode ended (terminated or truncated); call "
                          "reset(). The episode stays ended.", stacklevel=2)
            obs, _, terminated, truncated, info = self._last_transition
            return obs, 0.0, terminated, truncated, dict(info)
        picking.begin_step(float(a[6]))  # the tool's command (suction: the valve; hand: fingers)
        self.posture.follow(d.site_xmat[w.tool_site, 2::3])  # the tool's approach axis (its site's +z)
        try:
            d.ctrl[:self._n_joints] = self.ik.step(a[:6] * self._twist_scale, d.qpos[w.arm_qadr])
        except NoSolutionFound:  # e.g. pressed against a joint's limit: hold the last command
            pass
        badqacc = d.warning[_BADQACC]
        for _ in range(self.ctrl_cfg.substeps):
            mujoco.mj_step(m, d)
            if picking.needs_substep_check():
                if badqacc.number > 0:
                    break
                picking.after_substep()
        if badqacc.number > 0 or not np.isfinite(d.qpos).all():
            ep.unstable = True
        picking.after_step()
        info = picking.evaluate(self.control_dt)
        terminated = (info["target_picked"] or (self._end_on_bruise and bool(ep.bruised))
                      or (ep.target_detached and ep.grip_lost)
                      or (self.end_on_dead_end and picking.dead_end())
                      or self.done)
        truncated = ep.unstable
        self.done = terminated or truncated
        reward, terms = self._reward(info["is_success"])
        info.update({f"reward_{k}": v for k, v in terms.items()}, start=self._start_label)
        if ep.unstable:
            mujoco.mj_resetData(m, d)  # keep later calls finite; the episode is over
            mujoco.mj_forward(m, d)
        if self.render_mode == "human":
            self.render()
        obs = self._obs()
        if self.done:
            self._last_transition = (obs, reward, terminated, truncated, dict(info))
        return obs, reward, terminated, truncated, info

    def _settle(self) -> None:
        """Run the world ``PickPhysicsParams.settle_time`` with the arm holding still (the soft
        welds take up gravity; after an earlier pick in the same world, what it left moving comes
        to rest), the live root springs applied as in a control step; no picking rule is
        judged."""
        m, d, roots = self.world.model, self.world.data, self.picking.roots
        for _ in range(max(1, int(round(self.params.settle_time / m.opt.timestep)))):
            mujoco.mj_step(m, d)
            if roots is not None and roots.any_active:
                roots.apply()

    def start_pick(self, target: int, estimate: PoseEstimate, q_start: np.ndarray | None = None,
                   end_on_bruise: bool = True) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Begin picking mushroom ``target`` in the world as it stands, instead of on a new bed
        (``reset``): a harvest (:mod:`sms3d_env.harvest`) picks one mushroom after another in
        one world. ``step`` then runs the pick; its ``info`` and ``time_s`` count from here.

        Nothing of the bed is rebuilt: mushrooms picked, knocked off, moved or bruised stay as
        they are, and the roots (which still hold, their springs' state) carry over. What starts
        anew is the pick's own: the picking model's events (bruises, disturbed neighbours,
        detachments) for ``target``, the tool (nothing held: call it with the grip released),
        the IK and its posture target for ``estimate`` (the target's estimated pose, in the
        observation), and the ``pick`` camera, aimed at the target. The arm starts at rest at
        ``q_start`` (its joints in ``robot.joints``' order; None: where it stands), and the world
        settles for ``settle_time`` first, as at reset. A target already off its roots counts as
        detached from the start (a lift picks it). ``end_on_bruise``: a bruised cap ends the pick
        as at reset; False: it goes on (a harvester's picker cannot see a bruise).

        Nothing is drawn from the env's random generator. RuntimeError before the first reset or
        with a mushroom held; ValueError for a target not in the bed or a ``q_start`` of the wrong
        size.
        """
        if self.world is None:
            raise RuntimeError("call reset() before start_pick(): it builds the bed's world")
        w, previous = self.world, self.picking
        m, d = w.model, w.data
        n = len(w.body_ids)
        if isinstance(target, bool) or not isinstance(target, (int, np.integer)) or not 0 <= target < n:
            raise ValueError(f"start_pick: target must be a mushroom of the bed, an integer in [0, {n}), got {target!r}")
        if previous.state.grip >= 0:
            raise RuntimeError(f"start_pick: the tool still holds mushroom {previous.state.grip}; release it first")
        target = int(target)
        q = d.qpos[w.arm_qadr].copy() if q_start is None else np.asarray(q_start, float)
        if q.shape != (self._n_joints,) or not np.isfinite(q).all():
            raise ValueError(f"start_pick: q_start must hold {self._n_joints} finite joint values, got {q_start!r}")
        rule = self.target_rule
        cap_top = d.site_xpos[w.cap_top_sites[target]].copy()
        axis = d.xmat[w.body_ids[target]].reshape(3, 3)[:, 2].copy()
        reachable = pickable(cap_top, axis, self.reach, rule.max_tilt_deg)
        self.picking = PickingModel(w, self.params, target, reachable, self.suction_mode == "latched",
                                    roots=previous.roots)
        ep = self.picking.state
        if w.root_eq[target] >= 0 and not d.eq_active[w.root_eq[target]]:
            ep.target_detached = True  # knocked off its roots by an earlier pick
        self.target_pose = np.concatenate([estimate.cap_top, estimate.stem_axis])
        aim_pick_camera(m, cap_top, self.robot_cfg.mount_pos)
        d.qpos[w.arm_qadr], d.qvel[w.arm_dadr] = q, 0.0
        d.ctrl[:self._n_joints] = q
        self.picking.tool.reset()
        self.posture.reset(q, estimate.cap_top, estimate.stem_axis)
        mujoco.mj_forward(m, d)
        self._settle()
        self.picking.settled()
        self.done, self._end_on_bruise, self._start_label = False, bool(end_on_bruise), "current"
        if self.render_mode == "human":
            self.render()
        return self._obs(), {**self.picking.evaluate(self.control_dt), "start": self._start_label}

    def _model_key(self, slot: int | None, target: int) -> tuple[int, int | None] | None:
        """The compiled-model cache key of a pool bed: its slot and, where only the mushrooms near
        the target are free (``free_radius``), the target; with every mushroom free the model is
        the same whatever the target, so one model serves every target of the bed."""
        if slot is None:
            return None
        return slot, (None if self.scene_source.config.free_radius is None else target)

    def set_pregrasp_start(self, share: float) -> None:
        """Start this share of episodes (a probability in [0, 1]) on the way to a pre-grasp pose
        from the next reset on: ``start=PregraspStart(share)`` (a training schedule reaches it
        through ``VecEnv.env_method``)."""
        check_share("share", share)
        self.start = PregraspStart(float(share))

    def failure_cause(self) -> str | None:
        """Why the episode is not (yet) a success, or None on success."""
        return self.picking.failure_cause()

    def _reward(self, success: bool) -> tuple[float, dict[str, float]]:
        """The step's reward and its terms (the staged reward's; empty for the others)."""
        w, ep = self.world, self.picking.state
        d = w.data
        s = RewardState(
            tool_pos=d.site_xpos[w.tool_site], tool_axis=d.site_xmat[w.tool_site, 2::3],
            goal_cap_top=self.target_pose[:3], goal_axis=self.target_pose[3:],
            gripped_target=ep.grip == ep.target, target_detached=ep.target_detached,
            lift=self.picking.lift(), lift_goal=self.params.lift_height, success=success,
            bruised=bool(ep.bruised), root_utilisation=ep.root_util,
            steps_left=self.reward_config.horizon - self.steps)
        if self.reward_config.kind == "staged":
            terms = reward_terms(s)
            return sum(terms.values()), terms
        return compute_reward(s, self.reward_config.kind), {}

    # ------------------------------------------------------------------ observation
    def _obs(self) -> dict[str, np.ndarray]:
        w = self.world
        d = w.data
        pos = d.site_xpos[w.tool_site]
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, d.site_xmat[w.tool_site])
        # One flat vector, one finiteness check, then views per entry (small-array numpy calls
        # dominate here, not arithmetic).
        parts = [d.qpos[w.arm_qadr], d.qvel[w.arm_dadr], pos, quat, self.picking.tool.observation(),
                 self.target_pose, self.target_pose[:3] - pos]
        if self.task_obs:
            parts += self._task_obs()
        flat = np.concatenate(parts)
        if not np.isfinite(flat).all():
            flat = np.nan_to_num(flat)
        obs = {k: flat[sl] for k, sl in self._obs_slices.items()}
        if self.image_obs is not None:
            (h, wd), camera = self.image_obs.size, self.image_obs.camera
            obs["rgb"] = self._render(h, wd, camera, depth=False)
            obs["depth"] = self._render(h, wd, camera, depth=True)[..., None].astype(np.float32)
        return obs

    def _task_obs(self) -> list[np.ndarray]:
        """The ``task_obs`` entries (see :mod:`sms3d_env.task_obs`)."""
        w, ep = self.world, self.picking.state
        d = w.data
        rot = d.site_xmat[w.tool_site]
        cap_top, axis = self.target_pose[:3], self.target_pose[3:]
        sealed = ep.seal_step >= 0
        twist = twist_about(axis, ep.seal_tool_x, rot[0::3]) if sealed else 0.0
        since_seal = (self.steps - ep.seal_step) * self.control_dt if sealed else 0.0
        return [tool_in_target(d.site_xpos[w.tool_site], rot[2::3], cap_top, axis),
                np.array([self.steps * self.control_dt, since_seal, twist]),
                d.sensordata[w.wrench_adr]]

    # ------------------------------------------------------------------ rendering
    def _disown_renderers(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers = {}

    @property
    def viewer(self) -> PassiveViewer | None:
        """``render_mode="human"``'s window (``viewer.is_running``); None in the other modes."""
        return self._viewer

    def _render(self, h: int, w: int, camera: str, depth: bool) -> np.ndarray:
        r = self._renderers.get((h, w))
        if r is None:
            r = self._renderers[(h, w)] = open_renderer(self.model, h, w)
        if depth:
            r.enable_depth_rendering()
        else:
            r.disable_depth_rendering()
        r.update_scene(self.data, camera=camera)
        return r.render().copy()

    def render(self) -> np.ndarray | None:
        """``rgb_array``: (H, W, 3) uint8; ``depth_array``: (H, W) float32 metres, both of
        ``render_camera.size`` from the camera ``render_camera.name``; ``human``: show the viewer
        (None); None before the first reset."""
        if self.render_mode is None or self.world is None:
            return None
        if self.render_mode == "human":
            m, d = self.world.model, self.world.data
            cam = m.camera(self.render_camera.name).id
            eye, back = d.cam_xpos[cam], d.cam_xmat[cam].reshape(3, 3)[:, 2]
            self._viewer.show(m, d, eye, eye - PICK_CAMERA_DISTANCE * back)
            return None
        h, w = self.render_camera.size
        return self._render(h, w, self.render_camera.name, depth=self.render_mode == "depth_array")

    def close(self) -> None:
        self._disown_renderers()
        if self._viewer is not None:
            self._viewer.close()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderers"] = {}  # GL contexts do not pickle (World carries its MjData's state)
        state["_viewer"] = None  # nor does a window
        return state

