"""The training options of SMS3DPickEnv (SMS3DPickTrain-v2): latched suction, the staged reward,
dead-end episode ends, observations in the estimated target frame, the wrist F/T, argument checks."""

import math
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import generator
import sms3d_env
from sms3d_env import OraclePose, ScriptedPicker
from sms3d_env.rewards import RewardConfig, RewardState, reward_terms
from sms3d_env.scene_source import SceneSourceConfig
from sms3d_env.task_obs import target_frame, tool_in_target, twist_about

SMALL = generator.SceneConfig().replace(placement__num_mushrooms=8)
# The mapping forms: v2 places the beds with no two collision hulls interpenetrating.
SMALL_MAPPING = {"placement": {"num_mushrooms": 8}}
BED = {"placement": {"num_mushrooms": 25}}
#: SMALL as a SceneConfig object v2 takes: no two collision hulls interpenetrating.
SMALL_HULLS = SMALL.replace(placement__overlap_iou=0.0, placement__overlap_solids="hulls")


def _run_until_sealed(env, seed=0):
    picker = ScriptedPicker.for_env(env)
    obs, _ = env.reset(seed=seed)
    for _ in range(250):
        obs, *_ = env.step(picker(obs))
        if obs["suction"][1] > 0.5:
            return obs
    raise AssertionError("the scripted picker never sealed")


@pytest.mark.parametrize("mode, kept", [("latched", True), ("momentary", False)])
def test_latched_suction_keeps_the_seal_through_off_commands(mode, kept):
    env = gym.make("SMS3DPick-v2", scene={"placement": {"num_mushrooms": 8}}, suction_mode=mode)
    _run_until_sealed(env)
    off = np.zeros(7, np.float32)
    off[6] = -1.0
    for _ in range(5):
        obs, *_ = env.step(off)
    assert bool(obs["suction"][1] > 0.5) is kept
    assert bool(obs["suction"][0] > 0.5) is kept  # the valve state is observed


def test_training_id_sets_the_options_and_passes_check_env():
    from gymnasium.utils.env_checker import check_env

    env = gym.make("SMS3DPickTrain-v2", scene=SMALL_MAPPING)
    u = env.unwrapped
    assert (u.reward_config.kind, u.suction_mode, u.end_on_dead_end, u.task_obs) == ("staged", "latched", True, True)
    assert sms3d_env.TRAIN_OPTIONS["reward_type"] == "staged"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(u, skip_render_check=True)
    unexpected = [str(w.message) for w in caught if "infinity" not in str(w.message)]
    assert not unexpected, unexpected


def _reward_state(**kw):
    base = dict(tool_pos=np.zeros(3), tool_axis=np.array([0.0, 0.0, -1.0]),
                goal_cap_top=np.array([0.0, 0.0, -0.05]), goal_axis=np.array([0.0, 0.0, 1.0]),
                gripped_target=False, target_detached=False, lift=0.0, lift_goal=0.03,
                success=False, bruised=False, root_utilisation=0.0, steps_left=100)
    base.update(kw)
    return RewardState(**base)


@settings(max_examples=300, deadline=None)
@given(dist=st.floats(0, 0.5), tilt=st.floats(0, math.pi), held=st.booleans(), detached=st.booleans(),
       lift=st.floats(-0.1, 0.2), load=st.floats(0, 5), bruised=st.booleans(), left=st.integers(0, 250))
def test_staged_reward_is_bounded_and_maximal_at_success(dist, tilt, held, detached, lift, load, bruised, left):
    axis = np.array([0.0, math.sin(tilt), -math.cos(tilt)])
    s = _reward_state(tool_pos=np.array([dist, 0.0, -0.05]), tool_axis=axis, gripped_target=held,
                      target_detached=detached, lift=lift, root_utilisation=load, bruised=bruised,
                      steps_left=left)
    terms = reward_terms(s)
    per_step = terms["stage"] + terms["progress"]
    assert 0.0 <= per_step < 1.0
    assert terms["success_bonus"] == 0.0
    success = reward_terms(_reward_state(success=True, steps_left=left))
    assert success["stage"] + success["progress"] == 1.0
    # Finishing now is worth at least staying at any lower stage until the time limit.
    assert sum(success.values()) >= per_step * (left + 1)


def test_staged_reward_orders_the_stages():
    far = sum(reward_terms(_reward_state(tool_pos=np.array([0.2, 0.0, 0.1]))).values())
    near = sum(reward_terms(_reward_state(tool_pos=np.array([0.0, 0.0, -0.045]))).values())
    sealed = sum(reward_terms(_reward_state(gripped_target=True)).values())
    loaded = sum(reward_terms(_reward_state(gripped_target=True, root_utilisation=0.8)).values())
    detached = sum(reward_terms(_reward_state(gripped_target=True, target_detached=True)).values())
    lifted = sum(reward_terms(_reward_state(gripped_target=True, target_detached=True, lift=0.02)).values())
    assert far < near < sealed < loaded < detached < lifted < 1.0
    knocked_off = reward_terms(_reward_state(target_detached=True, tool_pos=np.array([0.2, 0.0, 0.1])))
    assert sum(knocked_off.values()) == far  # detachment alone pays nothing


