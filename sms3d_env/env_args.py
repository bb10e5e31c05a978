"""Argument checks of ``SMS3DPickEnv``: refuse what the env could not honour or would silently
ignore, with a ``ValueError``/``TypeError`` naming the argument."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sms3d_env.rewards import REWARD_TYPES
from sms3d_env.robot import TOOLS
from sms3d_env.targets import RULES

SUCTION_MODES = ("momentary", "latched")
POSTURE_TARGETS = ("estimate", "tool")
REWARD_POSES = ("estimate", "truth")
SUCCESS_PAYOFFS = ("time_left", "fixed")
RENDER_MODES = ("rgb_array", "depth_array", "human")


def _int_at_least(name: str, v: Any, least: int = 0) -> None:
    """ValueError unless ``v`` is an integer (not a bool) >= ``least``."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < least:
        raise ValueError(f"{name} must be an integer >= {least}, got {v!r}")


def _finite(name: str, v: Any, lo: float, hi: float, what: str) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and lo <= v <= hi):
        raise ValueError(f"{name} must be {what}, got {v!r}")


def _flag(name: str, v: Any) -> None:
    """TypeError unless ``v`` is a bool (numpy's too): by truthiness, ``"no"`` or ``"false"``
    would switch the option on."""
    if not isinstance(v, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(v).__name__} {v!r}")


def check_pregrasp_start(share: Any) -> None:
    _finite("pregrasp_start", share, 0.0, 1.0, "a probability in [0, 1]")


