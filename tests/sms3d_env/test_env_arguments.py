"""The env's constructor: at most 16 arguments, each documented; the option records refuse bad
fields by name; the options of earlier versions (saved runs, recipes, datasets) translate to the
arguments that hold them now."""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import re

import gymnasium as gym
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import generator
import sms3d_env  # noqa: F401  (registers the env ids)
from sms3d_env.cameras import ImageObservation, RenderCamera
from sms3d_env.controller import ControllerConfig
from sms3d_env.env_args import translate_legacy_options
from sms3d_env.physics_params import V1_PHYSICS, PickPhysicsParams
from sms3d_env.pick_env import SMS3DPickEnv
from sms3d_env.pickers.policy import PolicyActor
from sms3d_env.policies.loader import SHIPPED_POLICY
from sms3d_env.pose_sources import NoisyPose
from sms3d_env.records import record_of
from sms3d_env.rewards import RewardConfig
from sms3d_env.scene_source import SceneSourceConfig, scene_source_config
from sms3d_env.start_states import PregraspStart
from sms3d_env.targets import TargetRule

SMALL = generator.SceneConfig().replace(placement__num_mushrooms=6)
#: SMALL in the mapping form, and the config it gives where mushrooms collide (v2, the class
#: defaults): placed with no overlap of the collision hulls.
SMALL_MAPPING = {"placement": {"num_mushrooms": 6}}
SMALL_HULLS = SMALL.replace(placement__overlap_iou=0.0, placement__overlap_solids="hulls")
RECORDS = (SceneSourceConfig, TargetRule, RewardConfig, ControllerConfig, PregraspStart, ImageObservation,
           RenderCamera)


def _arguments_table() -> dict[str, list[str]]:
    """The rows of the class docstring's ``## Arguments`` table by parameter name: its cells."""
    doc = inspect.getdoc(SMS3DPickEnv)
    section = doc.split("## Arguments", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        name = re.fullmatch(r"``(\w+)``", cells[0]) if line.lstrip().startswith("|") else None
        if name:
            rows[name.group(1)] = cells[1:]
    return rows


def test_the_constructor_takes_at_most_16_arguments_each_in_the_arguments_table():
    parameters = [p for name, p in inspect.signature(SMS3DPickEnv.__init__).parameters.items() if name != "self"]
    assert len(parameters) <= 16
    table = _arguments_table()
    assert list(table) == [p.name for p in parameters]  # every argument, in the signature's order
    for p in parameters:
        type_, default, description = table[p.name]
        assert type_ and description, p.name
        # The documented default is the signature's (None, a number, or a quoted string).
        assert default.strip("`").strip('"') == str(p.default), p.name


def test_the_registered_ids_build_their_options_from_the_records():
    # v2's mushrooms collide, so its generated beds are placed with no overlap of their collision
    # hulls: the mapping form of a scene config says so by default (a SceneConfig object must).
    scenes = {env_id: SMALL_MAPPING if env_id.endswith("-v2") else SMALL
              for env_id in ("SMS3DPick-v1", "SMS3DPickTrain-v1", "SMS3DPick-v2", "SMS3DPickTrain-v2")}
    made = {env_id: gym.make(env_id, scene=scene).unwrapped for env_id, scene in scenes.items()}
    for env_id, env in made.items():
        version = env_id[-2:]
        bed = SMALL_HULLS if version == "v2" else SMALL
        assert env.scene_source.config == SceneSourceConfig(config=bed)
        assert env.reward_config.kind == ("staged" if "Train" in env_id else "dense")
        # v2: the class defaults (the harvest-ready target, PickPhysicsParams()); v1: its picking
        # model (V1_PHYSICS) and the tallest target; both the records' controller.
        assert env.start is None
        assert env.target_rule == TargetRule("harvest_ready" if version == "v2" else "tallest")
        assert env.ctrl_cfg == ControllerConfig()
        assert env.params == PickPhysicsParams(**({} if version == "v2" else V1_PHYSICS)), env_id
        assert type(env.robot_cfg).__name__ == "GantryConfig"
        env.close()
    # The env's own default: every mushroom free (v1's and v2's); a scene source's radius is kept.
    assert SMS3DPickEnv(scene=SMALL_MAPPING).scene_source.config.free_radius is None
    wider = gym.make("SMS3DPick-v2", scene={"config": SMALL_MAPPING, "free_radius": 0.2}).unwrapped
    assert wider.scene_source.config.free_radius == 0.2


@pytest.mark.parametrize("scene, expected", [
    (None, SceneSourceConfig()),
    (SMALL, SceneSourceConfig(config=SMALL)),
    ({"placement": {"num_mushrooms": 6}}, SceneSourceConfig(config=SMALL)),
    ({"config": {"placement": {"num_mushrooms": 6}}, "pool": 3}, SceneSourceConfig(config=SMALL, pool=3)),
    ("beds/", SceneSourceConfig(scenes="beds/")),
])
def test_every_form_of_the_scene_argument_reads_as_its_record(scene, expected):
    assert scene_source_config(scene) == expected


def _field_names(cls: type) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)]


