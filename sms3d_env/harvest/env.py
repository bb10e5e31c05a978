"""``SMS3DHarvest-v0``: harvest one bed, mushroom after mushroom, in one world that lasts the episode.

The env holds the gym API and the episode's bookkeeping; the picks are ``SMS3DPickEnv``'s, run
by the scripted picker in the world as the earlier picks left it (``SMS3DPickEnv.start_pick``),
the scan is :mod:`sms3d_env.harvest.scan`, the timed moves :mod:`sms3d_env.harvest.motion`, the
scores :mod:`sms3d_env.harvest.scores`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium import spaces

from generator.errors import ConfigError
from sms3d_env.env_args import pose_error_of
from sms3d_env.harvest.config import HarvestConfig
from sms3d_env.harvest.motion import Motion
from sms3d_env.harvest.scan import (
    BED_FEATURES,
    CANDIDATE_FEATURES,
    Detection,
    current_scene,
    detect,
    in_view,
    neighbour_features,
)
from sms3d_env.harvest.scores import BedTally
from sms3d_env.pick_env import SMS3DPickEnv
from sms3d_env.pickers.scripted import ScriptedPicker
from sms3d_env.pose_sources import PoseEstimate, PoseSource, make_pose_source
from sms3d_env.records import record_of
from sms3d_env.targets import pickable

__all__ = ["MaskedActionError", "SMS3DHarvestEnv"]

#: The bed when ``scene`` gives none: 50 mushrooms, the generator's mix of cap sizes.
DEFAULT_SCENE = {"placement": {"num_mushrooms": 50}}
#: Where collected mushrooms are parked with a tray on the head (``collection_point=None``): (x, y)
#: off the bed, outside the terrain patch (m); at the travel height.
OFF_BED = (0.38, 0.0)


class MaskedActionError(ValueError):
    """An action that ``action_masks()`` forbids now: ``action`` and ``reason`` (an empty slot, a
    candidate collected since the scan, one the IK cannot reach)."""

    def __init__(self, action: int, reason: str) -> None:
        super().__init__(f"action {action} is masked: {reason} (see action_masks())")
        self.action, self.reason = action, reason

    def __reduce__(self):  # picklable across subprocess vector envs
        return (type(self), (self.action, self.reason))


class SMS3DHarvestEnv(gym.Env):
    """Clear one bed: which mushrooms to pick, in what order, and when to look again.

    ## Action space
    ``Discrete(K + 2)``, K = ``HarvestConfig.max_candidates``: ``i < K`` picks candidate slot
    ``i`` of the last scan (the travel there, the scripted picker's pick, the carry to the
    collection point when it is picked); ``K`` re-scans the bed; ``K + 1`` stops (terminated).
    ``action_masks()`` (sb3-contrib's MaskablePPO convention) allows the slots that hold a
    candidate not collected since the scan and reachable; re-scan and stop always. A masked
    action raises ``MaskedActionError``; one outside the space ``ValueError``.

    ## Observation space
    A ``Dict``, float32: ``candidates`` (K x 14, one row per slot, zeros where empty:
    ``scan.CANDIDATE_FEATURES``: available, estimated cap top and stem axis, cap diameter, gap to
    the nearest detected cap, close neighbours, approach blocked, distance from the tool,
    reachable, attempts since the scan) and ``bed`` (9: ``scan.BED_FEATURES``: time, picked,
    attempts, scans, failed attempts, candidates available, tool position). Estimates only: no
    true pose, root or seal load.

    ## Reward
    ``reward_clean`` per harvest-ready mushroom picked clean, minus ``reward_damage`` per
    mushroom newly damaged, minus ``reward_per_second`` per simulated second; the terms in
    ``info["reward_clean"|"reward_damage"|"reward_time"]``.

    ## Episode end
    Terminated by the stop action; truncated after ``max_actions`` actions, or when the
    simulation went unstable (``info["unstable_simulation"]``).

    ``info``: the bed's scores so far (``BedTally.summary``: yield, picked, damage, missed,
    mushrooms per hour, scans, attempts, retries, the time's parts), the reward's terms,
    ``last_pick`` (target, collected, clean, failure cause, steps, time; None after a scan or
    stop), ``candidates`` (each slot's true mushroom id, -1 empty: for scoring, not an
    observation), ``candidates_dropped``; at the episode's end ``summary`` (the same scores).

    Arguments and version history: docs/harvest.md.
    """

    metadata = {"render_modes": ["rgb_array", "depth_array"], "render_fps": 25}

    def __init__(self, render_mode: str | None = None, scene: Any = None, robot: Any = None,
                 pose_source: str | PoseSource = "oracle", pose_error_deg: float | tuple[float, float] = 0.0,
                 physics: Any = None, controller: Any = None, harvest: HarvestConfig | Mapping[str, Any] | None = None,
                 render_camera: Any = "side") -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ConfigError("render_mode", f"must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        if isinstance(pose_source, str) and pose_source == "perception":
            raise ConfigError("pose_source", "'perception' is not available in SMS3DHarvest-v0 yet (a scan would "
                                             "render the current bed for the shipped pipeline); use 'oracle', "
                                             "'noisy' or a callable pose source")
        if isinstance(pose_source, str) and pose_source not in ("oracle", "noisy"):
            raise ConfigError("pose_source", f"must be 'oracle', 'noisy' or a callable, got {pose_source!r}")
        error = pose_error_of(pose_error_deg)
        if error != 0.0 and pose_source != "noisy":
            raise ConfigError("pose_error_deg", f"sets the 'noisy' source's error; with pose_source={pose_source!r} "
                                                "it would be ignored")
        self.config = HarvestConfig() if harvest is None else record_of(HarvestConfig, harvest, "harvest")
        self.render_mode = render_mode
        self.pick = SMS3DPickEnv(render_mode=render_mode, robot=robot, scene=DEFAULT_SCENE if scene is None else scene,
                                 physics=physics, controller=controller, render_camera=render_camera)
        if self.pick.tool != "suction":
            raise ConfigError("robot", "SMS3DHarvest-v0 picks with the suction tool only (the hand's grasp is not "
                                       "carried from one pick to the next)")
        self.pose_source = make_pose_source(pose_source, error)
        self.picker = ScriptedPicker.for_env(self.pick)
        c = self.config
        self.motion = Motion(c.travel_speed, c.travel_accel, c.travel_height)
        self.collection_point = None if c.collection_point is None else np.array([*c.collection_point,
                                                                                   c.travel_height])
        self.park_point = np.array([*(c.collection_point or OFF_BED), c.travel_height])
        k = c.max_candidates
        self.RESCAN, self.STOP = k, k + 1
        self.action_space = spaces.Discrete(k + 2)
        self.observation_space = spaces.Dict({
            "candidates": spaces.Box(-np.inf, np.inf, (k, len(CANDIDATE_FEATURES)), np.float32),
            "bed": spaces.Box(-np.inf, np.inf, (len(BED_FEATURES),), np.float32),
        })
        self.tally: BedTally | None = None
        self._done = True

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """A new bed (``options={"scene": k}`` picks one of a fixed list), the robot at home, and
        the first scan (counted: a harvester looks before it picks)."""
        super().reset(seed=seed)
        pick_options = {"scene": options["scene"]} if options and "scene" in options else None
        self.pick.reset(seed=int(self.np_random.integers(2**31 - 1)), options=pick_options)
        w = self.pick.world
        c = self.config
        self.tally = BedTally(np.array([inst.cap_diameter >= c.harvest_diameter for inst in self.pick.scene.instances]))
        self.collected: set[int] = set()
        self.attempted: set[int] = set()
        self.tool_pos = w.data.site_xpos[w.tool_site].copy()
        self.actions, self.unstable, self._done = 0, False, False
        self._scan()
        return self._obs(), self._info(None, {"clean": 0.0, "damage": 0.0, "time": 0.0})

    def step(self, action: Any):
        if self.tally is None:
            raise RuntimeError("call reset() before step()")
        if self._done:
            raise RuntimeError("step() after the episode ended (stopped or truncated); call reset()")
        a = self._check_action(action)
        t0 = self.tally.time_s
        last_pick, clean_ready, damaged = None, False, set()
        if a < self.RESCAN:
            last_pick, clean_ready, damaged = self._pick(a)
        elif a == self.RESCAN:
            self._scan()
        self.actions += 1
        terminated = a == self.STOP
        truncated = not terminated and (self.actions >= self.config.max_actions or self.unstable)
        c = self.config
        terms = {"clean": c.reward_clean * float(clean_ready), "damage": -c.reward_damage * len(damaged),
                 "time": -c.reward_per_second * (self.tally.time_s - t0)}
        info = self._info(last_pick, terms)
        self._done = terminated or truncated
        if self._done:
            info["summary"] = self.tally.summary()
        return self._obs(), float(sum(terms.values())), terminated, truncated, info

    def action_masks(self) -> np.ndarray:
        """(K + 2,) bool: the actions allowed now (sb3-contrib's MaskablePPO reads it, through a
        vector env's ``env_method``)."""
        mask = np.zeros(self.action_space.n, bool)
        n = len(self.candidates)
        mask[:n] = ~self.taken[:n] & self.reachable[:n]
        mask[self.RESCAN] = mask[self.STOP] = True
        return mask

    def _check_action(self, action: Any) -> int:
        a = np.asarray(action)
        if a.shape not in ((), (1,)) or not np.issubdtype(a.dtype, np.integer):
            raise ValueError(f"action must be one integer in [0, {self.action_space.n}), got {action!r}")
        a = int(a.reshape(()))
        if not 0 <= a < self.action_space.n:
            raise ValueError(f"action must be in [0, {self.action_space.n}), got {a}")
        if not self.action_masks()[a]:
            if a >= len(self.candidates):
                reason = f"slot {a} holds no candidate (the last scan found {len(self.candidates)})"
            elif self.taken[a]:
                reason = f"candidate {a} was collected since the last scan"
            else:
                reason = f"candidate {a} is not reachable (the IK finds no pose, or it leans past max_tilt_deg)"
            raise MaskedActionError(a, reason)
        return a

    # ------------------------------------------------------------------ scan
    def _scan(self) -> None:
        """Look at the bed as it stands: detections of every mushroom in view, the candidates
        (estimated cap at least the harvest size; the first K), their reachability."""
        c, pick = self.config, self.pick
        now = current_scene(pick.scene, pick.world)
        self.detections = detect(now, in_view(now, self.collected), self.pose_source, self.np_random)
        ready = [d for d in self.detections if d.cap_diameter >= c.harvest_diameter]
        self.candidates_dropped = max(0, len(ready) - c.max_candidates)
        self.candidates: list[Detection] = ready[:c.max_candidates]
        k = c.max_candidates
        self.taken = np.zeros(k, bool)
        self.slot_attempts = np.zeros(k, int)
        self.reachable = np.zeros(k, bool)
        self.reachable[:len(self.candidates)] = [self._reachable(det) for det in self.candidates]
        self.tally.scans += 1
        self.tally.time["scan"] += c.scan_time
        self._neighbours = None

    def _reachable(self, det: Detection) -> bool:
        return pickable(det.cap_top, det.axis / np.linalg.norm(det.axis), self.pick.reach, self.config.max_tilt_deg)

    # ------------------------------------------------------------------ pick
    def _pick(self, slot: int) -> tuple[dict[str, Any], bool, set[int]]:
        """Travel to candidate ``slot``, pick it with the scripted picker in the world as it
        stands, carry it to the collection point if picked; the pick's outcome, whether it was a
        harvest-ready mushroom picked clean, and the mushrooms it damaged."""
        c, pick, tally = self.config, self.pick, self.tally
        det = self.candidates[slot]
        k = det.instance
        tally.attempts += 1
        tally.retries += k in self.attempted
        self.attempted.add(k)
        self.slot_attempts[slot] += 1
        axis = det.axis / np.linalg.norm(det.axis)
        start = det.cap_top + axis * c.pick_clearance
        tally.time["travel"] += self.motion.time(self.tool_pos, start)
        # The timed move ends with the cup on the estimated axis above the cap (None: no IK
        # solution there, so the pick starts where the arm stands).
        q_start = pick.reach.solve(det.cap_top, axis, (c.pick_clearance,))
        d = pick.world.data
        t_before = float(d.time)
        obs, _ = pick.start_pick(k, PoseEstimate(det.cap_top, det.rotation), q_start, end_on_bruise=False)
        settle = float(d.time) - t_before
        self.picker.reset()
        steps, picking = 0, pick.picking
        while steps < c.max_pick_steps:
            obs, _, terminated, truncated, _ = pick.step(self.picker(obs))
            steps += 1
            if terminated or truncated:
                break
            if self.picker.phase == "lift" and obs["suction"][1] < 0.5:
                break  # lifting with nothing on the cup: the picker gave up, or the seal let go
        tally.time["pick"] += settle + steps * pick.control_dt
        ep = picking.state
        self.unstable = bool(ep.unstable)
        collected = picking.picked() and not self.unstable
        cause = None if collected else pick.failure_cause()
        if collected:
            self._collect(k)
            self.taken[slot] = True
        else:
            tally.failed_attempts += 1
            if ep.grip >= 0:
                picking.tool.release()  # valve off: what the cup holds drops where it is
            self.tool_pos = pick.world.data.site_xpos[pick.world.tool_site].copy()
        clean, damaged = tally.record_pick(k, collected, set(ep.bruised), set(ep.detached), set(ep.disturbed))
        self._neighbours = None
        last = {"target": k, "collected": collected, "clean": clean, "failure_cause": cause, "steps": steps,
                "time_s": settle + steps * pick.control_dt}
        return last, clean and bool(tally.ready[k]), damaged

    def _collect(self, k: int) -> None:
        """Carry picked mushroom ``k`` to the collection point (with a tray on the head: none),
        drop it there, and take it out of the bed: it is parked at the collection point (with a
        tray on the head, at ``OFF_BED``), gravity compensated, as in a tray the simulation does
        not model, and collides with nothing, so it can neither touch the bed nor be seen in it
        again."""
        pick, c = self.pick, self.config
        w = pick.world
        m, d = w.model, w.data
        self.tool_pos = d.site_xpos[w.tool_site].copy()
        if self.collection_point is not None:
            self.tally.time["carry"] += self.motion.time(self.tool_pos, self.collection_point)
            self.tool_pos = self.collection_point.copy()
        self.tally.time["carry"] += c.drop_time
        pick.picking.tool.release()
        b = w.body_ids[k]
        for g in (w.cap_geoms[k], w.stem_geoms[k]):
            m.geom_contype[g] = m.geom_conaffinity[g] = 0
        m.body_contype[b] = m.body_conaffinity[b] = 0
        m.body_gravcomp[b] = 1.0
        joint = m.body_jntadr[b]
        qadr, dadr = m.jnt_qposadr[joint], m.jnt_dofadr[joint]
        d.qpos[qadr:qadr + 3] = self.park_point
        d.qvel[dadr:dadr + 6] = 0.0
        mujoco.mj_forward(m, d)
        self.collected.add(k)

    # ------------------------------------------------------------------ observation
    def _obs(self) -> dict[str, np.ndarray]:
        k, n = self.config.max_candidates, len(self.candidates)
        rows = np.zeros((k, len(CANDIDATE_FEATURES)), np.float32)
        if n:
            if self._neighbours is None:  # the harvester knows what it collected since the scan
                seen = [det for det in self.detections if det.instance not in self.collected]
                index = {det.instance: j for j, det in enumerate(seen)}
                table = neighbour_features(seen)
                self._neighbours = np.array([table[index[det.instance]] if det.instance in index else np.zeros(3)
                                             for det in self.candidates])
            tops = np.array([det.cap_top for det in self.candidates])
            axes = np.array([det.axis / np.linalg.norm(det.axis) for det in self.candidates])
            rows[:n] = np.column_stack([
                ~self.taken[:n], tops, axes, [det.cap_diameter for det in self.candidates], self._neighbours,
                np.linalg.norm(tops[:, :2] - self.tool_pos[:2], axis=1), self.reachable[:n], self.slot_attempts[:n],
            ])
        t = self.tally
        bed = np.array([t.time_s, len(t.collected), t.attempts, t.scans, t.failed_attempts,
                        int((~self.taken[:n]).sum()), *self.tool_pos], np.float32)
        return {"candidates": rows, "bed": bed}

    def _info(self, last_pick: dict[str, Any] | None, terms: dict[str, float]) -> dict[str, Any]:
        slots = np.full(self.config.max_candidates, -1)
        slots[:len(self.candidates)] = [det.instance for det in self.candidates]
        return {**self.tally.summary(), **{f"reward_{k}": v for k, v in terms.items()}, "last_pick": last_pick,
                "candidates": slots, "candidates_dropped": self.candidates_dropped,
                "unstable_simulation": self.unstable}

    # ------------------------------------------------------------------ rendering
    def render(self) -> np.ndarray | None:
        """The pick env's ``render()`` of the world as it stands (``render_camera``, by default
        the fixed ``"side"`` view); None before the first reset or without a render mode."""
        return self.pick.render()

    def close(self) -> None:
        self.pick.close()
