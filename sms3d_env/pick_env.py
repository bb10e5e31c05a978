"""``SMS3DPick-v1``: pick one mushroom from a synthetic bed with a Cartesian gantry harvester or
a Kinova Jaco, by a suction tool (default) or the Jaco 3-finger hand.

The env holds the gym API only: spaces, reset/step, observation, reward assembly and rendering.
The beds come from :mod:`sms3d_env.scene_source`; the world (scene + robot model and its id
tables) is :mod:`sms3d_env.world`; the picking rules (roots, bruising, neighbours, success and
failure) are :mod:`sms3d_env.picking_model`, called after every physics substep, with each tool's
own (suction: valve, seal, grip; hand: fingers) in :mod:`sms3d_env.tools`; the reward terms are
:mod:`sms3d_env.rewards`.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from generator.gl import open_renderer
from sms3d_env.controller import ControllerConfig, IKController
from sms3d_env.env_args import (
    POSTURE_TARGETS,
    RENDER_MODES,
    SUCTION_MODES,
    check_env_args,
    check_pregrasp_start,
    scene_config_of,
)
from sms3d_env.physics_params import PickPhysicsParams
from sms3d_env.picking_model import FAILURE_CAUSES, PickingModel
from sms3d_env.pose_sources import OraclePose, PoseSource, make_pose_source
from sms3d_env.rewards import RewardState, compute_reward, reward_terms
from sms3d_env.robot import RobotConfig, RobotSpec
from sms3d_env.robots import make_robot
from sms3d_env.scene_source import SceneSource
from sms3d_env.targets import Reachability, select_target
from sms3d_env.task_obs import TASK_OBS_SIZES, tool_in_target, twist_about
from sms3d_env.viewer import PassiveViewer
from sms3d_env.world import CAMERAS, PICK_CAMERA, PICK_CAMERA_DISTANCE, World, build_world

__all__ = ["FAILURE_CAUSES", "POSTURE_TARGETS", "SUCTION_MODES", "SMS3DPickEnv"]

_BADQACC = int(mujoco.mjtWarning.mjWARN_BADQACC)
# posture_target="tool": the posture target is solved again once the tool axis has turned this
# far from the axis it was solved for (an IK solve costs milliseconds; most steps need none).
_POSTURE_RESOLVE_DEG = 5.0
# State observation entries and their sizes, in the order of the flat vector they are cut from.
_OBS_SIZES = {"joint_pos": 6, "joint_vel": 6, "tool_pose": 7, "suction": 3, "target_pose": 6,
              "target_rel": 3}


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

    mink's differential IK turns the twist into joint targets every ``control_dt``. NaN/inf raise.

    ## Observation space
    A ``Dict`` (SB3's ``MultiInputPolicy``); all float64 unless noted:

    | key | size | content |
    | --- | --- | --- |
    | ``joint_pos``, ``joint_vel`` | 6, 6 | arm joints (rad, rad/s) |
    | ``tool_pose`` | 7 | tool site position (m) and quaternion (w, x, y, z) |
    | ``suction`` | 3 | suction: (on, sealed, seal load / capacity); hand: (closure 0–1, holding with ≥ 2 fingers, finger force on the target N) |
    | ``target_pose`` | 6 | the *estimated* cap top (m) and stem axis (from the pose source) |
    | ``target_rel`` | 3 | estimated cap top − tool position (m) |
    | ``tool_in_target``, ``progress``, ``wrist_wrench`` | 7, 3, 6 | with ``task_obs=True``: see :mod:`sms3d_env.task_obs` |
    | ``rgb``, ``depth`` | H × W × 3 uint8, H × W × 1 float32 | with ``image_obs=True`` (``camera``, by default ``"overhead"``) |

    Nothing in the observation is privileged: no true pose, no root or seal loads beyond what a
    vacuum sensor reports.

    ## Reward
    ``"dense"`` (default), ``"sparse"`` (0 on success, −1 otherwise) or ``"staged"`` (bounded per
    step, maximal at success; terms in ``info["reward_stage"|"reward_progress"|"reward_success_bonus"]``),
    see :mod:`sms3d_env.rewards`. Their approach terms pull towards the estimated pose
    (``reward_pose="truth"``: towards the true one); the staged success bonus is the steps left
    (``success_payoff="fixed"``: the horizon, whenever the success comes).

    ## Episode end
    | | when |
    | --- | --- |
    | terminated, success | target detached, held, lifted ``PickPhysicsParams.lift_height`` |
    | terminated, failure | a cap bruised; the detached target's grip lost; with ``end_on_dead_end``: the target knocked off and not held, or a latched seal on a neighbour |
    | truncated | the simulation went unstable; the registered time limit (250 steps) |

    ``info``: ``is_success``, ``failure_cause`` (one of ``FAILURE_CAUSES``), ``target``,
    ``reachable``, ``gripped``, ``gripped_target``, ``target_detached``, ``bruised``,
    ``neighbours_disturbed``, ``lift``, ``unstable_simulation`` (the picking model's
    ``evaluate()``), ``start`` (``"home"``, or ``"pregrasp"`` for a ``pregrasp_start`` reset),
    ``time_s`` (simulated seconds since reset; at success, the pick's cycle time), plus the
    staged reward's terms. ``failure_cause="not_reached"``: the tool never came within 1 cm of
    the target's true cap top (the approach stopped short); ``"no_seal"``: it did, and no seal
    formed.

    ## Version history
    - v1: the robot is physically honest. A Cartesian gantry harvester (``robot="gantry"``, the
      default) or a Jaco hanging above the bed (``robot="jaco"``), every link of either
      colliding with the soil and with every mushroom; every mushroom is free and rooted
      (``free_radius=None``), so any link that touches a cap is judged by the same bruise and
      disturbed-neighbour rules as the tool. ``info`` gains ``time_s``; the failure cause
      ``not_reached`` separates approaches that stopped short from seals that failed.
    - v0: the Jaco beside the bed below the soil line; its base, shoulder, upper arm, forearm and
      first wrist link collide with nothing, and only the mushrooms within 10 cm of the target
      collide with anything (``free_radius=0.10``). Superseded by v1; its measurements stay in the
      results history.

    Args:
        render_mode: ``"rgb_array"``, ``"depth_array"`` (metric depth in metres) or ``"human"``
            (MuJoCo's passive viewer, synced at every reset and step, closed by ``close()``; it
            needs a display, see :mod:`sms3d_env.viewer`, else ``DisplayUnavailableError``).
        scene_config: ``generator.SceneConfig`` for a new seeded scene per reset (default: 25
            mushrooms), or its mapping form (``SceneConfig.from_dict``, e.g. ``{"placement":
            {"num_mushrooms": 10}}``), which keeps the env's spec JSON (Minari datasets and RL Zoo
            recipes rebuild the env from it). Ignored when ``scenes`` is given.
        scenes: a fixed list of ``generator.Scene`` objects, or the folder of a ``sms3d generate``
            dataset (checksums verified); one is drawn per reset (``options={"scene": k}``).
        pose_source: ``"oracle"``, ``"noisy"``, ``"perception"`` or a callable
            ``(scene, id, rng) -> PoseEstimate``.
        pose_error_deg, position_noise: the ``"noisy"`` source's rotation error (deg) and
            position noise standard deviation (m); refused with any other source.
        pose_error_range_deg: ``(low, high)``: the ``"noisy"`` source's rotation error drawn per
            episode, uniformly in that range (``UniformNoisyPose``), instead of
            ``pose_error_deg``; a spec that stays JSON where the source object would not.
        target_rule: ``"tallest"``, ``"largest"``, ``"index"`` (with ``target_index``),
            ``"random"``; ``options={"target": i}`` overrides it for one reset.
        reward_type: ``"dense"``, ``"sparse"`` or ``"staged"``.
        physics, controller: the picking model's numbers, the IK's speeds and weights.
        robot: ``"gantry"`` (``SMS3DPick-v1``'s default: the Cartesian harvester of
            :mod:`sms3d_env.gantry`) or ``"jaco"`` (the Kinova Jaco hanging above the bed), or a
            ``GantryConfig`` / ``RobotConfig``; every link of either collides with the soil and
            the mushrooms. ``None``: ``SMS3DPick-v0``'s Jaco, mounted beside the bed with five
            links that collide with nothing.
        control_dt, substeps: control period (s) and physics steps per control step.
        image_obs, image_size, camera: RGB-D observations of ``image_size`` from ``camera``.
            ``camera``: one of ``world.CAMERAS``, for ``render()`` and image observations alike;
            None (default): ``render()`` from ``"pick"`` (placed at each reset beyond the target
            as seen from the robot's mount, looking at its cap top: the tool and the target in
            view with either robot), image observations from ``"overhead"`` (the perception
            camera; the pick camera is aimed with the true pose, a privileged view).
        render_size: ``render()``'s (height, width).
        max_tilt_deg: targets tilted more than this are not chosen.
        free_radius: only mushrooms whose stem base lies within this distance (m) of the
            target's keep a free joint and a root weld (they can be disturbed or detached); the
            others are static bodies, which makes the simulation several times faster. ``None``:
            every mushroom is free.
        tool: ``"suction"`` or ``"hand"``; overrides ``robot.tool`` (default: ``"suction"``).
        suction_mode: ``"momentary"`` (default: any command <= 0 releases the seal) or
            ``"latched"`` (the vacuum valve holds its state: once a seal forms it stays on
            whatever the command, as a picker's valve does after its vacuum switch trips).
        end_on_dead_end: also terminate (as a failure) when the episode can no longer succeed.
        task_obs: add ``tool_in_target``, ``progress`` and ``wrist_wrench``.
        horizon: control steps per episode that the staged reward's success bonus assumes (the
            registered time limit, 250).
        scene_pool, pool_seed: > 0: draw each reset's bed from a pool of this many
            ``scene_config`` beds (seeds ``pool_seed ..``, each generated on first use and kept,
            the compiled models of the most recently drawn beds and targets cached, at most
            ``scene_source.MAX_CACHED_MODELS``) instead of generating a new one.
        posture_target: the IK's null-space posture: ``"estimate"`` (default) a pre-grasp
            configuration solved once per episode for the *estimated* axis; ``"tool"`` solved
            again whenever the tool axis turns more than 5 deg away from the axis of the last
            solve, so a picker that corrects a wrong estimate is not pulled back towards it.
        pregrasp_start: the share of resets (a probability) that start the arm on the way from
            home to a pre-grasp pose instead of at home: the joints at a uniformly drawn fraction
            of the way from home to a configuration with the cup on the *estimated* stem axis
            2–8 cm above the estimated cap top, facing down it, each then moved by
            N(0, 0.01 rad) — start states a real arm reaches by its planner from the same
            estimate. A training option (a reverse curriculum after Florensa et al. 2017,
            "Reverse Curriculum Generation for Reinforcement Learning"): the seal, twist and
            lift are met from the first episodes, and the approach is learned backwards from
            them. 0 (default) always starts at home and draws nothing from the episode's random
            stream. ``info["start"]`` says which start an episode had (``"home"`` or
            ``"pregrasp"``); ``set_pregrasp_start(p)`` changes the share between episodes (a
            training schedule reaches it through ``VecEnv.env_method``).
        reach_lateral_weight: the staged reward's approach funnel: the weight (>= 1) of the
            tool's offset across the estimated stem axis in the reach term's distance (1, the
            default: the plain distance to the estimated cap top). Refused with another reward.
        reward_pose: the pose the dense and staged rewards' approach terms pull towards:
            ``"estimate"`` (default: the pose in the observation) or ``"truth"`` (the target's
            true cap top and stem axis at reset). A training option for pickers trained under
            pose error: shaped towards the estimate, a correction of a wrong estimate (after the
            wrist wrench at touch-down reveals it) costs reward until it seals; shaped towards
            the truth, it pays. The reward is simulation-side (like the root load in the staged
            reward): the observation stays the same either way.
        success_payoff: the staged reward's success bonus: ``"time_left"`` (default) the
            control steps left until ``horizon`` (the return of holding the per-step maximum to
            the time limit: every step saved adds to every success's payoff); ``"fixed"`` always
            ``horizon``, a success's payoff whenever it comes (still never less than loitering in
            a stage below it), so that only the discount, not the bonus, pays for haste: a
            training option for decisions that trade time against success, such as when to start
            a descent. Refused with another reward.

    ``SMS3DPickTrain-v0`` sets the training options: ``suction_mode="latched"``,
    ``reward_type="staged"``, ``end_on_dead_end=True``, ``task_obs=True``.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 25}

    def __init__(
        self,
        render_mode: str | None = None,
        scene_config: Any = None,
        scenes: Sequence[Any] | None = None,
        pose_source: str | PoseSource = "oracle",
        pose_error_deg: float = 0.0,
        position_noise: float = 0.0,
        pose_error_range_deg: Sequence[float] | None = None,
        target_rule: str = "tallest",
        target_index: int = 0,
        reward_type: str = "dense",
        physics: PickPhysicsParams | None = None,
        robot: str | RobotSpec | None = None,
        controller: ControllerConfig | None = None,
        control_dt: float = 0.04,
        substeps: int = 20,
        image_obs: bool = False,
        image_size: tuple[int, int] = (64, 64),
        camera: str | None = None,
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
        posture_target: str = "estimate",
        pregrasp_start: float = 0.0,
        reach_lateral_weight: float = 1.0,
        reward_pose: str = "estimate",
        success_payoff: str = "time_left",
    ) -> None:
        # None: v0's Jaco (five of its links collide with nothing); SMS3DPick-v1 passes a name.
        self.robot_cfg = RobotConfig() if robot is None else make_robot(robot)
        check_env_args(render_mode=render_mode, reward_type=reward_type, control_dt=control_dt,
                       substeps=substeps, tool=tool or self.robot_cfg.tool, suction_mode=suction_mode,
                       horizon=horizon, scene_pool=scene_pool, pool_seed=pool_seed, scenes=scenes,
                       pose_source=pose_source, pose_error_deg=pose_error_deg,
                       position_noise=position_noise, pose_error_range_deg=pose_error_range_deg,
                       target_rule=target_rule, image_size=image_size,
                       render_size=render_size, max_tilt_deg=max_tilt_deg, free_radius=free_radius,
                       scene_config=scene_config, posture_target=posture_target,
                       pregrasp_start=pregrasp_start,
                       reach_lateral_weight=reach_lateral_weight, reward_pose=reward_pose,
                       success_payoff=success_payoff, image_obs=image_obs,
                       end_on_dead_end=end_on_dead_end, task_obs=task_obs)
        if tool is not None:
            self.robot_cfg = replace(self.robot_cfg, tool=tool)
        self.tool = self.robot_cfg.tool
        self.render_mode = render_mode
        self.scene_source = SceneSource(scene_config_of(scene_config), scenes, scene_pool, pool_seed)
        self.pose_source = make_pose_source(pose_source, pose_error_deg, position_noise, pose_error_range_deg)
        self.target_rule, self.target_index = target_rule, target_index
        self.reward_type, self.reach_lateral_weight = reward_type, float(reach_lateral_weight)
        self.reward_pose, self.success_payoff = reward_pose, success_payoff
        self.params = physics or PickPhysicsParams(cup_radius=self.robot_cfg.cup_radius)
        self.ctrl_cfg = controller or ControllerConfig()
        self.control_dt, self.substeps = float(control_dt), substeps
        self.image_obs, self.image_size = bool(image_obs), tuple(image_size)
        if camera is not None and camera not in CAMERAS:
            raise ValueError(f"camera must be None or one of {CAMERAS}, got {camera!r}")
        self.camera, self.render_size = camera, tuple(render_size)
        self.max_tilt_deg = max_tilt_deg
        self.free_radius = free_radius
        self.suction_mode, self.end_on_dead_end = suction_mode, bool(end_on_dead_end)
        self.task_obs, self.horizon = bool(task_obs), horizon
        self.posture_target, self.pregrasp_start = posture_target, float(pregrasp_start)
        self._posture_axis = np.zeros(3)  # the tool axis the posture target was solved for

        self.ik = IKController(self.robot_cfg, self.ctrl_cfg, self.control_dt)
        self.home_q = np.asarray(self.robot_cfg.home_q, float)
        self.reach = Reachability(self.ik.model, self.ik.site, self.ik.arm_qadr, self.home_q)
        self.action_space = spaces.Box(-1.0, 1.0, (7,), np.float32)
        self._twist_scale = np.repeat([self.ctrl_cfg.max_linear_speed, self.ctrl_cfg.max_angular_speed], 3)
        self._obs_sizes = {**_OBS_SIZES, **(TASK_OBS_SIZES if self.task_obs else {})}
        self._obs_slices = _slices(self._obs_sizes)
        obs = {k: spaces.Box(-np.inf, np.inf, (n,), np.float64) for k, n in self._obs_sizes.items()}
        if image_obs:
            h, w = self.image_size
            obs["rgb"] = spaces.Box(0, 255, (h, w, 3), np.uint8)
            obs["depth"] = spaces.Box(0.0, np.inf, (h, w, 1), np.float32)
        self.observation_space = spaces.Dict(obs)
        self.world: World | None = None
        self.picking: PickingModel | None = None
        self.target_pose = np.zeros(6)  # the estimate in the observation: cap top, stem axis
        self._reward_goal = np.zeros(6)  # the pose the reward shapes towards (``reward_pose``)
        self.done = False  # the episode terminated or was truncated
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

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        scene, slot = self.scene_source.draw(self.np_random, options)
        rule, index = ("index", int(options["target"])) if "target" in options else (self.target_rule, self.target_index)
        target, reachable = select_target(scene, rule, self.np_random, self.reach, index=index,
                                          max_tilt_deg=self.max_tilt_deg)
        estimate = self.pose_source(scene, target, self.np_random)
        self.target_pose = np.concatenate([estimate.cap_top, estimate.stem_axis])
        goal = estimate if self.reward_pose == "estimate" else OraclePose()(scene, target, self.np_random)
        self._reward_goal = np.concatenate([goal.cap_top, goal.stem_axis])
        self._disown_renderers()
        self.world = w = build_world(scene, target, self.robot_cfg, self.free_radius,
                                     self.control_dt / self.substeps, self.scene_source.models,
                                     self._model_key(slot, target))
        self.picking = PickingModel(w, self.params, target, reachable, self.suction_mode == "latched")
        self.done = False
        m, d = w.model, w.data
        q_start, self._start = self.home_q, "home"
        if self.pregrasp_start > 0 and self.np_random.random() < self.pregrasp_start:
            q_start = self._pregrasp_configuration(estimate.cap_top, estimate.stem_axis)
            self._start = "pregrasp"
        d.qpos[w.arm_qadr] = q_start
        d.ctrl[:6] = q_start
        self.picking.tool.reset()
        # Posture target of the IK: the arm's configuration at a pre-grasp pose above the
        # *estimated* target (the pose the policy sees). Home holds the cup pointing down near the
        # Jaco's wrist singularity (joint 5 ~ 0, joints 4 and 6 aligned); a posture target at home
        # let the differential IK stall there, centimetres short of some pre-grasp poses.
        q_pre = self.reach.solve(estimate.cap_top, estimate.stem_axis, (0.05, 0.03))
        self.ik.reset(q_start, self.home_q if q_pre is None else q_pre)
        self._posture_axis = -estimate.stem_axis / np.linalg.norm(estimate.stem_axis)
        mujoco.mj_forward(m, d)
        for _ in range(max(1, int(round(self.params.settle_time / m.opt.timestep)))):
            mujoco.mj_step(m, d)
        self.picking.settled()
        if self.render_mode == "human":
            self.render()
        return self._obs(), {**self.picking.evaluate(), "start": self._start, "time_s": 0.0}

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
        if self.done:
            warnings.warn("step() called after the episode ended (terminated or truncated); call "
                          "reset(). The episode stays ended.", stacklevel=2)
        picking.begin_step(float(a[6]))  # the tool's command (suction: the valve; hand: fingers)
        if self.posture_target == "tool":
            self._follow_tool_posture()
        try:
            d.ctrl[:6] = self.ik.step(a[:6] * self._twist_scale, d.qpos[w.arm_qadr])
        except Exception:  # mink raises when the QP has no solution: hold the last command
            pass
        badqacc = d.warning[_BADQACC]
        for _ in range(self.substeps):
            mujoco.mj_step(m, d)
            if picking.needs_substep_check():
                if badqacc.number > 0:
                    break
                picking.after_substep()
        if badqacc.number > 0 or not np.isfinite(d.qpos).all():
            ep.unstable = True
        picking.after_step()
        info = picking.evaluate()
        terminated = (info["is_success"] or bool(ep.bruised) or (ep.target_detached and ep.grip_lost)
                      or (self.end_on_dead_end and picking.dead_end())
                      or self.done)
        truncated = ep.unstable
        self.done = terminated or truncated
        reward, terms = self._reward(info["is_success"])
        # time_s: simulated seconds since reset (at success, the pick's cycle time).
        info.update({f"reward_{k}": v for k, v in terms.items()}, start=self._start,
                    time_s=picking.steps * self.control_dt)
        if ep.unstable:
            mujoco.mj_resetData(m, d)  # keep later calls finite; the episode is over
            mujoco.mj_forward(m, d)
        if self.render_mode == "human":
            self.render()
        return self._obs(), reward, terminated, truncated, info

    def _model_key(self, slot: int | None, target: int) -> tuple[int, int | None] | None:
        """The compiled-model cache key of a pool bed: its slot and, where only the mushrooms near
        the target are free (``free_radius``), the target; with every mushroom free the model is
        the same whatever the target, so one model serves every target of the bed."""
        if slot is None:
            return None
        return slot, (None if self.free_radius is None else target)

    def set_pregrasp_start(self, share: float) -> None:
        """Change ``pregrasp_start`` (a probability in [0, 1]) from the next reset on."""
        check_pregrasp_start(share)
        self.pregrasp_start = float(share)

    def _pregrasp_configuration(self, cap_top: np.ndarray, axis: np.ndarray) -> np.ndarray:
        """``pregrasp_start``: arm joints a uniform fraction of the way from home to a pre-grasp
        configuration (the cup 2–8 cm above the estimated cap top on the estimated axis, facing
        down it), each joint moved by N(0, 0.01 rad) (a few millimetres and about a degree at the
        tool); home where the pre-grasp pose has no IK solution."""
        rng = self.np_random
        q_pre = self.reach.solve(cap_top, axis, (0.08, rng.uniform(0.02, 0.08)))
        if q_pre is None:
            return self.home_q
        q = self.home_q + rng.uniform() * (q_pre - self.home_q)
        return np.clip(q + rng.normal(0.0, 0.01, q.shape), self.reach.lo, self.reach.hi)

    def _follow_tool_posture(self) -> None:
        """``posture_target="tool"``: keep the IK's posture target a pre-grasp configuration for
        the tool's *current* approach axis above the estimated cap top. Measured why: with the
        posture solved once for the estimated axis, the scripted picker driven by the *true* pose
        picked 13 / 20 episodes at 30 deg estimate error (20 / 20 at 0 deg) — the null-space pull
        towards the estimate's arm configuration fights any correction of the axis; following the
        tool, 19 / 20."""
        w = self.world
        z = w.data.site_xmat[w.tool_site].reshape(3, 3)[:, 2]
        if np.degrees(np.arccos(np.clip(z @ self._posture_axis, -1.0, 1.0))) <= _POSTURE_RESOLVE_DEG:
            return
        q = self.reach.solve(self.target_pose[:3], -z, (0.05, 0.03))
        if q is not None:
            self.ik.set_posture(q)
        # A failed solve keeps the old posture but still records the axis it was tried for, so
        # that the next attempt waits for another 5 deg turn instead of repeating every step.
        self._posture_axis = z.copy()

    def failure_cause(self) -> str | None:
        """Why the episode is not (yet) a success, or None on success."""
        return self.picking.failure_cause()

    def _reward(self, success: bool) -> tuple[float, dict[str, float]]:
        """The step's reward and its terms (the staged reward's; empty for the others)."""
        w, ep = self.world, self.picking.state
        d = w.data
        s = RewardState(
            tool_pos=d.site_xpos[w.tool_site], tool_axis=d.site_xmat[w.tool_site, 2::3],
            goal_cap_top=self._reward_goal[:3], goal_axis=self._reward_goal[3:],
            gripped_target=ep.grip == ep.target, target_detached=ep.target_detached,
            lift=self.picking.lift(), lift_goal=self.params.lift_height, success=success,
            bruised=bool(ep.bruised), root_utilisation=ep.root_util,
            steps_left=self.horizon - (self.steps if self.success_payoff == "time_left" else 0),
            lateral_weight=self.reach_lateral_weight)
        if self.reward_type == "staged":
            terms = reward_terms(s)
            return sum(terms.values()), terms
        return compute_reward(s, self.reward_type), {}

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
        if self.image_obs:
            h, wd = self.image_size
            camera = self.camera or "overhead"
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

    @property
    def render_camera(self) -> str:
        """The camera ``render()`` shows: ``camera``, by default ``world.PICK_CAMERA``."""
        return self.camera or PICK_CAMERA

    def _render(self, h: int, w: int, camera: str, depth: bool) -> np.ndarray:
        os.environ.setdefault("MUJOCO_GL", "egl")
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
        ``render_size`` from ``render_camera``; ``human``: show the viewer (None); None before
        the first reset."""
        if self.render_mode is None or self.world is None:
            return None
        if self.render_mode == "human":
            m, d = self.world.model, self.world.data
            cam = m.camera(self.render_camera).id
            eye, back = d.cam_xpos[cam], d.cam_xmat[cam].reshape(3, 3)[:, 2]
            self._viewer.show(m, d, eye, eye - PICK_CAMERA_DISTANCE * back)
            return None
        h, w = self.render_size
        return self._render(h, w, self.render_camera, depth=self.render_mode == "depth_array")

    def close(self) -> None:
        self._disown_renderers()
        if self._viewer is not None:
            self._viewer.close()

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_renderers"] = {}  # GL contexts do not pickle (World carries its MjData's state)
        state["_viewer"] = None  # nor does a window
        return state
