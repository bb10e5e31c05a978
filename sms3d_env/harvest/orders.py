"""Scripted harvest planners a grower would name: a pick order and a re-scan rule, read from the
observation and the action mask alone (``ScriptedOrder``), and ``run_harvest``, one bed with any
planner.

| order | next candidate |
| --- | --- |
| ``detection`` | the first available slot (the scan's order) |
| ``largest`` | the largest estimated cap |
| ``tallest`` | the highest estimated cap top |
| ``nearest`` | the nearest to the tool (a greedy nearest-neighbour tour) |
| ``isolated`` | the widest gap from its cap's edge to the nearest detected cap's edge |

| re-scan | when |
| --- | --- |
| ``never`` | only the first scan; stop when no candidate is left |
| ``after_pick`` | after every pick attempt |
| ``after_failure`` | after an attempt that collected nothing |

With any rule the planner also re-scans once when no candidate is left and it has picked since
its last scan (what the picks uncovered or moved), then stops. A candidate is tried at most
``max_attempts`` times per scan (1: no retry), and a spot where ``give_up_after`` picks failed
(an estimated cap top within ``SPOT_RADIUS`` of theirs, whatever the scan) is not tried again:
measured why, at a 10° pose error one bed of 20 re-scanned and retried one unpickable mushroom
93 times until the episode was truncated.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sms3d_env.harvest.scan import BED_FEATURES, CANDIDATE_FEATURES

ORDERS = ("detection", "largest", "tallest", "nearest", "isolated")
RESCANS = ("never", "after_pick", "after_failure")
#: Two estimated cap tops closer than this (m, horizontally) are the same spot for
#: ``give_up_after``. ASSUMPTION: the oracle and noisy sources keep a cap top where it is, and two
#: harvest-size caps (radius 25 mm or more) stand further apart.
SPOT_RADIUS = 0.01
_F = {name: i for i, name in enumerate(CANDIDATE_FEATURES)}
_B = {name: i for i, name in enumerate(BED_FEATURES)}
#: Each order's score per candidate row (the highest is picked; ties: the first slot).
_SCORES = {
    "detection": lambda rows: np.zeros(len(rows)),
    "largest": lambda rows: rows[:, _F["cap_diameter"]],
    "tallest": lambda rows: rows[:, _F["cap_top_z"]],
    "nearest": lambda rows: -rows[:, _F["tool_distance"]],
    "isolated": lambda rows: rows[:, _F["nearest_gap"]],
}


class ScriptedOrder:
    """A pick order and a re-scan rule (see the module's tables): ``planner(obs, mask) ->
    action``; ``reset()`` at each episode's start. ValueError for an unknown order or rule."""

    def __init__(self, order: str = "detection", rescan: str = "never", max_attempts: int = 1,
                 give_up_after: int = 2) -> None:
        if order not in ORDERS:
            raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
        if rescan not in RESCANS:
            raise ValueError(f"rescan must be one of {RESCANS}, got {rescan!r}")
        for name, value in (("max_attempts", max_attempts), ("give_up_after", give_up_after)):
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        self.order, self.rescan, self.max_attempts, self.give_up_after = order, rescan, max_attempts, give_up_after
        self.reset()

    @property
    def label(self) -> str:
        return f"{self.order}/{self.rescan}"

    def reset(self) -> None:
        self._last: np.ndarray | None = None  # the bed features after the last action
        self._picked_since_scan = False
        self._chosen = np.zeros(2)  # the estimated cap top (x, y) of the last pick tried
        self._failed: list[list] = []  # [spot (x, y), failed picks there]

    def __call__(self, obs: dict[str, np.ndarray], mask: np.ndarray) -> int:
        rows, bed = obs["candidates"], obs["bed"]
        k = len(rows)
        rescan, stop = k, k + 1
        last, self._last = self._last, bed
        if last is not None and bed[_B["scans"]] > last[_B["scans"]]:
            self._picked_since_scan = False
        elif last is not None and bed[_B["attempts"]] > last[_B["attempts"]]:
            self._picked_since_scan = True
            failed = bed[_B["picked"]] == last[_B["picked"]]
            if failed:
                self._count_failure()
            if self.rescan == "after_pick" or (self.rescan == "after_failure" and failed):
                return rescan
        allowed = mask[:k] & (rows[:, _F["attempts"]] < self.max_attempts) & ~self._given_up(rows)
        if not allowed.any():
            return rescan if self._picked_since_scan and self.rescan != "never" else stop
        score = np.where(allowed, _SCORES[self.order](rows), -np.inf)
        slot = int(np.argmax(score))
        self._chosen = rows[slot, _F["cap_top_x"]:_F["cap_top_y"] + 1].astype(float)
        return slot

    def _count_failure(self) -> None:
        for spot in self._failed:
            if np.linalg.norm(spot[0] - self._chosen) < SPOT_RADIUS:
                spot[1] += 1
                return
        self._failed.append([self._chosen.copy(), 1])

    def _given_up(self, rows: np.ndarray) -> np.ndarray:
        """Per row: its cap top lies at a spot where ``give_up_after`` picks failed."""
        spots = np.array([spot for spot, n in self._failed if n >= self.give_up_after]).reshape(-1, 2)
        if not len(spots):
            return np.zeros(len(rows), bool)
        tops = rows[:, _F["cap_top_x"]:_F["cap_top_y"] + 1]
        return (np.linalg.norm(tops[:, None] - spots[None], axis=2) < SPOT_RADIUS).any(axis=1)


def run_harvest(env: Any, planner: Any, seed: int | None = None, options: dict[str, Any] | None = None
                ) -> dict[str, Any]:
    """Harvest one bed: ``planner(obs, mask) -> action`` (``planner.reset()`` called if present)
    until the episode ends; the episode's summary (``BedTally.summary``) with its ``seed``,
    ``actions`` and ``return``."""
    u = env.unwrapped
    obs, _ = env.reset(seed=seed, options=options)
    if hasattr(planner, "reset"):
        planner.reset()
    total, actions, done, info = 0.0, 0, False, {}
    while not done:
        obs, reward, terminated, truncated, info = env.step(planner(obs, u.action_masks()))
        total += float(reward)
        actions += 1
        done = terminated or truncated
    return {"seed": seed, "actions": actions, "return": total, **info["summary"],
            "truncated": bool(truncated), "unstable_simulation": bool(info["unstable_simulation"])}
