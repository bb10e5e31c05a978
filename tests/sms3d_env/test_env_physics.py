"""Picking physics and pose sources on real MuJoCo scenes."""

import gymnasium as gym
import numpy as np
import pytest

import generator
import sms3d_env
from sms3d_env.pose_sources import NoisyPose, OraclePose

SMALL = generator.SceneConfig().replace(placement__num_mushrooms=8)


def test_holding_force_from_vacuum_and_area():
    p = sms3d_env.PickPhysicsParams()
    assert p.holding_force == pytest.approx(20e3 * np.pi * 0.01**2)
    with pytest.raises(ValueError):
        sms3d_env.PickPhysicsParams(seal_angle_deg=95)


def test_mushrooms_stay_rooted_under_gravity_and_small_push():
    env = gym.make("SMS3DPick-v0", scene=SMALL).unwrapped
    env.reset(seed=0)
    start = env.data.xpos[env.world.body_ids].copy()
    for _ in range(25):  # 1 s with the arm still
        env.step(np.zeros(7, np.float32))
    assert np.linalg.norm(env.data.xpos[env.world.body_ids] - start, axis=1).max() < 0.002
    assert all(env.data.eq_active[env.world.root_eq[env.world.root_eq >= 0]])
    # A small push (0.3 N) on every mushroom for 0.5 s does not uproot any.
    import mujoco

    for _ in range(250):
        env.data.xfrc_applied[env.world.body_ids, 0] = 0.3
        mujoco.mj_step(env.model, env.data)
        env.picking.after_substep()
    assert all(env.data.eq_active[env.world.root_eq[env.world.root_eq >= 0]])
    assert np.linalg.norm(env.data.xpos[env.world.body_ids] - start, axis=1).max() < 0.005


def test_noisy_pose_error_is_exact():
    scene = generator.generate_scene(SMALL, seed=0)
    rng = np.random.default_rng(0)
    truth = OraclePose()(scene, 0, rng)
    for deg in (5.0, 30.0):
        est = NoisyPose(deg)(scene, 0, rng)
        ang = np.degrees(np.arccos(np.clip(est.stem_axis @ truth.stem_axis, -1, 1)))
        assert ang == pytest.approx(deg, abs=1e-6)
        np.testing.assert_allclose(est.cap_top, truth.cap_top)


def test_target_override_and_rule():
    env = gym.make("SMS3DPick-v0", scene=SMALL).unwrapped
    _, info = env.reset(seed=0, options={"target": 2})
    assert info["target"] == 2
    _, info = env.reset(seed=0)
    tallest = max(range(8), key=lambda i: env.scene.instances[i].cap_top[2])
    if info["reachable"]:
        heights = [inst.cap_top[2] for inst in env.scene.instances]
        assert heights[info["target"]] <= heights[tallest]


def test_failure_cause_vocabulary():
    env = gym.make("SMS3DPick-v0", scene=SMALL, max_episode_steps=5)
    env.reset(seed=0)
    for _ in range(5):
        *_, te, tr, info = env.step(np.zeros(7, np.float32))
    assert info["failure_cause"] in sms3d_env.FAILURE_CAUSES
    assert info["is_success"] is False


TOOL_GEOMS = {
    "suction": ["jaco/tube", "jaco/flange", "jaco/cup_face"],
    "hand": ["jaco/hand_link_6_main", "jaco/hand_finger_knuckle_1", "jaco/hand_finger_tip_2"],
}


@pytest.mark.parametrize("tool", list(TOOL_GEOMS))
def test_wrist_hand_and_tool_collide_with_soil_and_mushrooms_not_with_the_arm(tool):
    env = gym.make("SMS3DPick-v0", scene=SMALL, tool=tool).unwrapped
    env.reset(seed=0)
    m = env.model

    def collide(g1: int, g2: int) -> bool:
        return bool((m.geom_contype[g1] & m.geom_conaffinity[g2])
                    or (m.geom_contype[g2] & m.geom_conaffinity[g1]))

    soil = m.geom("terrain").id
    cap = int(env.world.cap_geoms[env.picking.state.target])
    names = ["jaco/ring_5", "jaco/link_5", "jaco/ring_6", *TOOL_GEOMS[tool]]
    geoms = [m.geom(n).id for n in names]
    for g in geoms:
        assert collide(g, soil) and collide(g, cap), m.geom(g).name
        body = m.geom_bodyid[g]  # the broadphase prunes by the per-body unions of the masks
        assert m.body_contype[body] & m.geom_contype[g] == m.geom_contype[g]
    for g1 in geoms:
        for g2 in geoms:
            assert not collide(g1, g2)
