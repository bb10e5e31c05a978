"""Reachability: its solve cache (the same answers as solving afresh, episodes unchanged by it)
and its restarts where the solve from home stalls."""

import gymnasium as gym
import numpy as np

import generator
import sms3d_env  # noqa: F401  (registers the env ids)
from sms3d_env import ScriptedPicker
from sms3d_env.controller import ControllerConfig, IKController
from sms3d_env.robots import HANGING_JACO
from sms3d_env.targets import Reachability

# The mapping form: v2 places the bed with no two collision hulls interpenetrating.
SMALL = {"placement": {"num_mushrooms": 8}}


def _reach_and_targets():
    env = gym.make("SMS3DPick-v2", robot="jaco", scene=SMALL)  # the arm: solves that can stall
    env.reset(seed=0)
    u = env.unwrapped
    return env, u.reach, [(np.asarray(i.cap_top), np.asarray(i.rotation)[:, 2]) for i in u.scene.instances]


def test_a_cached_solve_is_the_fresh_solve_and_a_copy():
    env, reach, targets = _reach_and_targets()
    try:
        for cap_top, axis in targets[:4]:
            first = reach.solve(cap_top, axis, (0.05, 0.03))
            fresh = reach._solve(cap_top, axis, (0.05, 0.03))
            assert (first is None) == (fresh is None)
            if first is not None:
                np.testing.assert_array_equal(first, fresh)
                first[:] = 99.0  # a caller's change does not reach the cache
                np.testing.assert_array_equal(reach.solve(cap_top, axis, (0.05, 0.03)), fresh)
    finally:
        env.close()


def test_the_cache_keeps_the_most_recently_used_solves():
    env, reach, targets = _reach_and_targets()
    try:
        reach._solved.clear()
        reach.cache_size = 2
        (a, ax), (b, bx), (c, cx) = targets[:3]
        reach.solve(a, ax)
        reach.solve(b, bx)
        reach.solve(a, ax)  # a is now the most recently used
        reach.solve(c, cx)  # evicts b
        kept = {k[0] for k in reach._solved}
        assert len(reach._solved) == 2 and kept == {a.tobytes(), c.tobytes()}
    finally:
        env.close()


def test_pool_episodes_are_the_same_with_and_without_the_cache():
    """A bed pool asks the same reachability and posture solves at every reset of a bed: answered
    from the cache, every observation and reward equals a run whose cache is emptied each reset."""
    runs = []
    for keep in (True, False):
        env = gym.make("SMS3DPickTrain-v2", robot="jaco", scene={"config": SMALL, "pool": 2}, start={"share": 0.5})
        picker = ScriptedPicker.for_env(env)
        trace = []
        try:
            for episode in range(5):
                if not keep:
                    env.unwrapped.reach._solved.clear()
                obs, _ = env.reset(seed=episode % 2 if episode else 0)
                picker.reset()
                for _ in range(40):
                    obs, reward, terminated, truncated, _ = env.step(picker(obs))
                    trace.append((np.concatenate([np.ravel(v) for v in obs.values()]), reward))
                    if terminated or truncated:
                        break
        finally:
            env.close()
        runs.append(trace)
    assert len(runs[0]) == len(runs[1])
    for (o1, r1), (o2, r2) in zip(*runs, strict=True):
        np.testing.assert_array_equal(o1, o2)
        assert r1 == r2


def test_a_pose_whose_solve_from_home_stalls_in_the_wrist_singularity_is_solved_by_a_restart():
    """The v1 Jaco's pre-grasp pose for the 30 deg estimate of held-out bed 1,000,237: from home
    the least squares stops at the wrist singularity; a restart with a turned joint solves it, the
    cup on the axis, the arm and the straight joint path from home to it well conditioned (home:
    0.15)."""
    ik = IKController(HANGING_JACO, ControllerConfig())
    reach = Reachability(ik.model, ik.site, ik.arm_qadr, np.asarray(HANGING_JACO.home_q))
    cap_top, axis = np.array([0.0207, -0.0559, 0.0657]), np.array([0.0797, 0.6877, 0.7216])
    axis /= np.linalg.norm(axis)
    assert reach._solve_from(reach.home, cap_top, -axis, (0.05, 0.03)) is None
    q = reach.solve(cap_top, axis, (0.05, 0.03))
    assert q is not None and np.all((reach.lo <= q) & (q <= reach.hi))
    assert np.linalg.norm(reach._res(q, cap_top + 0.03 * axis, -axis)) < 1e-3
    assert reach.conditioning(q) > 0.1 and reach.path_conditioning(q) > 0.1


def _mushroom(x: float, y: float, top: float, diameter: float):
    from types import SimpleNamespace

    return SimpleNamespace(cap_top=np.array([x, y, top]), cap_diameter=diameter, rotation=np.eye(3))


def test_a_neighbours_cap_over_the_approach_blocks_it_and_a_lower_one_does_not():
    from sms3d_env.targets import approach_blocked, target_classes

    bed = [_mushroom(0.0, 0.0, 0.05, 0.055), _mushroom(0.04, 0.0, 0.07, 0.06), _mushroom(0.5, 0.5, 0.05, 0.03)]
    assert approach_blocked(bed).tolist() == [True, False, False]
    classes = target_classes(bed)
    assert classes["harvest_ready"].tolist() == [True, True, False] and classes["small"].tolist() == [False, False, True]
    assert classes["crowded"].tolist() == [True, True, False]  # the two big caps' outlines overlap


def test_the_class_rules_partition_seeded_beds_as_documented():
    from sms3d_env.targets import HARVEST_DIAMETER, target_classes

    for seed in range(5):
        insts = generator.generate_scene(generator.SceneConfig().replace(placement__num_mushrooms=50), seed=seed).instances
        c = target_classes(insts)
        sizes = np.array([inst.cap_diameter for inst in insts])
        assert (c["harvest_ready"] == (sizes >= HARVEST_DIAMETER)).all() and (c["small"] == ~c["harvest_ready"]).all()
        for cls in ("isolated", "crowded", "approach_blocked"):
            assert not (c[cls] & ~c["harvest_ready"]).any()
        assert not (c["isolated"] & c["crowded"]).any()


def test_the_harvest_ready_rule_draws_among_harvest_size_caps_not_the_tallest():
    env = gym.make("SMS3DPick-v1", scene=generator.SceneConfig().replace(placement__num_mushrooms=25),
                   target="harvest_ready")
    tallest = gym.make("SMS3DPick-v1", scene=generator.SceneConfig().replace(placement__num_mushrooms=25))
    same = 0
    for seed in range(8):
        _, info = env.reset(seed=seed)
        inst = env.unwrapped.scene.instances[info["target"]]
        assert inst.cap_diameter >= 0.05
        same += info["target"] == tallest.reset(seed=seed)[1]["target"]
    assert same < 8
