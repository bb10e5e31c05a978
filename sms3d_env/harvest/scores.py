"""What happened to each mushroom of a harvested bed, and the bed's scores.

| score | definition |
| --- | --- |
| yield | harvest-ready mushrooms picked clean / harvest-ready mushrooms in the bed |
| picked clean | collected, never bruised, and taken off its roots by its own pick (not knocked off before) |
| bruised | a cap bruised (any pick: the robot's contact or slip, or a neighbour's), collected or not |
| knocked off | off its roots other than by its own successful pick (a neighbour's pick, or its own pick that dropped it), collected later or not |
| moved | rooted, and moved further than ``PickPhysicsParams.disturb_tolerance`` during some pick |
| damaged | bruised, knocked off or moved, and not picked clean: ``damaged_share`` of the bed |
| missed | harvest-ready and not collected |
| mushrooms per hour | mushrooms collected per hour of simulated episode time (``clean_per_hour``: picked clean) |

Damage is split into harvest-ready (cap >= ``harvest_diameter``, true) and not ready.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: The damage kinds counted, each split ready / not ready.
DAMAGE_KINDS = ("bruised", "knocked_off", "moved")
#: Where the episode's simulated time went (s): ``travel`` (timed moves to each pick's start),
#: ``carry`` (to the collection point and the drop), ``scan`` and ``pick`` (the simulated picks,
#: their settling included).
TIME_PARTS = ("travel", "carry", "scan", "pick")


@dataclass
class BedTally:
    """The running account of one harvest episode (mushroom ids index the bed)."""

    ready: np.ndarray  # (n,) bool: the true cap is at least the harvest size
    collected: list[int] = field(default_factory=list)  # in the order they were collected
    clean: set[int] = field(default_factory=set)
    bruised: set[int] = field(default_factory=set)
    knocked_off: set[int] = field(default_factory=set)
    moved: set[int] = field(default_factory=set)
    time: dict[str, float] = field(default_factory=lambda: dict.fromkeys(TIME_PARTS, 0.0))
    scans: int = 0
    attempts: int = 0
    retries: int = 0
    failed_attempts: int = 0

    @property
    def time_s(self) -> float:
        return float(sum(self.time.values()))

    def damaged(self) -> set[int]:
        """Mushrooms bruised, knocked off or moved and not picked clean."""
        return (self.bruised | self.knocked_off | self.moved) - self.clean

    def record_pick(self, target: int, collected: bool, bruised: set[int], detached: set[int],
                    disturbed: set[int]) -> tuple[bool, set[int]]:
        """Add one pick of ``target``: whether it was collected, and the pick's bruised,
        detached and disturbed mushrooms (the picking model's sets). Returns (picked clean,
        the mushrooms damaged anew)."""
        before = self.damaged()
        clean = collected and target not in self.knocked_off and target not in self.bruised and target not in bruised
        self.bruised |= bruised
        self.knocked_off |= detached - ({target} if collected else set())
        self.moved |= disturbed - detached - {target}
        if collected:
            self.collected.append(target)
            if clean:
                self.clean.add(target)
        return clean, self.damaged() - before

    def _split(self, ids: set[int]) -> dict[str, int]:
        ready = sum(1 for i in ids if self.ready[i])
        return {"ready": ready, "not_ready": len(ids) - ready}

    def summary(self) -> dict[str, Any]:
        """The bed's scores (see the module's table); JSON-ready."""
        n, n_ready = len(self.ready), int(self.ready.sum())
        clean_ready = sum(1 for i in self.clean if self.ready[i])
        hours = self.time_s / 3600.0
        missed = n_ready - sum(1 for i in set(self.collected) if self.ready[i])
        damaged = self.damaged()
        return {
            "mushrooms": n, "harvest_ready": n_ready, "picked": len(self.collected),
            "picked_clean": len(self.clean), "picked_clean_ready": clean_ready,
            "picked_not_ready": sum(1 for i in self.collected if not self.ready[i]),
            "yield": clean_ready / n_ready if n_ready else float("nan"),
            "missed": missed,
            "damage": {kind: self._split(getattr(self, kind)) for kind in DAMAGE_KINDS},
            "damaged": self._split(damaged), "damaged_share": len(damaged) / n if n else 0.0,
            "mushrooms_per_hour": len(self.collected) / hours if hours > 0 else 0.0,
            "clean_per_hour": len(self.clean) / hours if hours > 0 else 0.0,
            "scans": self.scans, "attempts": self.attempts, "retries": self.retries,
            "failed_attempts": self.failed_attempts,
            "time_s": self.time_s, **{f"time_{k}_s": v for k, v in self.time.items()},
        }