@pytest.mark.parametrize("horizon", [None, 300])
def test_scripted_success_is_reported_with_reward_terms(horizon):
    """The success step pays the steps left until the reward's horizon (the registered time limit,
    250, by default; the same bed, the same picks: only the last reward differs)."""
    reward = {} if horizon is None else {"reward_type": RewardConfig("staged", horizon)}
    env = gym.make("SMS3DPickTrain-v2", scene=SMALL_MAPPING, **reward)
    picker = ScriptedPicker.for_env(env)
    obs, _ = env.reset(seed=1)
    done, rewards = False, []
    while not done:
        obs, r, terminated, truncated, info = env.step(picker(obs))
        rewards.append(r)
        done = terminated or truncated
    assert info["is_success"] and terminated
    assert info["reward_stage"] == 1.0
    assert info["reward_success_bonus"] == (horizon or 250) - len(rewards)
    assert len(rewards) > 1 and max(rewards[:-1]) < 1.0 and rewards[-1] == 1.0 + info["reward_success_bonus"]


def _nearest_neighbour_pose(scene, i, rng):
    """The oracle pose of the target's nearest neighbour: the picker seals on the wrong cap."""
    base = np.array([inst.position for inst in scene.instances])
    d = np.linalg.norm(base - base[i], axis=1)
    d[i] = np.inf
    return OraclePose()(scene, int(np.argmin(d)), rng)


@pytest.mark.parametrize("dead_end", [True, False])
def test_a_latched_seal_on_a_neighbour_ends_the_episode(dead_end):
    env = gym.make("SMS3DPick-v2", scene=BED, pose_source=_nearest_neighbour_pose,
                   suction_mode="latched", end_on_dead_end=dead_end)
    picker = ScriptedPicker.for_env(env)
    obs, info = env.reset(seed=1)
    u = env.unwrapped
    target, steps, terminated = info["target"], 0, False
    while not terminated and steps < 250:
        obs, _, terminated, truncated, info = env.step(picker(obs))
        steps += 1
        if obs["suction"][1] > 0.5:
            break
    assert obs["suction"][1] > 0.5 and not info["gripped_target"]  # sealed, on another mushroom
    assert terminated is dead_end and not info["is_success"]
    assert u.failure_cause() == "not_reached"  # the cup went to the neighbour, never to the target
    assert target == info["target"]


def test_target_frame_entries_for_a_known_pose():
    axis = np.array([0.3, -0.2, 0.9])
    axis /= np.linalg.norm(axis)
    r = target_frame(axis)
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(r[:, 2], axis)
    assert np.linalg.det(r) == pytest.approx(1.0)
    cap = np.array([0.1, 0.2, 0.05])
    # Tool 3 cm up the stem axis, facing down it: offset (0, 0, 0.03), axis (0, 0, -1), angle 0.
    v = tool_in_target(cap + 0.03 * axis, -axis, cap, axis)
    np.testing.assert_allclose(v, [0, 0, 0.03, 0, 0, -1, 0], atol=1e-7)
    # Tilted by 20 degrees about the frame's x axis: the angle reads 20 degrees.
    rot = np.eye(3)
    mujoco.mju_axisAngle2Quat(q := np.zeros(4), r[:, 0], np.deg2rad(20))
    mujoco.mju_quat2Mat(m9 := np.zeros(9), q)
    rot = m9.reshape(3, 3)
    assert tool_in_target(cap, rot @ -axis, cap, axis)[6] == pytest.approx(np.deg2rad(20))
    x0 = r[:, 0]
    assert twist_about(axis, x0, rot @ x0) == pytest.approx(0.0, abs=1e-9)  # about x: no twist
    mujoco.mju_axisAngle2Quat(q, axis, 0.5)
    mujoco.mju_quat2Mat(m9, q)
    assert twist_about(axis, x0, m9.reshape(3, 3) @ x0) == pytest.approx(0.5)


def test_task_observation_matches_the_tool_and_estimate():
    env = gym.make("SMS3DPickTrain-v2", scene=SMALL_MAPPING)
    obs, _ = env.reset(seed=3)
    for _ in range(4):
        obs, *_ = env.step(env.action_space.sample() * 0.3)
    u = env.unwrapped
    quat = obs["tool_pose"][3:]
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    expected = tool_in_target(obs["tool_pose"][:3], mat.reshape(3, 3)[:, 2],
                              obs["target_pose"][:3], obs["target_pose"][3:])
    np.testing.assert_allclose(obs["tool_in_target"], expected, atol=1e-6)
    np.testing.assert_allclose(obs["progress"], [4 * u.control_dt, 0.0, 0.0])


