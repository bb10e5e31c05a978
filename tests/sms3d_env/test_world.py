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


def _colliding_env(num_mushrooms: int, overlap_iou: float = 0.0, collide: bool = True):
    from sms3d_env.physics_params import PickPhysicsParams

    bed = SceneConfig().replace(placement__num_mushrooms=num_mushrooms, placement__overlap_iou=overlap_iou)
    return gym.make("SMS3DPick-v1", scene=bed, physics=PickPhysicsParams(mushrooms_collide=collide))


@pytest.mark.parametrize("collide", [False, True])
def test_a_loose_cap_dropped_on_a_neighbour_touches_it_only_when_mushrooms_collide(collide):
    import mujoco

    env = _colliding_env(10, collide=collide)
    env.reset(seed=3)
    w = env.unwrapped.world
    m, d = w.model, w.data
    i, j = 0, 1
    # Drop mushroom j's cap onto mushroom i's: free it from its root and move it above i.
    d.eq_active[w.root_eq[j]] = 0
    adr = m.jnt_qposadr[m.body_jntadr[w.body_ids[j]]]
    d.qpos[adr:adr + 3] = d.xpos[w.body_ids[i]] + [0.0, 0.0, 0.01]
    m.opt.enableflags &= ~int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    mujoco.mj_forward(m, d)
    pairs = {tuple(sorted(w.geom_mushroom[g] for g in d.contact.geom[c])) for c in range(d.ncon)}
    assert ((i, j) in pairs) is collide


def test_seeded_100_mushroom_beds_placed_without_overlap_do_not_interpenetrate_at_rest():
    from sms3d_env.world import interpenetrating_mushrooms

    env = _colliding_env(100)
    for seed in (1_000_000, 1_000_001):
        env.reset(seed=seed)  # refused if any pair interpenetrated by more than 1 mm
        w = env.unwrapped.world
        assert interpenetrating_mushrooms(w.model, w.geom_mushroom) == []


def test_a_bed_whose_mushrooms_interpenetrate_is_refused_when_they_collide():
    env = _colliding_env(25, overlap_iou=0.05)  # the paper's placement lets volumes overlap by 5 %
    with pytest.raises(ValueError, match=r"interpenetrate by .* mm at rest.*overlap_iou = 0"):
        env.reset(seed=1_000_000)


def test_a_pool_bed_that_interpenetrates_is_refused_at_every_draw_not_only_the_first():
    from sms3d_env.physics_params import PickPhysicsParams

    bed = {"config": {"placement": {"num_mushrooms": 25}}, "pool": 1}  # the paper's 5 % overlap
    env = gym.make("SMS3DPick-v1", scene=bed, physics=PickPhysicsParams(mushrooms_collide=True))
    for seed in (0, 1):
        with pytest.raises(ValueError, match="interpenetrate"):
            env.reset(seed=seed)
