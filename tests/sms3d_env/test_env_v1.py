"""SMS3DPick-v1: an honest robot (every link collides), the gantry beside the Jaco, robot names,
``not_reached`` and the simulated time."""

from __future__ import annotations

import pickle
import re

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sms3d_env  # noqa: F401  (registers the ids)
from generator import SceneConfig
from sms3d_env.pickers.episode import run_episode
from sms3d_env.pickers.scripted import ScriptedPicker
from sms3d_env.robots import ROBOTS

SMALL = SceneConfig().replace(placement__num_mushrooms=10)


@pytest.mark.parametrize("robot", ROBOTS)
def test_the_exact_pose_scripted_picker_picks_with_every_link_colliding(robot):
    env = gym.make("SMS3DPick-v1", robot=robot, scene=SMALL)
    results = [run_episode(env, ScriptedPicker.for_env(env), seed) for seed in range(1_000_000, 1_000_004)]
    assert sum(r["success"] for r in results) >= 3, results
    assert all(r["failure_cause"] != "not_reached" for r in results)


@pytest.mark.parametrize("env_id", ["SMS3DPick-v1", "SMS3DPickTrain-v1"])
@pytest.mark.parametrize("robot", ROBOTS)
# Unbounded observations (joint velocities, forces) are intended; Gymnasium-Robotics has the same.
@pytest.mark.filterwarnings("ignore:.*observation space (minimum|maximum) value is -?infinity")
def test_gymnasium_and_sb3_check_env_pass(env_id, robot):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id, robot=robot, scene=SMALL).unwrapped
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=False)


@pytest.mark.parametrize("env_id, latest", [("SMS3DPick-v0", "SMS3DPick-v2"),
                                             ("SMS3DPickTrain-v0", "SMS3DPickTrain-v2")])
# Gymnasium warns that the version is out of date before it refuses it.
@pytest.mark.filterwarnings("ignore:.*-v0 is out of date:DeprecationWarning")
def test_the_removed_v0_ids_are_refused_naming_the_latest_version(env_id, latest):
    from gymnasium.error import DeprecatedEnv

    with pytest.raises(DeprecatedEnv, match=f"v0 for `{env_id[:-3]}` is deprecated. Please use `{latest}` instead"):
        gym.make(env_id)


def test_the_removed_sparse_id_is_unknown_to_gymnasium():
    from gymnasium.error import NameNotFound

    with pytest.raises(NameNotFound, match="SMS3DPickSparse` doesn't exist"):
        gym.make("SMS3DPickSparse-v0")


def test_v1_is_out_of_date_in_favour_of_v2():
    with pytest.warns(DeprecationWarning, match="SMS3DPick-v1 is out of date.*`v2`"):
        gym.make("SMS3DPick-v1", scene=SMALL).close()


@pytest.mark.parametrize("bad, error", [("ur5", ValueError), ("", ValueError), (3, TypeError),
                                        (None.__class__, TypeError)])
def test_a_bad_robot_is_refused_naming_the_argument_and_the_choices(bad, error):
    with pytest.raises(error, match=r"robot must be .*" + re.escape(repr(tuple(ROBOTS)))):
        gym.make("SMS3DPick-v1", robot=bad)


def test_the_gantry_is_deterministic_by_seed_and_pickles_mid_episode():
    def rollout(env, steps):
        obs, _ = env.reset(seed=11)
        picker = ScriptedPicker()
        for _ in range(steps):
            obs, *_ = env.step(picker(obs))
        return obs, picker

    a = gym.make("SMS3DPick-v1", scene=SMALL)
    b = gym.make("SMS3DPick-v1", scene=SMALL)
    obs_a, picker = rollout(a, 30)
    obs_b, _ = rollout(b, 30)
    for key in obs_a:
        np.testing.assert_array_equal(obs_a[key], obs_b[key])
    copy = pickle.loads(pickle.dumps(a.unwrapped))
    action = picker(obs_a)
    after_a = a.unwrapped.step(action)[0]
    after_copy = copy.step(action)[0]
    for key in after_a:
        np.testing.assert_allclose(after_a[key], after_copy[key], atol=1e-9)


def test_an_approach_that_stops_short_is_not_reached_and_time_counts():
    env = gym.make("SMS3DPick-v1", scene=SMALL)
    env.reset(seed=5)
    for _ in range(10):
        _, _, terminated, truncated, info = env.step(np.zeros(7, np.float32))
    assert info["failure_cause"] == "not_reached"
    assert info["time_s"] == pytest.approx(10 * env.unwrapped.control_dt)


