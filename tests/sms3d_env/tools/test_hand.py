"""The hand's rules (``sms3d_env.tools.hand``) called directly: finger commands, the grip rule
(held = at least ``MIN_FINGERS`` fingers on one mushroom while the hand is commanded closed) and
the lost grip of a detached target that left the fingers."""

from __future__ import annotations

import numpy as np
import pytest

from sms3d_env.episode_state import EpisodeState
from sms3d_env.gantry import GantryConfig
from sms3d_env.tools import Hand
from sms3d_env.tools.hand import MIN_FINGERS


@pytest.fixture
def hand(make_world, upright) -> Hand:
    return Hand(make_world(GantryConfig(tool="hand")), None, EpisodeState(target=upright))


def _finger_geom(hand: Hand, finger: int) -> int:
    return int(np.nonzero(hand.finger_of_geom == finger)[0][0])


def _palm_geoms(hand: Hand) -> np.ndarray:
    model = hand.world.model
    return np.nonzero(model.geom_bodyid == model.body(hand.world.prefix + "hand_hand").id)[0]


def _touch(hand: Hand, mushroom: int, fingers: range | list[int], force: float = 1.0) -> None:
    for f in fingers:
        hand.on_contact(0, 0, _finger_geom(hand, f), mushroom, force)


def test_every_finger_has_contact_geoms_and_the_palm_is_no_finger(hand):
    assert sorted(set(hand.finger_of_geom[hand.world.robot_geom]) - {-1}) == [0, 1, 2]
    palm = _palm_geoms(hand)
    assert palm.size and (hand.finger_of_geom[palm] == -1).all()


def test_the_command_maps_minus_one_to_open_and_one_to_closed(hand):
    assert hand.command(-1.0) is False
    np.testing.assert_allclose(hand.world.data.ctrl[hand.act], hand.lo)
    assert hand.command(0.0) is False  # half closed is not closed
    np.testing.assert_allclose(hand.world.data.ctrl[hand.act], (hand.lo + hand.hi) / 2)
    assert hand.command(1.0) is True
    np.testing.assert_allclose(hand.world.data.ctrl[hand.act], hand.hi)
    hand.reset()  # fingers open at reset, whatever was commanded before
    assert hand.closure() == pytest.approx(0.0)
    np.testing.assert_allclose(hand.world.data.ctrl[hand.act], hand.lo)


@pytest.mark.parametrize("fingers, closed, held", [
    (range(MIN_FINGERS), True, True),
    (range(3), True, True),
    (range(MIN_FINGERS - 1), True, False),  # one finger only pushes
    ([1, 1, 1], True, False),  # three contacts of one finger are still one finger
    (range(3), False, False),  # fingers on the cap, hand commanded open
], ids=["two-fingers", "three-fingers", "one-finger", "one-finger-thrice", "hand-open"])
def test_a_mushroom_is_held_by_two_fingers_of_the_closed_hand(hand, fingers, closed, held):
    ep = hand.state
    ep.tool_on = hand.command(1.0 if closed else -1.0)
    _touch(hand, ep.target, fingers)
    hand.update_hold()
    assert (ep.grip == ep.target) is held
    assert ep.ever_gripped_target is held
    hand.update_hold()  # each physics step decides again from its own contacts
    assert ep.grip == -1


def test_a_palm_contact_holds_nothing(hand):
    ep = hand.state
    ep.tool_on = hand.command(1.0)
    _touch(hand, ep.target, [0])
    hand.on_contact(0, 0, int(_palm_geoms(hand)[0]), ep.target, 5.0)  # the palm is no second finger
    hand.update_hold()
    assert ep.grip == -1


def test_the_target_is_preferred_then_the_firmest_hold(hand):
    ep = hand.state
    ep.tool_on = hand.command(1.0)
    a, b = [k for k in range(len(hand.world.body_ids)) if k != ep.target][:2]
    _touch(hand, a, range(2), force=1.0)
    _touch(hand, b, range(1, 3), force=2.0)
    hand.update_hold()
    assert ep.grip == b
    _touch(hand, a, range(2), force=1.0)
    _touch(hand, ep.target, [0, 2], force=0.5)
    hand.update_hold()
    assert ep.grip == ep.target
    assert ep.finger_force == pytest.approx(1.0)


def test_a_detached_target_that_leaves_the_fingers_for_a_step_is_a_lost_grip(hand):
    ep = hand.state
    ep.tool_on, ep.target_detached = hand.command(1.0), True
    _touch(hand, ep.target, range(3))
    hand.update_hold()
    assert ep.held_detached
    hand.after_step()
    ep.steps += 1
    assert not ep.grip_lost  # touched in this step
    hand.update_hold()  # a step without finger contacts
    hand.after_step()
    assert ep.grip_lost
    assert not hand.dead_end()  # the hand's fingers detach a cap as they close: never a dead end
