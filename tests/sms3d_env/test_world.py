"""The world of one episode (``sms3d_env.world``): collision filtering between the robot, the soil
and the mushrooms, and which mushrooms are free to move (``free_set``, ``free_radius``)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import sms3d_env  # noqa: F401  (registers the ids)
from generator import SceneConfig
from sms3d_env.gantry import GantryConfig
from sms3d_env.robots import ROBOTS
from sms3d_env.world import free_set

SMALL = SceneConfig().replace(placement__num_mushrooms=10)


@pytest.mark.parametrize("robot", ROBOTS)
def test_every_robot_body_can_touch_the_soil_and_every_mushroom(robot, can_touch):
    env = gym.make("SMS3DPick-v1", robot=robot, scene=SMALL)
    env.reset(seed=3)
    u = env.unwrapped
    m, w = u.model, u.world
    robot_bodies = {int(m.geom_bodyid[g]) for g in np.nonzero(w.robot_geom)[0]}
    assert len(robot_bodies) >= 6
    mushroom_geoms = np.concatenate([w.cap_geoms, w.stem_geoms])
    for body in robot_bodies:
        geoms = np.nonzero((m.geom_bodyid == body) & w.robot_geom)[0]
        name = m.body(body).name
        assert any(can_touch(m, g, w.terrain_geom) for g in geoms), f"{name} passes through the soil"
        for k in mushroom_geoms:
            assert any(can_touch(m, g, k) for g in geoms), f"{name} passes through {m.geom(k).name}"


def test_only_mushrooms_within_the_free_radius_move_and_meet_the_robot(bed, upright, make_world, can_touch):
    bases = np.array([inst.position for inst in bed.instances])
    distance = np.linalg.norm(bases - bases[upright], axis=1)
    radius = float(np.sort(distance)[2:4].mean())  # between the third and fourth nearest: 3 free
    free = free_set(bed, upright, radius)
    assert len(free) == 3 and upright in free
    assert all((distance[k] <= radius) == (k in free) for k in range(len(bases)))
    assert free_set(bed, upright, None) == set(range(len(bases)))

    world = make_world(GantryConfig(), upright, radius)
    m = world.model
    assert set(world.free_ids.tolist()) == free == set(np.nonzero(world.is_free)[0].tolist())
    robot = np.nonzero(world.robot_geom)[0]
    for k in range(len(bases)):
        moves = k in free
        # A free joint, a root weld and (suction) a grip weld for the free ones only.
        assert (world.dofadr[k] >= 0, world.root_eq[k] >= 0, world.grip_eq[k] >= 0) == (moves,) * 3
        for g in (world.cap_geoms[k], world.stem_geoms[k]):
            assert can_touch(m, g, world.cup_geom) is moves, m.geom(g).name
            assert any(can_touch(m, g, r) for r in robot) is moves
            assert not can_touch(m, g, world.terrain_geom)  # rooted: the soil waits for the lift
