"""The start-state curriculum that follows home-start success (the PPO recipe's ``pregrasp_annealing`` callback)."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from hypothesis import given
from hypothesis import strategies as st
from stable_baselines3.common.logger import Logger

from sms3d_env.training.curriculum import (
    HOME_WINDOW,
    MIN_HOME_EPISODES,
    annealed_share,
    pregrasp_annealing,
)

unit = st.floats(min_value=0.0, max_value=1.0)


@given(unit, unit, unit)
def test_the_share_falls_from_its_start_to_zero_as_home_starts_succeed(initial, s1, s2):
    assert annealed_share(initial, 0.0) == initial and annealed_share(initial, 1.0) == 0.0
    lo, hi = sorted((s1, s2))
    assert 0.0 <= annealed_share(initial, hi) <= annealed_share(initial, lo) <= initial


class _Envs:
    """A VecEnv's ``env_method``, recorded."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, float]] = []

    def env_method(self, name: str, value: float) -> None:
        self.calls.append((name, value))


def _episode_ends(cb, starts_and_successes):
    for start, success in starts_and_successes:
        cb.update_locals({"infos": [{"start": start, "is_success": success}, {}], "dones": [True, False]})
        cb.on_step()


def test_only_finished_home_starts_move_the_share():
    envs = _Envs()
    cb = pregrasp_annealing(0.8)
    cb.init_callback(SimpleNamespace(get_env=lambda: envs, logger=Logger(None, []), num_timesteps=0))
    # Too few home episodes: the share stays at its start, whatever the curriculum starts did.
    _episode_ends(cb, [("pregrasp", True)] * 50 + [("home", True)] * (MIN_HOME_EPISODES - 1))
    cb.on_rollout_end()
    assert envs.calls[-1] == ("set_pregrasp_start", pytest.approx(0.8))
    # 9 + 8 of 20 home starts succeeded: 0.8 x (1 - 17 / 20).
    _episode_ends(cb, [("home", False)] * 3 + [("home", True)] * 8)
    cb.on_rollout_end()
    assert envs.calls[-1] == ("set_pregrasp_start", pytest.approx(0.8 * (1 - 17 / 20)))
    # The window keeps the last HOME_WINDOW home episodes: all failures now.
    _episode_ends(cb, [("home", False)] * HOME_WINDOW)
    cb.on_rollout_end()
    assert envs.calls[-1] == ("set_pregrasp_start", pytest.approx(0.8))