def test_wrist_sensor_reads_the_tool_weight_at_rest():
    env = gym.make("SMS3DPickTrain-v2", scene=SMALL_MAPPING)
    obs, _ = env.reset(seed=0)
    for _ in range(10):
        obs, *_ = env.step(np.zeros(7, np.float32))
    m = env.unwrapped.model
    tool = m.body(f"{env.unwrapped.robot_cfg.prefix}tool").id
    weight = m.body_subtreemass[tool] * 9.81
    assert np.linalg.norm(obs["wrist_wrench"][:3]) == pytest.approx(weight, rel=0.05)


def test_step_after_the_end_warns_and_stays_terminated():
    env = gym.make("SMS3DPickTrain-v2", scene=SMALL_MAPPING).unwrapped  # no TimeLimit/order wrapper
    picker = ScriptedPicker.for_env(env)
    obs, _ = env.reset(seed=1)
    terminated = False
    while not terminated:
        obs, _, terminated, _, _ = env.step(picker(obs))
    with pytest.warns(UserWarning, match="after the episode ended"):
        _, _, terminated, _, _ = env.step(np.zeros(7, np.float32))
    assert terminated


BAD_ARGS = [
    ({"pose_source": "oracle", "pose_error_deg": 10.0}, "pose_error_deg"),
    ({"pose_source": "noisy", "pose_error_deg": (30.0, 10.0)}, "pose_error_deg"),
    ({"pose_source": "noisy", "pose_error_deg": 200.0}, "pose_error_deg"),
    ({"target": "nonsense"}, "TargetRule.rule"),
    ({"target": {"rule": "tallest", "index": 3}}, "TargetRule.index"),  # only the index rule reads it
    ({"target": {"rul": "index"}}, "TargetRule has no field 'rul'"),
    ({"target": {"max_tilt_deg": float("nan")}}, "TargetRule.max_tilt_deg"),
    ({"image_obs": {"size": (0, 0)}}, "ImageObservation.size"),
    ({"image_obs": {"camera": "wrist"}}, "ImageObservation.camera"),
    ({"render_camera": {"size": (480,)}}, "RenderCamera.size"),
    ({"render_camera": "wrist"}, "RenderCamera.name"),
    ({"scene": {"free_radius": -1.0}}, "SceneSourceConfig.free_radius"),
    ({"scene": {"pool": -1}}, "SceneSourceConfig.pool"),
    ({"scene": 3}, "scene must be"),
    ({"suction_mode": "sticky"}, "suction_mode"),
    ({"tool": "hand", "suction_mode": "latched"}, "suction_mode"),
    ({"reward_type": "shaped"}, "RewardConfig.kind"),
    ({"reward_type": {"kind": "staged", "horizon": 0}}, "RewardConfig.horizon"),
    ({"controller": {"substeps": 0}}, "ControllerConfig.substeps"),
    ({"controller": {"posture_target": "truth"}}, "ControllerConfig.posture_target"),
    ({"controller": "fast"}, "controller must be a record ControllerConfig"),
    ({"start": {"share": 1.5}}, "PregraspStart.share"),
]


@pytest.mark.parametrize("kwargs, field", BAD_ARGS)
def test_env_refuses_arguments_it_would_ignore_or_misread(kwargs, field):
    with pytest.raises((ValueError, TypeError), match=field):
        sms3d_env.SMS3DPickEnv(**kwargs)


def test_gym_make_refuses_a_pose_error_the_oracle_would_ignore():
    with pytest.raises(ValueError, match=r"applies to pose_source='noisy' only; with pose_source='oracle' "
                                         r"it would be ignored \(got pose_error_deg=10"):
        gym.make("SMS3DPick-v2", pose_source="oracle", pose_error_deg=10)


_NON_FINITE_OR_NEGATIVE = st.one_of(st.floats(allow_nan=True, allow_infinity=True).filter(
    lambda v: not (math.isfinite(v) and v >= 0)), st.booleans(), st.text(max_size=3))
#: A number each argument refuses when it is not finite and >= 0: how to pass it, and the name
#: its error gives.
_NUMBERS = {
    "pose_error_deg": (lambda v: {"pose_source": "noisy", "pose_error_deg": v}, "pose_error_deg"),
    "max_tilt_deg": (lambda v: {"target": {"max_tilt_deg": v}}, "TargetRule.max_tilt_deg"),
    "free_radius": (lambda v: {"scene": {"free_radius": v}}, "SceneSourceConfig.free_radius"),
    "control_dt": (lambda v: {"controller": {"control_dt": v}}, "ControllerConfig.control_dt"),
    "share": (lambda v: {"start": {"share": v}}, "PregraspStart.share"),
}


