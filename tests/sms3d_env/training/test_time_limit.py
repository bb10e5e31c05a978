"""The time limit reported as a termination for time-aware training (``TimeLimitAsTerminal``)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import sms3d_env  # noqa: F401  (registers the env ids)
from sms3d_env.training.time_limit import TimeLimitAsTerminal

LIMIT = 6


def _run_to_end(env: gym.Env, seed: int) -> list[tuple[bool, bool, dict]]:
    env.reset(seed=seed)
    steps = []
    while True:
        _, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, np.float32))
        steps.append((terminated, truncated, info))
        if terminated or truncated:
            return steps


def test_the_limit_step_terminates_and_everything_else_is_unchanged():
    plain = gym.make("SMS3DPickTrain-v0", max_episode_steps=LIMIT)
    wrapped = TimeLimitAsTerminal(gym.make("SMS3DPickTrain-v0", max_episode_steps=LIMIT))
    try:
        for seed in (0, 1):  # and again after a reset: the count starts afresh
            a, b = _run_to_end(plain, seed), _run_to_end(wrapped, seed)
            assert len(a) == len(b) == LIMIT
            assert a[-1][:2] == (False, True) and b[-1][:2] == (True, False)
            assert b[-1][2]["time_limit_reached"] is True and "time_limit_reached" not in a[-1][2]
            assert all(x[:2] == y[:2] == (False, False) for x, y in zip(a[:-1], b[:-1]))
            assert a[-1][2]["failure_cause"] == b[-1][2]["failure_cause"]
    finally:
        plain.close()
        wrapped.close()


class _Unstable(gym.Env):
    """Truncates its first step as an unstable simulation would."""

    observation_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def reset(self, *, seed=None, options=None):
        return np.zeros(1, np.float32), {}

    def step(self, action):
        return np.zeros(1, np.float32), 0.0, False, True, {"unstable_simulation": True}


def test_an_unstable_simulation_at_the_limit_stays_a_truncation():
    gym.register("_UnstableForTimeLimitTest-v0", entry_point=_Unstable, max_episode_steps=1)
    env = TimeLimitAsTerminal(gym.make("_UnstableForTimeLimitTest-v0"))
    env.reset(seed=0)
    _, _, terminated, truncated, info = env.step(np.zeros(1, np.float32))
    assert (terminated, truncated) == (False, True) and "time_limit_reached" not in info


def test_an_env_without_a_time_limit_is_refused():
    with pytest.raises(ValueError, match="time limit"):
        TimeLimitAsTerminal(gym.make("SMS3DPickTrain-v0", max_episode_steps=None).unwrapped)
