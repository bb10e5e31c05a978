"""Picking physics and pose sources on real MuJoCo scenes."""

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import generator
import sms3d_env
from sms3d_env.physics import grip_utilisation
from sms3d_env.physics_params import V1_PHYSICS
from sms3d_env.pose_sources import NoisyPose, OraclePose

SMALL = generator.SceneConfig().replace(placement__num_mushrooms=8)
#: SMALL in the mapping form: v2 places it with no two collision hulls interpenetrating.
SMALL_MAPPING = {"placement": {"num_mushrooms": 8}}


def test_holding_force_from_vacuum_and_area():
    p = sms3d_env.PickPhysicsParams()  # v2's 60 kPa on a 20 mm cup
    assert p.holding_force == pytest.approx(60e3 * np.pi * 0.01**2)
    assert sms3d_env.PickPhysicsParams(**V1_PHYSICS).holding_force == pytest.approx(20e3 * np.pi * 0.01**2)
    with pytest.raises(ValueError):
        sms3d_env.PickPhysicsParams(seal_angle_deg=95)


loads = st.floats(0.0, 10.0)


@given(tension=loads, shear=loads, bend=st.floats(0.0, 0.1), twist=st.floats(0.0, 0.05),
       compression=loads)
def test_pressing_the_cup_on_the_cap_adds_to_the_seals_capacity(tension, shear, bend, twist, compression):
    """v1's seal carries shear, bending and twist against the holding force plus the cup's
    compression of the cap; without ``seal_preload`` against the holding force alone; tension's
    capacity is the holding force either way, and each capacity is reached exactly."""
    v1 = sms3d_env.PickPhysicsParams(**V1_PHYSICS)
    unloaded = sms3d_env.PickPhysicsParams(**{**V1_PHYSICS, "seal_preload": False})
    load = (tension, shear, bend, twist)
    assert grip_utilisation(*load, v1, compression) <= grip_utilisation(*load, v1) + 1e-12
    assert grip_utilisation(*load, unloaded, compression) == grip_utilisation(*load, unloaded)
    normal = v1.holding_force + compression
    a, mu = v1.cup_radius, v1.shear_friction
    for capacity in ((v1.holding_force, 0, 0, 0), (0, mu * normal, 0, 0), (0, 0, normal * a / 2, 0),
                     (0, 0, 0, mu * normal * 2 * a / 3)):
        assert grip_utilisation(*capacity, v1, compression) == pytest.approx(1.0)


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
    env = gym.make("SMS3DPick-v2", scene=SMALL_MAPPING, target="tallest").unwrapped
    _, info = env.reset(seed=0, options={"target": 2})
    assert info["target"] == 2
    _, info = env.reset(seed=0)
    tallest = max(range(8), key=lambda i: env.scene.instances[i].cap_top[2])
    if info["reachable"]:
        heights = [inst.cap_top[2] for inst in env.scene.instances]
        assert heights[info["target"]] <= heights[tallest]


def test_failure_cause_vocabulary():
    env = gym.make("SMS3DPick-v2", scene=SMALL_MAPPING, max_episode_steps=5)
    env.reset(seed=0)
    for _ in range(5):
        *_, te, tr, info = env.step(np.zeros(7, np.float32))
    assert info["failure_cause"] in sms3d_env.FAILURE_CAUSES
    assert info["is_success"] is False

