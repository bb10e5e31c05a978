"""The wall-aware falling learning rate: it ends at its final value by steps or by wall clock."""

from __future__ import annotations

import pickle

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sms3d_env.training.schedules import WallAwareLinearSchedule


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_rate_follows_the_steps_while_they_are_ahead_of_the_clock():
    clock = FakeClock()
    rate = WallAwareLinearSchedule(1e-3, 1e-4, max_wall_s=1000.0, clock=clock)
    assert rate(1.0) == pytest.approx(1e-3)  # starts the clock
    clock.now += 100.0  # 10 % of the wall
    assert rate(0.5) == pytest.approx(1e-3 + 0.5 * (1e-4 - 1e-3))


def test_the_rate_follows_the_clock_once_it_is_ahead_of_the_steps():
    """The session-14 case: the wall stops the run at 82 % of its steps; the rate must be final."""
    clock = FakeClock()
    rate = WallAwareLinearSchedule(3e-4, 3e-5, max_wall_s=7000.0, clock=clock)
    rate(1.0)
    clock.now += 3500.0
    assert rate(0.9) == pytest.approx(3e-4 + 0.5 * (3e-5 - 3e-4))
    clock.now += 3500.0
    assert rate(1 - 0.82) == pytest.approx(3e-5)
    clock.now += 60.0  # past the wall (the step that stops the run): stays at the final rate
    assert rate(0.1) == pytest.approx(3e-5)


@given(st.floats(-0.5, 1.5), st.floats(0, 1e4), st.floats(1e-6, 0.5), st.floats(1e-6, 0.5))
def test_the_rate_stays_between_its_ends(progress_remaining, elapsed, start, end):
    clock = FakeClock()
    rate = WallAwareLinearSchedule(start, end, max_wall_s=600.0, clock=clock)
    rate(1.0)
    clock.now += elapsed
    assert min(start, end) - 1e-12 <= rate(progress_remaining) <= max(start, end) + 1e-12


def test_a_pickled_schedule_starts_its_clock_afresh():
    clock = FakeClock()
    rate = WallAwareLinearSchedule(1e-3, 1e-4, max_wall_s=10.0, clock=clock)
    rate(1.0)
    clock.now += 10.0
    assert rate(1.0) == pytest.approx(1e-4)
    loaded = pickle.loads(pickle.dumps(rate))
    assert loaded(1.0) == pytest.approx(1e-3)


@pytest.mark.parametrize("wall", [0.0, -1.0, float("inf"), float("nan"), None])
def test_a_wall_that_is_not_a_positive_time_is_refused_by_name(wall):
    with pytest.raises(ValueError, match="max_wall_s"):
        WallAwareLinearSchedule(1e-3, 1e-4, max_wall_s=wall)



def test_the_wall_clock_limit_stops_training_once_its_time_has_passed(monkeypatch):
    from sms3d_env.training import schedules

    now = [100.0]
    monkeypatch.setattr(schedules.time, "perf_counter", lambda: now[0])
    limit = schedules.wall_clock_limit(60.0)
    limit._on_training_start()
    now[0] = 159.0
    assert limit._on_step()
    now[0] = 160.0
    assert not limit._on_step()
