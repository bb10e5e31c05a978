"""Where the arm starts an episode (the env's ``start`` argument; None: at home).

``PregraspStart`` is a reverse curriculum after Florensa et al. 2017, "Reverse Curriculum
Generation for Reinforcement Learning": a share of resets start the arm on the way from home to
a pre-grasp pose, so that the seal, twist and lift are met from the first episodes and the
approach is learned backwards from them. Its start states are the ones a real arm reaches by its
planner from the same estimate.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sms3d_env.records import check_number

if TYPE_CHECKING:  # the record stays light: scipy and MuJoCo load with the env
    from sms3d_env.targets import Reachability


def check_share(name: str, share: object) -> None:
    """ValueError naming ``name`` unless ``share`` is a probability in [0, 1]."""
    check_number(name, share, 0.0, 1.0, "a probability in [0, 1]")


@dataclass(frozen=True)
class PregraspStart:
    """Start a share of episodes on the way from home to a pre-grasp pose (a training option).

    Attributes:
        share: the probability that a reset starts there: the joints at a uniformly drawn
            fraction of the way from home to a configuration with the cup on the *estimated*
            stem axis 2–8 cm above the estimated cap top, facing down it, each then moved by
            N(0, 0.01 rad) (a few millimetres and about a degree at the tool); at home where
            that pose has no IK solution. 0 always starts at home and draws nothing from the
            episode's random stream. ``SMS3DPickEnv.set_pregrasp_start`` changes it between
            episodes (a training schedule reaches it through ``VecEnv.env_method``).
    """

    share: float = 0.0

    def __post_init__(self) -> None:
        check_share("PregraspStart.share", self.share)

    def configuration(self, rng: np.random.Generator, reach: Reachability, home_q: np.ndarray,
                      cap_top: np.ndarray, stem_axis: np.ndarray) -> tuple[np.ndarray, str]:
        """The arm's start joints (rad or m, as ``home_q``) for the estimated ``cap_top`` (m) and
        ``stem_axis``, and which start it is (``info["start"]``: ``"home"`` or ``"pregrasp"``); the
        draws from ``rng``."""
        if not (self.share > 0 and rng.random() < self.share):
            return home_q, "home"
        q_pre = reach.solve(cap_top, stem_axis, (0.08, rng.uniform(0.02, 0.08)))
        if q_pre is None:
            return home_q, "pregrasp"
        q = home_q + rng.uniform() * (q_pre - home_q)
        return np.clip(q + rng.normal(0.0, 0.01, q.shape), reach.lo, reach.hi), "pregrasp"
