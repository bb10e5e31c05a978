"""The privileged teacher of the imitation recipe (``teacher="truth"``): the scripted picker's
decisions on the observation, its motions after the approach on the true pose.

A clone can only learn what is a function of its observation. A teacher that runs the scripted
picker on the true pose decides "the approach is done" 3 mm from the *true* stand-off point,
which a clone that sees only the estimate never reaches; it hovers there, its suction command
averaged to ≈ −0.25 (measured: 1 / 100 episodes at 0° error, no_seal 99; and 0 / 3 with an 8 mm,
10° tolerance). Here every phase switch is the scripted picker's on the observation (approach to
the *estimated* stand-off point, the seal as the vacuum sensor reports it, the travel counted),
and from the descent on the motion is what the true pose asks for: down onto the true stem axis
with the cup turned onto it, then the twist about it. What the clone learns there is what the
estimate and the wrist wrench say about the true axis.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sms3d_env.pickers.scripted import HandPicker, ScriptedPicker


class PrivilegedTeacher:
    """``teacher(obs, true_obs) -> action``; ``true_obs`` is ``obs`` with the true target pose.

    Args:
        env: a suction env (the hand's grasp is not taught this way).
    """

    def __init__(self, env: Any) -> None:
        self.picker = ScriptedPicker.for_env(env)
        if isinstance(self.picker, HandPicker):
            raise ValueError("the privileged teacher drives the suction tool only, got tool='hand'")

    @property
    def phase(self) -> str:
        return self.picker.phase

    def reset(self) -> None:
        self.picker.reset()

    def __call__(self, obs: dict[str, np.ndarray], true_obs: dict[str, np.ndarray]) -> np.ndarray:
        p = self.picker
        before = p.phase
        action = p(obs)  # the phase machine runs on what the robot observes
        truth = p.view(true_obs)
        if before == "descend" and p.phase == "descend":
            return p._action(p._descend_velocity(truth), p._align(truth), p.hold_command)
        if before == "twist":
            return p._action(*p._twist_velocity(truth), p.hold_command)
        return action
