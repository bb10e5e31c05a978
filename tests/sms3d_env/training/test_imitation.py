"""The imitation recipe's options: a pose error drawn per episode, the scripted picker labelling
every state from the estimate the clone sees."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sms3d_env  # noqa: F401  (registers the env ids)
from sms3d_env.pickers.scripted import ScriptedPicker
from sms3d_env.pose_sources import UniformNoisyPose
from sms3d_env.training.demonstrations import labelled_steps, minari_root, with_true_target
from sms3d_env.training.envs import TRAIN_ENV_ID, env_kwargs
from sms3d_env.training.imitation import BCConfig, _record


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = a @ b / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def test_with_true_target_replaces_only_the_estimate():
    env = gym.make(TRAIN_ENV_ID, **env_kwargs(8, pose_error_deg=30.0))
    try:
        obs, info = env.reset(seed=3)
        truth = with_true_target(env, obs, info["target"])
        inst = env.unwrapped.scene.instances[info["target"]]
        np.testing.assert_allclose(truth["target_pose"][:3], inst.cap_top)
        np.testing.assert_allclose(truth["target_pose"][3:], np.asarray(inst.rotation)[:, 2])
        assert _angle_deg(obs["target_pose"][3:], truth["target_pose"][3:]) == pytest.approx(30.0, abs=1e-6)
        assert all(np.array_equal(obs[k], truth[k]) for k in obs if k != "target_pose")
    finally:
        env.close()


def test_the_pose_error_range_draws_a_uniform_noisy_source():
    env = gym.make(TRAIN_ENV_ID, **env_kwargs(8, pose_error_range_deg=(5.0, 25.0)))
    try:
        source = env.unwrapped.pose_source
        assert isinstance(source, UniformNoisyPose) and (source.low_deg, source.high_deg) == (5.0, 25.0)
        env.spec.to_json()  # JSON: a dataset recorded in this env rebuilds it
    finally:
        env.close()
    assert "pose_source" not in env_kwargs(8)


def test_the_clone_sees_the_estimate_and_the_approach_is_labelled_from_it(tmp_path):
    """The learner (here: standing still) acts, the scripted picker labels: it approaches the
    *estimated* stand-off point (a switch the clone can see), and the clone sees the estimate."""
    cfg = BCConfig(episodes=1, num_mushrooms=(8,), pose_error_deg=30.0, out="unused")
    with minari_root(tmp_path):
        recorded = _record(cfg, [("bc/learner-v0", gym.make(TRAIN_ENV_ID, **env_kwargs(8, pose_error_deg=30.0)))],
                           range(3, 4), actor=lambda obs: np.zeros(7, np.float32), beta=0.0, progress=False)
    demos = labelled_steps(recorded, ["target_pose"])
    env = gym.make(TRAIN_ENV_ID, **env_kwargs(8, pose_error_deg=30.0))
    try:
        obs, _ = env.reset(seed=3)
        np.testing.assert_allclose(demos["target_pose"][0], obs["target_pose"])
        np.testing.assert_allclose(demos["actions"][0], ScriptedPicker.for_env(env)(obs), atol=1e-6)
    finally:
        env.close()


@settings(max_examples=40, deadline=None)
@given(low=st.floats(-10, 200, allow_nan=False), high=st.floats(-10, 200, allow_nan=False))
def test_bad_pose_error_ranges_are_refused_by_name(low, high):
    if 0 <= low <= high <= 180:
        assert BCConfig(pose_error_range_deg=(low, high)).pose_error_range_deg == (low, high)
    else:
        with pytest.raises(ValueError, match="pose_error_range_deg"):
            BCConfig(pose_error_range_deg=(low, high))


def test_a_fixed_error_and_a_range_exclude_each_other():
    with pytest.raises(ValueError, match="pose_error_range_deg"):
        BCConfig(pose_error_deg=10.0, pose_error_range_deg=(0.0, 30.0))


def test_the_removed_privileged_teacher_is_refused_by_name_and_older_runs_still_read(tmp_path):
    """``teacher: truth`` (the privileged teacher, removed) is refused saying why; ``teacher:
    estimate``, which older bc runs record, reads as the scripted picker's recipe it was."""
    from sms3d_env.training.recipes import read_recipe
    from sms3d_env.training.zoo import RecipeError

    old = tmp_path / "old.yml"
    old.write_text("recipe: bc\nteacher: estimate\nepisodes: 10\n")
    assert read_recipe(old).config == BCConfig(episodes=10)
    truth = tmp_path / "truth.yml"
    truth.write_text("recipe: bc\nteacher: truth\n")
    with pytest.raises(RecipeError, match="teacher: the privileged teacher was removed in 0.2.0: its clone picked 24 %"):
        read_recipe(truth)

