"""``SMS3DPickEnv``'s keyword arguments: the checks of those that are no record (refusing what the
env could not honour or would silently ignore, with a ``ValueError``/``TypeError`` naming the
argument), and ``translate_legacy_options``, which reads the arguments of earlier versions.

Light on purpose (numpy only at import): training code reads saved env options with it without
loading MuJoCo.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from typing import Any

from sms3d_env.records import check_choice, check_flag, check_number

SUCTION_MODES = ("momentary", "latched")
RENDER_MODES = ("rgb_array", "depth_array", "human")


def pose_error_of(pose_error_deg: Any) -> float | tuple[float, float]:
    """The ``"noisy"`` source's rotation error: a number of degrees in [0, 180], or a ``(low,
    high)`` pair with 0 <= low <= high <= 180, drawn uniformly per episode (``ValueError`` naming
    ``pose_error_deg`` otherwise)."""
    if isinstance(pose_error_deg, (tuple, list)):
        ok = len(pose_error_deg) == 2 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in pose_error_deg)
        if not (ok and 0 <= pose_error_deg[0] <= pose_error_deg[1] <= 180):
            raise ValueError(f"pose_error_deg as (low, high) must be degrees with 0 <= low <= high <= 180, "
                             f"got {pose_error_deg!r}")
        return float(pose_error_deg[0]), float(pose_error_deg[1])
    check_number("pose_error_deg", pose_error_deg, 0.0, 180.0,
                 "a number of degrees in [0, 180] or a (low, high) pair")
    return float(pose_error_deg)


def check_env_args(*, render_mode: Any, tool: Any, suction_mode: Any, pose_source: Any, pose_error_deg: Any,
                   end_on_dead_end: Any, task_obs: Any) -> None:
    """The checks of the env's arguments that are no record (``tool`` is the resolved tool:
    ``robot.tool`` or the ``tool`` argument)."""
    from sms3d_env.robot import TOOLS

    for name, v in (("end_on_dead_end", end_on_dead_end), ("task_obs", task_obs)):
        check_flag(name, v)
    if render_mode is not None:
        check_choice("render_mode", render_mode, RENDER_MODES)
    check_choice("tool", tool, TOOLS)
    check_choice("suction_mode", suction_mode, SUCTION_MODES)
    if tool != "suction" and suction_mode != "momentary":
        raise ValueError(f"suction_mode={suction_mode!r} applies to the suction tool only (tool={tool!r})")
    error = pose_error_of(pose_error_deg)
    if pose_source != "noisy" and error:
        raise ValueError(f"pose_error_deg applies to pose_source='noisy' only; with pose_source={pose_source!r} it "
                         f"would be ignored (got pose_error_deg={pose_error_deg!r}; a NoisyPose object carries its "
                         "own error)")


#: Env options removed because they measured worse (CHANGELOG), and the value each had by default.
REMOVED_OPTIONS = {"reach_lateral_weight": 1.0, "reward_pose": "estimate", "success_payoff": "time_left"}
#: Earlier keyword arguments -> (the argument that holds them now, the field of its mapping form).
_MOVED = {
    "scene_config": ("scene", "config"), "scenes": ("scene", "scenes"), "scene_pool": ("scene", "pool"),
    "pool_seed": ("scene", "pool_seed"), "free_radius": ("scene", "free_radius"),
    "target_rule": ("target", "rule"), "target_index": ("target", "index"), "max_tilt_deg": ("target", "max_tilt_deg"),
    "control_dt": ("controller", "control_dt"), "substeps": ("controller", "substeps"),
    "posture_target": ("controller", "posture_target"), "pregrasp_start": ("start", "share"),
}


def translate_legacy_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """``SMS3DPickEnv`` keyword arguments of earlier versions (a saved run's ``config.json``
    ``env_options``, an RL Zoo recipe's ``env_kwargs``, a Minari dataset's env spec) in the
    constructor's current form; current arguments pass unchanged.

    | earlier | now |
    | --- | --- |
    | ``scene_config``, ``scenes``, ``scene_pool``, ``pool_seed``, ``free_radius`` | ``scene``: ``SceneSourceConfig``'s mapping form (``config``, ``scenes``, ``pool``, ``pool_seed``, ``free_radius``) |
    | ``target_rule``, ``target_index``, ``max_tilt_deg`` | ``target``: ``{"rule", "index", "max_tilt_deg"}`` |
    | ``pose_error_range_deg`` | ``pose_error_deg``: ``(low, high)`` |
    | ``position_noise`` | ``pose_source``: ``NoisyPose(pose_error_deg, position_std=position_noise)`` |
    | ``control_dt``, ``substeps``, ``posture_target`` | ``controller``: ``{"control_dt", "substeps", "posture_target"}`` |
    | ``horizon`` | ``reward_type``: ``{"kind": reward_type, "horizon": horizon}`` |
    | ``pregrasp_start`` | ``start``: ``{"share": pregrasp_start}`` |
    | ``image_size``, ``camera`` | ``image_obs``: ``{"size", "camera"}`` (with ``image_obs=True``) |
    | ``camera``, ``render_size`` | ``render_camera``: ``{"name", "size"}`` |
    | ``reach_lateral_weight``, ``reward_pose``, ``success_payoff`` | removed (they shaped training rewards only, so a saved policy runs the same without them); a value other than the default is dropped with a warning |

    What the earlier env ignored is dropped (``scene_config`` beside ``scenes``, ``target_index``
    with another rule, ``image_size`` without image observations). ``ValueError`` naming both when an
    earlier key and the argument that holds it now are given together, or for a ``horizon``
    other than 250 without the ``reward_type`` it belongs to.
    """
    out = dict(options)
    old = {k: out.pop(k) for k in list(out) if k in _MOVED}
    for name in REMOVED_OPTIONS:
        if name in out and out.pop(name) != REMOVED_OPTIONS[name]:
            warnings.warn(f"the env option {name}={options[name]!r} was removed (it measured worse; see the "
                          f"CHANGELOG); the env is built without it", stacklevel=2)
    if "scenes" in old and old["scenes"] is not None:
        old.pop("scene_config", None)  # ignored beside scenes
    if old.get("target_rule", "tallest") != "index":
        old.pop("target_index", None)  # read by the index rule only
    for key, value in old.items():
        argument, field = _MOVED[key]
        if argument in options:
            raise ValueError(f"env options give both {key} (an earlier argument) and {argument}, which holds it now "
                             f"as {argument}.{field}; give {argument} alone")
        out.setdefault(argument, {})[field] = value
    range_deg = out.pop("pose_error_range_deg", None)
    if range_deg is not None:
        out["pose_error_deg"] = [float(v) for v in range_deg]
    noise = out.pop("position_noise", 0.0)
    if noise:
        from sms3d_env.pose_sources import NoisyPose

        out["pose_source"] = NoisyPose(float(out.pop("pose_error_deg", 0.0)), position_std=float(noise))
    horizon = out.pop("horizon", 250)
    if horizon != 250:
        if not isinstance(out.get("reward_type"), str):
            raise ValueError(f"env option horizon={horizon!r} sets the staged reward's horizon: give it with "
                             "reward_type={'kind': ..., 'horizon': ...} (the earlier options name no reward_type)")
        out["reward_type"] = {"kind": out["reward_type"], "horizon": horizon}
    camera, image_size = out.pop("camera", None), out.pop("image_size", None)
    if out.get("image_obs") is True and (camera is not None or image_size is not None):
        out["image_obs"] = {"size": image_size or (64, 64), "camera": camera or "overhead"}
    render_size = out.pop("render_size", None)
    if camera is not None or render_size is not None:
        out["render_camera"] = {"name": camera, **({"size": render_size} if render_size is not None else {})}
    return out