@settings(max_examples=60, deadline=None)
@given(cls=st.sampled_from(RECORDS), key=st.text(min_size=1, max_size=12))
def test_a_mapping_with_a_key_that_is_no_field_is_refused_by_that_key(cls, key):
    assume(key not in _field_names(cls))
    with pytest.raises(ValueError, match=f"{cls.__name__} has no field {re.escape(repr(key))}"):
        record_of(cls, {key: 1}, "argument")


#: A value each record field refuses, and why.
BAD_FIELDS = [
    (SceneSourceConfig, "config", "a bed"), (SceneSourceConfig, "scenes", []), (SceneSourceConfig, "scenes", [3]),
    (SceneSourceConfig, "pool", -1), (SceneSourceConfig, "pool", 2.5), (SceneSourceConfig, "pool_seed", True),
    (SceneSourceConfig, "free_radius", 0.0),
    (TargetRule, "rule", "nearest"), (TargetRule, "index", -1), (TargetRule, "max_tilt_deg", 91.0),
    (RewardConfig, "kind", "shaped"), (RewardConfig, "horizon", 0),
    (ControllerConfig, "control_dt", 0.0), (ControllerConfig, "substeps", 0), (ControllerConfig, "posture_target", "home"),
    (ControllerConfig, "max_linear_speed", math.inf),
    (PregraspStart, "share", 1.5), (PregraspStart, "share", "half"),
    (ImageObservation, "size", (64,)), (ImageObservation, "camera", "wrist"),
    (RenderCamera, "name", "wrist"), (RenderCamera, "size", (0, 640)),
]


@pytest.mark.parametrize("cls, field, value", BAD_FIELDS, ids=lambda v: getattr(v, "__name__", str(v)))
def test_each_record_refuses_a_bad_field_by_name(cls, field, value):
    with pytest.raises((ValueError, TypeError), match=rf"{cls.__name__}\.{field}"):
        cls(**{field: value})


def test_scene_and_pool_exclude_fixed_scenes():
    scene = generator.generate_scene(SMALL, seed=0)
    with pytest.raises(ValueError, match="SceneSourceConfig.pool"):
        SceneSourceConfig(scenes=[scene], pool=2)
    with pytest.raises(ValueError, match="SceneSourceConfig.config"):
        SceneSourceConfig(config=SMALL, scenes=[scene])
    with pytest.raises(generator.ConfigError, match=r"SceneSourceConfig.config.placement.num_mushroomz"):
        SceneSourceConfig(config={"placement": {"num_mushroomz": 3}})


def test_a_saved_policys_earlier_posture_option_translates_to_the_controller(tmp_path):
    """A run's ``config.json`` written before the env's arguments were grouped records
    ``posture_target`` among its env options; it reads as the controller's option."""
    import shutil

    for name in ("model.zip", "config.json"):
        shutil.copy(SHIPPED_POLICY.parent / name, tmp_path / name)
    config = json.loads((tmp_path / "config.json").read_text())
    config["env_options"]["posture_target"] = "tool"  # the earlier form
    (tmp_path / "config.json").write_text(json.dumps(config))
    assert translate_legacy_options(config["env_options"]) == {
        **{k: v for k, v in config["env_options"].items() if k != "posture_target"},
        "controller": {"posture_target": "tool"}}
    actor = PolicyActor(tmp_path / "model.zip")
    assert actor.env_options["controller"] == {"posture_target": "tool"}
    env = actor.make_env(scene=SMALL_MAPPING)
    try:
        assert env.unwrapped.ctrl_cfg.posture_target == "tool"
    finally:
        env.close()


