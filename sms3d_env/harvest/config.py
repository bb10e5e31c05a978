"""The harvest env's options (``HarvestConfig``, its ``harvest`` argument): what a scan costs, how
the harvester moves above the bed, where the picked mushrooms go, and the reward's weights.

Every number here without a published source is an ASSUMPTION and says so (docs/physics.md,
"Harvest").
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from generator.errors import ConfigError
from sms3d_env.targets import HARVEST_DIAMETER


def _number(name: str, value: Any, low: float, high: float = math.inf, what: str = "") -> None:
    ok = (not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
          and low <= value <= high)
    if not ok:
        raise ConfigError(f"HarvestConfig.{name}", f"must be {what or f'a finite number in [{low}, {high}]'}, "
                                                   f"got {value!r}")


def _integer(name: str, value: Any, least: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise ConfigError(f"HarvestConfig.{name}", f"must be an integer >= {least}, got {value!r}")


@dataclass(frozen=True)
class HarvestConfig:
    """Options of ``SMS3DHarvest-v0`` (the env's ``harvest`` argument, or its mapping form).

    Attributes:
        max_candidates: K, the candidate slots of the observation and of the pick actions. A
            scan that grades more mushrooms harvest-ready keeps the first K in its order (the
            rest wait for a later scan; ``info["candidates_dropped"]``).
        harvest_diameter: a detected cap at least this wide (m, estimated) is a candidate; the
            score's harvest-ready mushrooms are those whose true cap is (``targets.HARVEST_DIAMETER``:
            what a farm picks now).
        max_tilt_deg: a candidate whose estimated stem axis leans further from vertical (deg) is
            unreachable (masked), as for the pick env's target rules.
        scan_time: simulated seconds a scan (an overhead image and its processing) takes.
            ASSUMPTION: 1.0 s: both stages of the shipped perception pipeline took 0.84-0.93 s
            per bed (docs/results-perception.md), plus an exposure.
        travel_speed: top speed of a timed move above the bed (m/s per axis). ASSUMPTION: 0.5 m/s,
            the gantry's slide speed limit (``ControllerConfig.max_slide_speed``).
        travel_accel: acceleration of a timed move (m/s^2 per axis). ASSUMPTION: 1.0 m/s^2, a
            small belt axis carrying a mushroom on a suction cup.
        travel_height: height of the tool above the soil's plane (m, world z) on a timed move:
            clear of every cap with a mushroom hanging from the cup. ASSUMPTION: 0.20 m, the
            gantry's home.
        pick_clearance: the timed move hands over to the simulated pick with the cup this far
            (m) above the estimated cap top on the estimated stem axis, facing down it.
            ASSUMPTION: 0.05 m, the first pose of the IK's posture target
            (``posture.POSTURE_OFFSETS``).
        collection_point: (x, y) of the collection point (m, world): a tray beside the bed,
            within the gantry's rails (+-0.40 m) and outside the 0.7 m terrain patch; each
            picked mushroom is carried there, and the next pick starts from there.
            ASSUMPTION: (0.38, 0.0). None: a tray on the head, so a picked mushroom is dropped
            where it was picked (``drop_time``, no trip) and the next pick starts from there.
        drop_time: seconds to release a mushroom at the collection point (valve off, the cap
            off the cup). ASSUMPTION: 0.2 s.
        max_pick_steps: control steps one pick may take (the pick env's registered limit, 250:
            10 s).
        max_actions: actions after which the episode is truncated.
        reward_clean: reward per harvest-ready mushroom picked clean. ASSUMPTION (a weight).
        reward_damage: penalty per mushroom newly damaged (bruised, knocked off or moved).
            ASSUMPTION (a weight): a damaged mushroom costs what a clean one earns.
        reward_per_second: penalty per simulated second. ASSUMPTION (a weight): 0.02, so a pick
            cycle of ~7 s costs about a seventh of what a clean pick earns.
    """

    max_candidates: int = 48
    harvest_diameter: float = HARVEST_DIAMETER
    max_tilt_deg: float = 45.0
    scan_time: float = 1.0
    travel_speed: float = 0.5
    travel_accel: float = 1.0
    travel_height: float = 0.20
    pick_clearance: float = 0.05
    collection_point: tuple[float, float] | None = (0.38, 0.0)
    drop_time: float = 0.2
    max_pick_steps: int = 250
    max_actions: int = 200
    reward_clean: float = 1.0
    reward_damage: float = 1.0
    reward_per_second: float = 0.02

    def __post_init__(self) -> None:
        _integer("max_candidates", self.max_candidates, 1)
        _integer("max_pick_steps", self.max_pick_steps, 1)
        _integer("max_actions", self.max_actions, 1)
        _number("harvest_diameter", self.harvest_diameter, 0.0, 0.2, "a cap diameter in [0, 0.2] m")
        _number("max_tilt_deg", self.max_tilt_deg, 0.0, 90.0)
        _number("scan_time", self.scan_time, 0.0, what="a finite number of seconds >= 0")
        _number("drop_time", self.drop_time, 0.0, what="a finite number of seconds >= 0")
        for name in ("travel_speed", "travel_accel"):
            _number(name, getattr(self, name), 1e-9, what="a finite number > 0")
        _number("travel_height", self.travel_height, 0.0, 1.0, "a height in [0, 1] m")
        _number("pick_clearance", self.pick_clearance, 0.0, 0.2, "a distance in [0, 0.2] m")
        point = self.collection_point
        if point is None:
            pass
        elif (not isinstance(point, (tuple, list)) or len(point) != 2
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                           for v in point)):
            raise ConfigError("HarvestConfig.collection_point", f"must be None or two finite numbers (x, y) in m, "
                                                                f"got {point!r}")
        else:
            object.__setattr__(self, "collection_point", (float(point[0]), float(point[1])))
        for name in ("reward_clean", "reward_damage", "reward_per_second"):
            _number(name, getattr(self, name), 0.0, what="a finite weight >= 0")
