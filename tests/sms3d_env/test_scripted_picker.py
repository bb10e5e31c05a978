"""The scripted picker's phase switch from approach to descent, on hand-made observations."""

from __future__ import annotations

import numpy as np

from sms3d_env.pickers.scripted import ScriptedPicker


def _obs(tool_offset_m: float) -> dict[str, np.ndarray]:
    """The cup pointing straight down, ``tool_offset_m`` beside the stand-off point of an upright
    mushroom whose cap top is at the origin."""
    down = np.array([0.0, 1.0, 0.0, 0.0])  # (w, x, y, z): a half turn about x, tool z -> -z
    tool = np.concatenate([[tool_offset_m, 0.0, 0.03], down])
    return {"tool_pose": tool, "target_pose": np.array([0, 0, 0, 0, 0, 1.0]),
            "suction": np.zeros(3)}


def test_the_descent_starts_inside_the_approach_tolerance_only():
    strict = ScriptedPicker()
    strict(_obs(0.005))
    assert strict.phase == "approach"  # 5 mm off: outside the default 3 mm
    loose = ScriptedPicker(approach_tolerance=0.008, approach_tolerance_deg=10.0)
    loose(_obs(0.005))
    assert loose.phase == "descend"
    on_point = ScriptedPicker()
    on_point(_obs(0.001))
    assert on_point.phase == "descend"