def test_every_earlier_option_translates_to_the_argument_that_holds_it():
    earlier = {"scene_config": {"placement": {"num_mushrooms": 6}}, "scene_pool": 4, "pool_seed": 9,
               "free_radius": 0.1, "target_rule": "index", "target_index": 2, "max_tilt_deg": 30.0,
               "pose_source": "noisy", "pose_error_range_deg": (10, 30), "control_dt": 0.05, "substeps": 25,
               "posture_target": "tool", "reward_type": "staged", "horizon": 300, "pregrasp_start": 0.5,
               "image_obs": True, "image_size": (32, 48), "camera": "side", "render_size": (120, 160),
               "suction_mode": "latched"}
    now = translate_legacy_options(earlier)
    assert now == {
        "scene": {"config": {"placement": {"num_mushrooms": 6}}, "pool": 4, "pool_seed": 9, "free_radius": 0.1},
        "target": {"rule": "index", "index": 2, "max_tilt_deg": 30.0},
        "pose_source": "noisy", "pose_error_deg": [10.0, 30.0],
        "controller": {"control_dt": 0.05, "substeps": 25, "posture_target": "tool"},
        "reward_type": {"kind": "staged", "horizon": 300}, "start": {"share": 0.5},
        "image_obs": {"size": (32, 48), "camera": "side"}, "render_camera": {"name": "side", "size": (120, 160)},
        "suction_mode": "latched"}
    env = SMS3DPickEnv(**now)
    assert (env.scene_source.config.pool, env.target_rule.index, env.ctrl_cfg.substeps, env.reward_config.horizon,
            env.start.share, env.image_obs.camera, env.render_camera.size) == (4, 2, 25, 300, 0.5, "side", (120, 160))
    assert translate_legacy_options(now) == now  # current arguments pass unchanged


def test_what_the_earlier_env_ignored_is_dropped_and_position_noise_becomes_a_noisy_pose():
    scene = generator.generate_scene(SMALL, seed=0)
    assert translate_legacy_options({"scene_config": SMALL, "scenes": [scene]}) == {"scene": {"scenes": [scene]}}
    assert translate_legacy_options({"target_rule": "largest", "target_index": 3}) == {"target": {"rule": "largest"}}
    assert translate_legacy_options({"image_size": (8, 8), "horizon": 250}) == {}
    noisy = translate_legacy_options({"pose_source": "noisy", "pose_error_deg": 20.0, "position_noise": 0.002})
    assert set(noisy) == {"pose_source"} and isinstance(noisy["pose_source"], NoisyPose)
    assert (math.degrees(noisy["pose_source"].error), noisy["pose_source"].position_std) == pytest.approx((20.0, 0.002))


def test_translation_refuses_an_option_given_twice_and_a_horizon_without_its_reward():
    with pytest.raises(ValueError, match="posture_target .* and controller"):
        translate_legacy_options({"posture_target": "tool", "controller": {"substeps": 10}})
    with pytest.raises(ValueError, match="horizon=100"):
        translate_legacy_options({"horizon": 100})


def test_the_removed_reward_options_are_dropped_with_a_warning_unless_at_their_default():
    assert translate_legacy_options({"reward_pose": "estimate", "success_payoff": "time_left",
                                     "reach_lateral_weight": 1.0}) == {}
    with pytest.warns(UserWarning, match="reward_pose='truth' was removed"):
        assert translate_legacy_options({"reward_pose": "truth", "task_obs": True}) == {"task_obs": True}


def test_the_removed_options_are_no_env_arguments():
    for name in ("reach_lateral_weight", "reward_pose", "success_payoff", "scene_config", "pregrasp_start",
                 "posture_target", "image_size", "camera", "render_size", "horizon"):
        with pytest.raises(TypeError, match=name):
            SMS3DPickEnv(**{name: None})