def test_async_vector_envs_are_seeded_and_close_their_workers():
    import multiprocessing

    def first_observations():
        envs = gym.make_vec("SMS3DPick-v1", num_envs=4, vectorization_mode="async", scene=SMALL)
        try:
            obs, _ = envs.reset(seed=[1, 2, 3, 4])
            envs.step(np.zeros((4, 7), np.float32))
            return obs
        finally:
            envs.close()

    a, b = first_observations(), first_observations()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert len({tuple(row) for row in a["target_pose"]}) == 4  # four different beds
    assert multiprocessing.active_children() == []


def test_the_gantry_pressing_into_the_soil_at_full_speed_stays_below_the_bruising_force():
    corner = SceneConfig().replace(placement__num_mushrooms=1, placement__x_range=(0.15, 0.18),
                                   placement__y_range=(0.15, 0.18))
    env = gym.make("SMS3DPick-v1", scene=corner)
    env.reset(seed=0)
    u = env.unwrapped
    lift = u.model.actuator("gantry/act_lift_z").id
    down = np.array([0, 0, -1, 0, 0, 0, 0], np.float32)
    forces = []
    for _ in range(120):
        env.step(down)
        forces.append(abs(u.data.actuator_force[lift]))
    assert u.data.site_xpos[u.world.tool_site][2] < 0.01  # it reached the soil and pushed
    assert forces[-1] == pytest.approx(u.robot_cfg.lift_force)  # pressing as hard as the lift can
    assert max(forces) <= u.robot_cfg.lift_force + 1e-9 < u.params.bruise_force


def test_a_robot_config_of_its_own_defaults_is_the_hanging_jaco():
    from sms3d_env.robot import RobotConfig
    from sms3d_env.robots import HANGING_JACO

    env = gym.make("SMS3DPick-v1", robot=RobotConfig(), scene=SMALL).unwrapped
    assert env.robot_cfg == HANGING_JACO == gym.make("SMS3DPick-v1", robot="jaco", scene=SMALL).unwrapped.robot_cfg


def test_one_compiled_model_serves_every_target_of_a_pool_bed():
    # With every mushroom free the world does not depend on the target: a pool bed compiles once.
    env = gym.make("SMS3DPick-v1", scene={"config": SMALL, "pool": 1})
    targets = {env.reset(seed=s, options={"target": k})[1]["target"] for s, k in enumerate(range(4))}
    assert targets == {0, 1, 2, 3}
    assert len(env.unwrapped.scene_source.models) == 1


def test_a_step_whose_ik_has_no_solution_holds_the_last_command_and_other_errors_surface(monkeypatch):
    from mink.exceptions import NoSolutionFound

    env = gym.make("SMS3DPick-v1", scene=SMALL).unwrapped
    env.reset(seed=0)
    env.step(np.r_[0.5, 0.0, -0.5, 0.0, 0.0, 0.0, 0.0])
    held = env.world.data.ctrl[:6].copy()

    def no_solution(*args):
        raise NoSolutionFound("daqp")

    monkeypatch.setattr(env.ik, "step", no_solution)
    obs, reward, terminated, truncated, info = env.step(np.r_[0.5, 0.0, -0.5, 0.0, 0.0, 0.0, 0.0])
    assert np.array_equal(env.world.data.ctrl[:6], held) and np.isfinite(reward)

    def broken(*args):
        raise RuntimeError("a bug in the controller")

    monkeypatch.setattr(env.ik, "step", broken)
    with pytest.raises(RuntimeError, match="a bug in the controller"):
        env.step(np.zeros(7))


def test_robot_none_and_the_class_default_are_the_gantry_never_v0s_jaco():
    from sms3d_env.gantry import GantryConfig
    from sms3d_env.pick_env import SMS3DPickEnv

    assert isinstance(gym.make("SMS3DPick-v1", robot=None, scene=SMALL).unwrapped.robot_cfg, GantryConfig)
    assert isinstance(SMS3DPickEnv(scene={"placement": {"num_mushrooms": 10}}).robot_cfg, GantryConfig)


def test_a_step_after_the_episode_ended_keeps_its_outcome():
    env = gym.make("SMS3DPick-v1", scene=SMALL, max_episode_steps=None)
    result = run_episode(env, ScriptedPicker.for_env(env), 1_000_000)
    assert result["success"]
    base = env.unwrapped
    with pytest.warns(UserWarning, match="after the episode ended"):
        _, reward, terminated, truncated, info = base.step(np.zeros(7))
    assert (reward, terminated, truncated) == (0.0, True, False)
    assert info["is_success"] and info["failure_cause"] == result["failure_cause"]
