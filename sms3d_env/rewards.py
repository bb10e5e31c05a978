"""Rewards: dense shaping (approach, axis alignment, seal, detach, lift), sparse success, and the
staged reward of the training env (bounded per step, maximal at success).

Every reward is a pure function of a ``RewardState`` record; ``reward_terms`` returns the staged
reward's terms, which the env reports in ``info`` (``reward_<term>``). ``RewardConfig`` is the
env's ``reward_type`` argument.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sms3d_env.records import check_choice, check_int

REWARD_TYPES = ("dense", "sparse", "staged")
# Staged reward: the floor of each stage (pre-seal approach, sealed with the root holding,
# detached and held); success pays 1, the per-step maximum.
STAGE_FLOORS = {"approach": 0.0, "sealed": 0.4, "detached": 0.6}
APPROACH_WEIGHT, ROOT_WEIGHT, LIFT_WEIGHT = 0.3, 0.2, 0.3
# tanh scales. Reach: the mean of a coarse term (5/m, still sloped 20 cm away, where the arm
# starts) and a fine one (30/m: 5 mm from the cap top costs 14 % of it), so that the reward is
# steep where precision matters without going flat far away. Alignment: 5 degrees off the axis
# costs 25 % (the seal cone is 20 degrees: the term is steep inside it).
REACH_SCALES = (5.0, 30.0)  # 1/m
ALIGN_SCALE = 3.0  # 1/rad


@dataclass(frozen=True)
class RewardConfig:
    """The env's reward (its ``reward_type`` argument; a kind alone is ``RewardConfig(kind)``).

    Attributes:
        kind: ``"dense"`` (default), ``"sparse"`` or ``"staged"`` (``REWARD_TYPES``).
        horizon: the control steps per episode that the staged reward's success bonus assumes
            (the registered time limit, 250): the success step also pays the steps left until it.
    """

    kind: str = "dense"
    horizon: int = 250

    def __post_init__(self) -> None:
        check_choice("RewardConfig.kind", self.kind, REWARD_TYPES)
        check_int("RewardConfig.horizon", self.horizon, 1)


@dataclass(frozen=True)
class RewardState:
    tool_pos: np.ndarray
    tool_axis: np.ndarray  # cup +z (approach direction)
    # The pose the shaping pulls towards: the *estimated* cap top and stem axis (the observation's).
    goal_cap_top: np.ndarray
    goal_axis: np.ndarray
    gripped_target: bool
    target_detached: bool
    lift: float  # m the target's cap top rose since reset
    lift_goal: float
    success: bool
    bruised: bool
    root_utilisation: float = 0.0  # target root load / its detachment capacity (>= 1 detaches)
    steps_left: int = 0  # the staged success bonus: control steps until the time limit


def compute_reward(s: RewardState, reward_type: str) -> float:
    """Sparse: 0 on success, -1 otherwise (Gymnasium-Robotics convention).

    Dense: -distance to the goal cap top (m) + 0.1 x alignment of the cup axis with the goal
    stem axis (the estimated pose) + 0.5 sealed on the
    target + 1 detached *and held* + 2 x lift fraction while held + 5 success - 2 bruise. The
    detach and lift terms pay only while the cup holds the target: paid for detachment alone,
    PPO learned to knock targets off their roots and collect the bonus every step without ever
    holding one.

    Staged: see ``reward_terms``; the sum of its terms.
    """
    if reward_type == "sparse":
        return 0.0 if s.success else -1.0
    if reward_type == "staged":
        return sum(reward_terms(s).values())
    dist = math.dist(s.tool_pos, s.goal_cap_top)
    align = -float(s.tool_axis @ s.goal_axis)
    r = -dist + 0.1 * align
    held = s.gripped_target
    r += 0.5 * held + 1.0 * (s.target_detached and held)
    r += 2.0 * min(max(s.lift / s.lift_goal, 0.0), 1.0) * held
    r += 5.0 * s.success - 2.0 * s.bruised
    return r


def reward_terms(s: RewardState) -> dict[str, float]:
    """The staged reward's terms; their sum is the step's reward.

    One stage at a time, each starting where the one before ends (robosuite / ManiSkill3 style):

    | stage | when | reward in |
    | --- | --- | --- |
    | approach | not holding the target | 0.3 x reach x align in [0, 0.3] |
    | sealed | holding the target, root intact | 0.4 + 0.2 x min(root load / capacity, 1) |
    | detached | holding the detached target | 0.6 + 0.3 x lift fraction |
    | success | detached, held, lifted | 1 + ``steps_left`` |

    reach = 1 - mean(tanh(5/m x d), tanh(30/m x d)), d the distance (m) from the tool to the goal
    (estimated) cap top; align = 1 - tanh(3/rad x angle between the cup axis and the goal stem
    axis, reversed). Per step the reward is at most 1, reached only at success; the success step
    also pays ``steps_left`` (the return of holding that maximum until the time limit), so
    finishing early is never worth less than loitering in a stage below it. A bruise pays 0 (it ends the episode). The root load is privileged simulation state; it
    shapes the reward only and is never observed.
    """
    if s.bruised:
        return {"stage": 0.0, "progress": 0.0, "success_bonus": 0.0}
    if s.success:
        return {"stage": 1.0, "progress": 0.0, "success_bonus": float(max(s.steps_left, 0))}
    if s.gripped_target and s.target_detached:
        frac = min(max(s.lift / s.lift_goal, 0.0), 1.0)
        return {"stage": STAGE_FLOORS["detached"], "progress": LIFT_WEIGHT * frac, "success_bonus": 0.0}
    if s.gripped_target:
        load = min(max(s.root_utilisation, 0.0), 1.0)
        return {"stage": STAGE_FLOORS["sealed"], "progress": ROOT_WEIGHT * load, "success_bonus": 0.0}
    d = math.dist(s.tool_pos, s.goal_cap_top)
    reach = 1.0 - sum(math.tanh(k * d) for k in REACH_SCALES) / len(REACH_SCALES)
    cos = float(np.clip(-(s.tool_axis @ s.goal_axis) / np.linalg.norm(s.goal_axis), -1.0, 1.0))
    align = 1.0 - math.tanh(ALIGN_SCALE * math.acos(cos))
    return {"stage": STAGE_FLOORS["approach"], "progress": APPROACH_WEIGHT * reach * align,
            "success_bonus": 0.0}

