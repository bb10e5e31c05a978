"""The episode's state record: what the picking model (:mod:`sms3d_env.picking_model`) and its
tool (:mod:`sms3d_env.tools`) know of the episode so far. Both read and write it; it depends on
neither, so the tools need not import the picking model that calls them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class EpisodeState:
    """What the picking model knows of the episode so far (mushroom ids index the scene)."""

    target: int = 0
    reachable: bool = True
    steps: int = 0  # control steps taken
    grip: int = -1  # mushroom id held (sealed by the cup, or pinched by the fingers), -1 if none
    grip_util: float = 0.0  # suction: seal load as a fraction of its capacity
    finger_force: float = 0.0  # hand: finger normal force on the target (N)
    tool_on: bool = False  # suction on, or hand commanded more closed than half
    ever_gripped_target: bool = False
    held_detached: bool = False  # hand: the target was held after its detachment
    finger_touch_step: int = -1  # hand: last env step in which a finger touched the target
    target_detached: bool = False
    grip_lost: bool = False  # the detached target's grip let go
    seal_overloaded: bool = False  # the seal on the rooted target let go before its root did
    bruised: set[int] = field(default_factory=set)
    slip_work: dict[int, float] = field(default_factory=dict)  # friction work slipping on each cap (J)
    detached: set[int] = field(default_factory=set)
    disturbed: set[int] = field(default_factory=set)
    unstable: bool = False
    max_lift: float = 0.0
    closest_approach: float = np.inf  # the tool site's least distance to the target's cap top (m)
    root_util: float = 0.0  # target root load / capacity, largest in this control step (reward only)
    seal_step: int = -1  # control step at which the current seal formed (-1: none)
    grip_step: int = -1  # control steps until the target was first held (-1: not yet)
    detach_step: int = -1  # control steps until the target's root let go (-1: not yet)
    seal_tool_x: np.ndarray | None = None  # tool x axis (world) when it formed
