"""Schedules for runs that a wall-clock limit may stop before their last step: the learning rate
(:func:`falling_learning_rate`) and the limit itself (:func:`wall_clock_limit`), both SB3
callbacks that an RL recipe names.

SB3 drives a schedule by ``progress_remaining``, the share of ``total_steps`` still to run. A run
stopped by ``max_wall_s`` never sees the end of that schedule: measured, a rate meant to fall
from 3e-4 to 3e-5 over 3.2M steps was still 8.4e-5 when the 2 h
limit stopped it at 2.62M, because the machine's share of CPU set the step rate, not the command.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any


class WallAwareLinearSchedule:
    """A rate falling linearly from ``start`` to ``end`` over whichever runs out first: the run's
    steps (SB3's progress) or ``max_wall_s`` seconds of wall clock, counted from the first call
    (SB3 first calls it when the model builds its optimiser, just before training).

    The rate at a call is ``start + (end - start) × min(1, max(1 − progress_remaining,
    elapsed / max_wall_s))``. So a run that the wall limit stops ends at ``end``, and a run that
    finishes its steps first keeps the schedule of :class:`stable_baselines3.common.utils.LinearSchedule`
    wherever its steps are ahead of the clock. The clock makes the rate depend on the machine's
    speed: two runs of one seed differ once the wall is ahead (as they already do where
    ``max_wall_s`` stops them).

    Pickled with a saved model; a loaded copy (and any ``copy.copy``/``deepcopy``) starts its
    clock afresh at its first call.
    """

    def __init__(self, start: float, end: float, max_wall_s: float,
                 clock: Callable[[], float] = time.perf_counter) -> None:
        if max_wall_s is None or not (math.isfinite(max_wall_s) and max_wall_s > 0):
            raise ValueError(f"WallAwareLinearSchedule.max_wall_s must be > 0, got {max_wall_s!r}")
        self.start, self.end, self.max_wall_s = float(start), float(end), float(max_wall_s)
        self.clock = clock
        self._t0: float | None = None

    def fraction_done(self, progress_remaining: float) -> float:
        """How far along the schedule is, in [0, 1]: the larger of the step and wall fractions
        (the first call starts the clock)."""
        now = self.clock()
        if self._t0 is None:
            self._t0 = now
        by_wall = (now - self._t0) / self.max_wall_s
        return min(1.0, max(1.0 - float(progress_remaining), by_wall, 0.0))

    def __call__(self, progress_remaining: float) -> float:
        return self.start + (self.end - self.start) * self.fraction_done(progress_remaining)

    def __getstate__(self) -> dict:
        # One process's clock means nothing in another (and a test's fake clock may not pickle).
        return {**self.__dict__, "_t0": None, "clock": time.perf_counter}


def falling_rate(start: float, end: float, max_wall_s: float | None = None) -> Callable[[float], float]:
    """A value falling linearly from ``start`` to ``end`` over the run's steps (SB3's
    ``LinearSchedule``) or, with ``max_wall_s``, over whichever ends first, the steps or that
    many seconds (:class:`WallAwareLinearSchedule`)."""
    from stable_baselines3.common.utils import LinearSchedule

    return (LinearSchedule(start, end, end_fraction=1.0) if max_wall_s is None
            else WallAwareLinearSchedule(start, end, max_wall_s))


def falling_learning_rate(final: float, max_wall_s: float | None = None) -> Any:
    """An SB3 callback: from the start of training, the model's learning rate falls linearly
    from its initial value to ``final`` (:func:`falling_rate`, over the steps or with
    ``max_wall_s`` whichever ends first): a schedule that an RL Zoo hyperparameter file cannot
    write (its ``lin_`` rates fall to 0)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _FallingLearningRate(BaseCallback):
        def _on_training_start(self) -> None:
            schedule = falling_rate(float(self.model.lr_schedule(1.0)), float(final), max_wall_s)
            schedule(1.0)  # a wall-aware schedule's clock starts at its first call: now, as training does
            self.model.learning_rate = self.model.lr_schedule = schedule

        def _on_step(self) -> bool:
            return True

    return _FallingLearningRate()



def wall_clock_limit(max_wall_s: float) -> Any:
    """An SB3 callback that stops training once ``max_wall_s`` seconds have passed since it began."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _StopAfter(BaseCallback):
        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()

        def _on_step(self) -> bool:
            return time.perf_counter() - self.t0 < max_wall_s

    return _StopAfter()
