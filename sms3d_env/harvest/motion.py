"""Timed moves above the bed: where the harvester's tool travels between picks, to the
collection point and back, at ``HarvestConfig.travel_height``.

Above the bed nothing is there to touch (every cap stands below the travel height, the mushroom
hanging from the cup included), so these moves are timed rather than simulated: each axis of the
gantry runs a trapezoidal speed profile (``travel_accel`` up to ``travel_speed``, down again),
x and y together, the lift before and after. The simulated arm is placed where the move ends
(``SMS3DPickEnv.start_pick``). KNOWN SIMPLIFICATION: the wrist turns onto the next axis during
the move at no cost of time, and the Jaco's joint motion is timed as the gantry's would be.
"""

from __future__ import annotations

import math

import numpy as np


def axis_time(distance: float, speed: float, accel: float) -> float:
    """Seconds to move ``distance`` (m) from rest to rest on one axis with a trapezoidal speed
    profile (``accel`` m/s^2 up to ``speed`` m/s; a triangle where the distance is too short to
    reach it)."""
    distance = abs(float(distance))
    if distance * accel <= speed * speed:
        return 2.0 * math.sqrt(distance / accel)
    return distance / speed + speed / accel


class Motion:
    """Moves of the tool between points (m, world) over the bed: up to ``height``, across (x and
    y at once), down; ``speed`` and ``accel`` per axis."""

    def __init__(self, speed: float, accel: float, height: float) -> None:
        self.speed, self.accel, self.height = float(speed), float(accel), float(height)

    def time(self, start: np.ndarray, end: np.ndarray) -> float:
        """Seconds from ``start`` to ``end`` by way of the travel height (a point above it is
        reached straight)."""
        start, end = np.asarray(start, float), np.asarray(end, float)
        t = self.speed, self.accel
        across = max(axis_time(end[0] - start[0], *t), axis_time(end[1] - start[1], *t))
        return (axis_time(max(0.0, self.height - start[2]), *t) + across
                + axis_time(max(0.0, self.height - end[2]), *t))