@settings(max_examples=60, deadline=None)
@given(field=st.sampled_from(sorted(_NUMBERS)), value=_NON_FINITE_OR_NEGATIVE)
def test_env_numeric_arguments_property(field, value):
    kwargs, name = _NUMBERS[field]
    with pytest.raises((ValueError, TypeError), match=name):
        sms3d_env.SMS3DPickEnv(**kwargs(value))


@settings(max_examples=40, deadline=None)
@given(record=st.sampled_from(["image_obs", "render_camera"]),
       size=st.one_of(st.tuples(st.integers(-5, 0), st.integers(-5, 64)),
                      st.tuples(st.floats(1, 64), st.floats(1, 64)),
                      st.lists(st.integers(1, 64), min_size=0, max_size=1).map(tuple),
                      st.lists(st.integers(1, 64), min_size=3, max_size=4).map(tuple)))
def test_env_image_size_property(record, size):
    name = {"image_obs": "ImageObservation", "render_camera": "RenderCamera"}[record]
    with pytest.raises(ValueError, match=f"{name}.size"):
        sms3d_env.SMS3DPickEnv(**{record: {"size": size}})


@settings(max_examples=40, deadline=None)
@given(field=st.sampled_from(["image_obs", "end_on_dead_end", "task_obs"]),
       value=st.one_of(st.text(max_size=5), st.integers(), st.floats(allow_nan=True), st.none(),
                       st.lists(st.booleans(), max_size=2)))
def test_env_flags_take_bools_only(field, value):
    # By truthiness, end_on_dead_end="no" switched the option on.
    with pytest.raises(TypeError, match=f"{field} must be True or False"):
        sms3d_env.SMS3DPickEnv(**{field: value})


def test_env_flags_take_numpy_bools():
    env = sms3d_env.SMS3DPickEnv(scene={"placement": {"num_mushrooms": 8}}, end_on_dead_end=np.bool_(True),
                                 task_obs=np.False_)
    assert env.end_on_dead_end is True and env.task_obs is False


def test_uniform_noisy_pose_errs_within_its_range():
    from sms3d_env.pose_sources import UniformNoisyPose

    scene = generator.generate_scene(SMALL, seed=0)
    source, rng = UniformNoisyPose(10.0, 30.0), np.random.default_rng(0)
    truth = scene.instances[0].rotation[:, 2]
    errors = [np.degrees(np.arccos(np.clip(source(scene, 0, rng).stem_axis @ truth, -1, 1)))
              for _ in range(200)]
    assert 10.0 - 1e-6 <= min(errors) and max(errors) <= 30.0 + 1e-6
    assert 18 < np.mean(errors) < 22  # uniform: mean 20
    with pytest.raises(ValueError):
        UniformNoisyPose(30.0, 10.0)


def test_scene_pool_reuses_beds_and_replays_episodes_exactly():
    from sms3d_env.pickers import run_episode

    env = gym.make("SMS3DPickTrain-v2", scene=SceneSourceConfig(config=SMALL_HULLS, pool=1, pool_seed=7))
    picker = ScriptedPicker.for_env(env)
    first = run_episode(env, picker, seed=4)
    assert env.unwrapped.scene is env.unwrapped.scene_source.pool[0]
    expected = generator.generate_scene(SMALL_HULLS, seed=7)
    np.testing.assert_array_equal(env.unwrapped.scene.terrain.heights, expected.terrain.heights)
    # The pool's compiled model is copied per episode: a replay is the same episode.
    again = run_episode(env, picker, seed=4)
    assert (again["success"], again["steps"], again["return"]) == (first["success"], first["steps"], first["return"])


def test_a_scene_pool_keeps_a_bounded_number_of_compiled_models(monkeypatch):
    """A compiled model per pool bed held ~4.7 MB each without bound (2.4 GB for a 500-bed pool);
    the pool keeps the most recently used few, and a bed compiled again is the same episode."""
    from sms3d_env import scene_source

    monkeypatch.setattr(scene_source, "MAX_CACHED_MODELS", 2)
    env = gym.make("SMS3DPick-v2", scene={"config": SMALL_MAPPING, "pool": 5}).unwrapped
    seeds = range(8)

    def draws():
        out = []
        for seed in seeds:
            obs, _ = env.reset(seed=seed)
            assert len(env.scene_source.models) <= 2
            out.append((env.scene, obs))
        return out

    first = draws()
    assert len(env.scene_source.pool) > 2  # more beds drawn than models kept
    for (scene, obs), (again_scene, again_obs) in zip(first, draws(), strict=True):
        assert again_scene is scene  # the same bed for the same seed
        for key in obs:
            np.testing.assert_array_equal(again_obs[key], obs[key])
