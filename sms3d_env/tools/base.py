"""The ``Tool`` protocol: the rules one tool adds to the picking model.

The picking model (:mod:`sms3d_env.picking_model`) keeps what holds for any tool (contacts and
bruises, roots, neighbours, soil, success and failure) and calls its tool at fixed points of
every control step; the tool decides what it holds and when it lets go:

| hook | when | suction (:mod:`~sms3d_env.tools.suction`) | hand (:mod:`~sms3d_env.tools.hand`) |
| --- | --- | --- | --- |
| ``reset`` | reset, before the world settles | nothing | fingers open |
| ``command`` | start of a control step | valve: on if > 0 (latched: held while sealed); off releases | finger targets |
| ``on_contact`` | each robot-mushroom contact of a substep | seal test on a cup-cap contact | finger contact bookkeeping |
| ``update_hold`` | after the substep's contacts | nothing | held = at least two fingers, hand closed |
| ``check_hold`` | after the root check | seal load against its capacity | nothing (friction is MuJoCo's) |
| ``after_step`` | end of a control step | nothing | grip lost when a detached target left the fingers |
| ``dead_end`` | after a control step | target off its roots and not held, or a latched seal on a neighbour | never |
| ``observation`` | every observation | (on, sealed, seal load / capacity) | (closure, holding, finger force) |

A tool is built per episode on its ``World``, the ``PickPhysicsParams`` and the episode's
``EpisodeState`` (:mod:`sms3d_env.episode_state`; it reads and writes ``grip``, ``tool_on`` and
its own entries).
"""

from __future__ import annotations

from typing import Protocol


class Tool(Protocol):
    """One tool's rules in one episode."""

    #: ``"suction"`` or ``"hand"`` (``robot.TOOLS``).
    name: str
    #: Whether the picking model must run ``after_substep`` after every physics step, with no
    #: contact and nothing held too (the hand: its hold is re-decided from each step's contacts).
    checks_every_substep: bool

    def reset(self) -> None:
        """The tool's starting state, set before the world settles at reset."""

    def command(self, a: float) -> bool:
        """Apply the action's tool entry ``a`` in [-1, 1] for the coming control step; returns
        whether the tool is on (``EpisodeState.tool_on``)."""

    def on_contact(self, contact: int, geom: int, robot_geom: int, mushroom: int,
                   normal_force: float) -> None:
        """A contact (index ``contact`` in ``data.contact``) between the robot's ``robot_geom``
        and ``geom`` of ``mushroom``, with this normal force (N)."""

    def update_hold(self) -> None:
        """What the tool holds after this physics step's contacts (before the roots' check)."""

    def check_hold(self) -> None:
        """The hold's load after this physics step (after the roots' check)."""

    def after_step(self) -> None:
        """End of a control step (before the step counter advances)."""

    def dead_end(self) -> bool:
        """Whether the episode can no longer succeed by this tool's rules."""

    def observation(self) -> tuple[float, float, float]:
        """The observation's ``suction`` entry (three numbers a real tool's sensors give)."""
