"""``PregraspStart``: a share of resets that start the arm on the way from home to a pre-grasp
pose above the *estimated* target (a reverse curriculum for training); 0 (default) starts at
home and leaves the episode's random stream untouched."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sms3d_env  # noqa: F401  (registers the env ids)
from sms3d_env.pickers.episode import run_episode
from sms3d_env.pickers.scripted import ScriptedPicker
from sms3d_env.start_states import PregraspStart

BED = {"placement": {"num_mushrooms": 10}}


def _env(**kw):
    return gym.make("SMS3DPickTrain-v2", scene=BED, **kw)


def _start_distance(seed: int, **kw) -> float:
    """Distance (m) of the tool from the estimated cap top after a reset."""
    env = _env(pose_source="noisy", pose_error_deg=20.0, **kw)
    try:
        obs, _ = env.reset(seed=seed)
        assert np.abs(obs["joint_vel"]).max() < 0.05  # settled, not thrown
        return float(np.linalg.norm(obs["tool_in_target"][:3]))
    finally:
        env.close()


def test_pregrasp_starts_lie_on_the_way_from_home_to_the_estimate():
    home = [_start_distance(seed) for seed in range(6)]
    near = [_start_distance(seed, start=PregraspStart(1.0)) for seed in range(6)]
    # Between home and 2-8 cm above the estimated cap top; the 0.01 rad joint jitter moves the
    # tool by a few millimetres.
    for d_home, d in zip(home, near, strict=True):
        assert 0.015 <= d <= d_home + 0.01
    assert np.mean(near) < 0.8 * np.mean(home)
    assert min(near) < 0.5 * min(home)


def test_the_scripted_picker_picks_from_a_pregrasp_start():
    env = _env(start=PregraspStart(1.0))
    try:
        result = run_episode(env, ScriptedPicker.for_env(env.unwrapped), seed=0)
    finally:
        env.close()
    assert result["success"], result


def test_home_starts_are_the_default_and_draw_nothing_from_the_episode_stream():
    """The default starts at home without a draw; any share > 0 draws once per reset (here one
    so small that it too starts at home), so the stream after the reset differs by that draw."""
    runs = []
    for kw in ({}, {"start": {"share": 1e-300}}):
        env = _env(**kw)
        try:
            obs, _ = env.reset(seed=3)
            runs.append((obs, env.unwrapped.np_random.random()))
        finally:
            env.close()
    (a, next_a), (b, next_b) = runs
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])
    assert next_a != next_b
    np.testing.assert_allclose(a["joint_pos"], env.unwrapped.home_q, atol=0.05)


def test_info_names_each_episodes_start_and_the_share_can_change_between_episodes():
    env = _env()
    try:
        _, info = env.reset(seed=1)
        assert info["start"] == "home"
        assert env.step(np.zeros(7))[4]["start"] == "home"
        # Through the wrappers, as a VecEnv's env_method reaches it.
        env.get_wrapper_attr("set_pregrasp_start")(1.0)
        _, info = env.reset(seed=1)
        assert info["start"] == "pregrasp"
        assert env.step(np.zeros(7))[4]["start"] == "pregrasp"
        with pytest.raises(ValueError, match="share"):
            env.get_wrapper_attr("set_pregrasp_start")(1.5)
        assert env.unwrapped.start == PregraspStart(1.0)
    finally:
        env.close()


@settings(max_examples=20, deadline=None)
@given(st.one_of(st.floats(max_value=-1e-9), st.floats(min_value=1.0 + 1e-9), st.just(math.nan),
                 st.just(True)))
def test_a_pregrasp_share_outside_zero_to_one_is_refused_by_name(share):
    with pytest.raises(ValueError, match="PregraspStart.share"):
        PregraspStart(share)