def check_env_args(*, render_mode: Any, reward_type: Any, control_dt: Any, substeps: Any, tool: Any,
                   suction_mode: Any, horizon: Any, scene_pool: Any, pool_seed: Any, scenes: Any,
                   pose_source: Any, pose_error_deg: Any, position_noise: Any, target_rule: Any,
                   pose_error_range_deg: Any = None,
                   image_size: Any, render_size: Any, max_tilt_deg: Any, free_radius: Any,
                   scene_config: Any, posture_target: Any = "estimate", pregrasp_start: Any = 0.0,
                   reach_lateral_weight: Any = 1.0, reward_pose: Any = "estimate",
                   success_payoff: Any = "time_left", image_obs: Any = False, end_on_dead_end: Any = False,
                   task_obs: Any = False) -> None:
    """Every check of the env's keyword arguments that needs no model (``tool`` is the resolved
    tool, ``robot.tool`` or the ``tool`` argument)."""
    for name, v in (("image_obs", image_obs), ("end_on_dead_end", end_on_dead_end), ("task_obs", task_obs)):
        _flag(name, v)
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode must be one of {RENDER_MODES}, got {render_mode!r}")
    if reward_type not in REWARD_TYPES:
        raise ValueError(f"reward_type must be one of {REWARD_TYPES}, got {reward_type!r}")
    _finite("control_dt", control_dt, 1e-6, math.inf, "a finite number > 0 (s)")
    _int_at_least("substeps", substeps, 1)
    if tool not in TOOLS:
        raise ValueError(f"tool must be one of {TOOLS}, got {tool!r}")
    if suction_mode not in SUCTION_MODES:
        raise ValueError(f"suction_mode must be one of {SUCTION_MODES}, got {suction_mode!r}")
    if tool != "suction" and suction_mode != "momentary":
        raise ValueError(f"suction_mode={suction_mode!r} applies to the suction tool only (tool={tool!r})")
    if posture_target not in POSTURE_TARGETS:
        raise ValueError(f"posture_target must be one of {POSTURE_TARGETS}, got {posture_target!r}")
    check_pregrasp_start(pregrasp_start)
    _finite("reach_lateral_weight", reach_lateral_weight, 1.0, math.inf, "a finite number >= 1")
    if reach_lateral_weight != 1 and reward_type != "staged":
        raise ValueError(f"reach_lateral_weight shapes the staged reward only; with reward_type="
                         f"{reward_type!r} it would be ignored (got {reach_lateral_weight!r})")
    if reward_pose not in REWARD_POSES:
        raise ValueError(f"reward_pose must be one of {REWARD_POSES}, got {reward_pose!r}")
    if reward_pose != "estimate" and reward_type == "sparse":
        raise ValueError("reward_pose shapes the dense and staged rewards; the sparse reward has no "
                         "approach term it could change")
    if success_payoff not in SUCCESS_PAYOFFS:
        raise ValueError(f"success_payoff must be one of {SUCCESS_PAYOFFS}, got {success_payoff!r}")
    if success_payoff != "time_left" and reward_type != "staged":
        raise ValueError(f"success_payoff sets the staged reward's success bonus; with reward_type="
                         f"{reward_type!r} it would be ignored (got {success_payoff!r})")
    _int_at_least("horizon", horizon, 1)
    _int_at_least("scene_pool", scene_pool)
    _int_at_least("pool_seed", pool_seed)
    if scenes is not None and not isinstance(scenes, (str, bytes)) and hasattr(scenes, "__len__") and len(scenes) == 0:
        raise ValueError("scenes must be a non-empty sequence")
    if scene_pool and scenes is not None:
        raise ValueError("scene_pool draws generated beds; with scenes given it would be ignored")
    for name, v in (("pose_error_deg", pose_error_deg), ("position_noise", position_noise)):
        _finite(name, v, 0.0, math.inf, "a finite number >= 0")
    if pose_source != "noisy" and (pose_error_deg or position_noise):
        raise ValueError(f"pose_error_deg and position_noise apply to pose_source='noisy' only; with "
                         f"pose_source={pose_source!r} they would be ignored (got pose_error_deg="
                         f"{pose_error_deg!r}, position_noise={position_noise!r})")
    if pose_error_range_deg is not None:
        ok = (isinstance(pose_error_range_deg, (tuple, list)) and len(pose_error_range_deg) == 2
              and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pose_error_range_deg)
              and 0 <= pose_error_range_deg[0] <= pose_error_range_deg[1] <= 180)
        if not ok:
            raise ValueError(f"pose_error_range_deg must be (low, high) degrees with 0 <= low <= high <= 180, "
                             f"got {pose_error_range_deg!r}")
        if pose_source != "noisy" or pose_error_deg or position_noise:
            raise ValueError(f"pose_error_range_deg draws the 'noisy' source's error per episode: it needs "
                             f"pose_source='noisy' without pose_error_deg or position_noise (got pose_source="
                             f"{pose_source!r}, pose_error_deg={pose_error_deg!r}, position_noise={position_noise!r})")
    if target_rule not in RULES:
        raise ValueError(f"target_rule must be one of {RULES}, got {target_rule!r}")
    for name, size in (("image_size", image_size), ("render_size", render_size)):
        ok = (isinstance(size, (tuple, list)) and len(size) == 2
              and all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1 for n in size))
        if not ok:
            raise ValueError(f"{name} must be two integers >= 1 (height, width), got {size!r}")
    _finite("max_tilt_deg", max_tilt_deg, 0.0, 90.0, "a finite number in [0, 90]")
    if free_radius is not None:
        _finite("free_radius", free_radius, 1e-9, math.inf, "None or a finite number > 0 (m)")
    scene_config_of(scene_config)


def scene_config_of(scene_config: Any) -> Any:
    """The env's ``scene_config`` as a ``generator.SceneConfig`` (``None`` stays ``None``): its
    mapping form (the JSON an env spec holds) is read with ``SceneConfig.from_dict``, whose
    ``ConfigError`` names a bad field; anything else is a ``TypeError``."""
    from collections.abc import Mapping

    from generator.config import SceneConfig

    if scene_config is None or isinstance(scene_config, SceneConfig):
        return scene_config
    if isinstance(scene_config, Mapping):
        return SceneConfig.from_dict(scene_config)
    raise TypeError(f"scene_config must be a generator.SceneConfig, its mapping form or None, got "
                    f"{type(scene_config).__name__} {scene_config!r}")
