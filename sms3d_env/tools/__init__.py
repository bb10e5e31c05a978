"""The tools, each behind the ``Tool`` protocol (:mod:`~sms3d_env.tools.base`): the suction cup
(:mod:`~sms3d_env.tools.suction`) and the Jaco 3-finger hand (:mod:`~sms3d_env.tools.hand`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from sms3d_env.tools.base import Tool
from sms3d_env.tools.hand import Hand
from sms3d_env.tools.suction import Suction

if TYPE_CHECKING:
    from sms3d_env.episode_state import EpisodeState
    from sms3d_env.physics_params import PickPhysicsParams
    from sms3d_env.world import World

__all__ = ["Hand", "Suction", "Tool", "make_tool"]


def make_tool(world: World, params: PickPhysicsParams, state: EpisodeState, latched: bool = False) -> Tool:
    """The rules of ``world.tool`` for one episode; ``latched``: the suction valve's training
    option (ValueError with the hand)."""
    if world.tool == "suction":
        return Suction(world, params, state, latched)
    if latched:
        raise ValueError(f"a latched valve applies to the suction tool only (tool={world.tool!r})")
    return Hand(world, params, state)
