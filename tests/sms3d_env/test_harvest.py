"""SMS3DHarvest-v0: the gym API, masks, determinism, what a pick does to the bed, the time's
account, and SMS3DPickEnv.start_pick (the pick env's extension it runs on). Small fixed beds."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import generator
from generator.errors import ConfigError
from sms3d_env.gantry import GantryConfig
from sms3d_env.harvest import (
    HarvestConfig,
    MaskedActionError,
    ScriptedOrder,
    SMS3DHarvestEnv,
    run_harvest,
)
from sms3d_env.harvest.motion import Motion, axis_time
from sms3d_env.harvest.scan import current_scene, in_view
from sms3d_env.pose_sources import OraclePose

TOUCHING = {"placement__overlap_iou": 0.0, "placement__overlap_solids": "hulls"}


@pytest.fixture(scope="module")
def bed() -> generator.Scene:
    """A 12-mushroom bed whose mushrooms do not interpenetrate (seed 1): 6 harvest-ready caps, all reachable."""
    cfg = generator.SceneConfig().replace(placement__num_mushrooms=12, **TOUCHING)
    return generator.generate_scene(cfg, seed=1)


def make(bed, **kwargs) -> SMS3DHarvestEnv:
    return SMS3DHarvestEnv(scene=[bed], **kwargs)


def first_clean_pick(env: SMS3DHarvestEnv):
    """Pick the available candidates in slot order until one is collected; its step's returns."""
    for slot in np.flatnonzero(env.action_masks()[:env.RESCAN]):
        out = env.step(int(slot))
        if out[4]["last_pick"]["collected"]:
            return int(slot), out
    pytest.fail("no candidate of the bed was collected")


def test_check_env(bed):
    # Two slots, both candidates reachable: every action the checker samples is allowed.
    env = make(bed, harvest={"max_candidates": 2})
    env.reset(seed=0)
    assert env.action_masks().all()
    check_env(env, skip_render_check=True)


def test_registered_and_masks_through_a_vector_env(bed):
    from sb3_contrib.common.maskable.utils import get_action_masks
    from stable_baselines3.common.vec_env import DummyVecEnv

    env = gym.make("SMS3DHarvest-v0", scene=[bed], harvest={"max_candidates": 8})
    venv = DummyVecEnv([lambda: env])
    venv.reset()
    masks = get_action_masks(venv)  # 6 candidates in 8 slots, re-scan, stop
    assert masks.tolist() == [[True] * 6 + [False] * 2 + [True] * 2]
    venv.close()


def test_masks_through_a_subprocess_vector_env(bed):
    from sb3_contrib.common.maskable.utils import get_action_masks
    from stable_baselines3.common.vec_env import SubprocVecEnv

    # "module:id": the worker process imports the package that registers the id.
    venv = SubprocVecEnv([lambda: gym.make("sms3d_env:SMS3DHarvest-v0", scene=[bed], harvest={"max_candidates": 8})])
    venv.reset()
    assert get_action_masks(venv).tolist() == [[True] * 6 + [False] * 2 + [True] * 2]
    venv.close()


def test_determinism_by_seed(bed):
    def run(seed):
        env = SMS3DHarvestEnv(scene={"placement": {"num_mushrooms": 10}}, pose_source="noisy", pose_error_deg=10.0)
        obs, _ = env.reset(seed=seed)
        trace = [obs["candidates"].copy()]
        for _ in range(3):
            mask = env.action_masks()
            obs, reward, _, _, info = env.step(int(np.flatnonzero(mask)[0]))
            trace += [obs["candidates"].copy(), obs["bed"].copy(), reward]
        return trace, info

    (a, info_a), (b, info_b), (c, _) = run(7), run(7), run(8)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert {k: v for k, v in info_a.items() if k != "candidates"} == {k: v for k, v in info_b.items()
                                                                        if k != "candidates"}
    assert not np.array_equal(a[0], c[0])


def test_masked_and_invalid_actions_raise(bed):
    env = make(bed)
    env.reset(seed=0)
    n = len(env.candidates)
    with pytest.raises(MaskedActionError, match="holds no candidate") as err:
        env.step(n)  # the first empty slot
    assert err.value.action == n and pickle.loads(pickle.dumps(err.value)).reason == err.value.reason
    slot, _ = first_clean_pick(env)
    with pytest.raises(MaskedActionError, match="collected since the last scan"):
        env.step(slot)
    for bad in (-1, env.action_space.n, 1.5, "0"):
        with pytest.raises(ValueError):
            env.step(bad)
    env.step(env.STOP)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step(env.RESCAN)


def test_picked_mushroom_leaves_the_bed_and_a_rescan_sees_one_fewer(bed):
    env = make(bed)
    env.reset(seed=0)
    before = [det.instance for det in env.candidates]
    slot, (obs, reward, _, _, info) = first_clean_pick(env)
    k = info["last_pick"]["target"]
    assert info["last_pick"]["clean"] and reward == pytest.approx(1.0 + info["reward_time"])
    w = env.pick.world
    b = w.body_ids[k]
    # Out of the bed, at the collection point, and colliding with nothing.
    np.testing.assert_allclose(w.data.xpos[b], env.collection_point, atol=1e-6)
    assert w.model.body_contype[b] == w.model.body_conaffinity[b] == 0
    assert w.model.geom_contype[w.cap_geoms[k]] == w.model.geom_conaffinity[w.cap_geoms[k]] == 0
    assert obs["candidates"][slot, 0] == 0.0 and not env.action_masks()[slot]
    env.step(env.RESCAN)
    after = [det.instance for det in env.candidates]
    assert k not in after and len(after) == len(before) - 1 and set(after) == set(before) - {k}
    assert info["picked"] == 1 and k in env.tally.clean


class ConfusedPose:
    """A detector that reports mushroom ``other``'s pose for mushroom ``target`` (the truth for the rest)."""

    def __init__(self, target: int, other: int) -> None:
        self.target, self.other, self.oracle = target, other, OraclePose()

    def __call__(self, scene, i, rng):
        return self.oracle(scene, self.other if i == self.target else i, rng)


def test_a_knocked_mushroom_stays_in_the_bed(bed):
    # Candidate 0's estimate is candidate 1's pose: the cup seals on mushroom 1, twists it off its
    # roots and lifts it; the pick collects nothing, and mushroom 1 is dropped back into the bed.
    probe = make(bed)
    probe.reset(seed=0)
    target, other = (det.instance for det in probe.candidates[:2])
    env = make(bed, pose_source=ConfusedPose(target, other), harvest={"max_pick_steps": 120})
    env.reset(seed=0)
    start = env.pick.world.data.xpos[env.pick.world.body_ids[other]].copy()
    _, _, _, _, info = env.step(0)
    assert not info["last_pick"]["collected"] and other in env.tally.knocked_off
    assert info["damage"]["knocked_off"]["ready"] >= 1 and info["damaged"]["ready"] >= 1
    assert info["reward_damage"] <= -1.0
    w = env.pick.world
    assert other not in env.collected
    assert np.linalg.norm(w.data.xpos[w.body_ids[other]][:2] - start[:2]) < 0.05  # near where it grew
    assert w.model.body_conaffinity[w.body_ids[other]] != 0  # still in the world's collisions
    assert other in in_view(current_scene(env.pick.scene, w), env.collected)


def test_time_accounting_adds_up(bed):
    env = make(bed, harvest={"scan_time": 0.7})
    obs, _ = env.reset(seed=0)
    pick_time, planner = 0.0, ScriptedOrder("nearest", "after_pick")
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(planner(obs, env.action_masks()))
        pick_time += info["last_pick"]["time_s"] if info["last_pick"] else 0.0
        done = terminated or truncated
    s = info["summary"]
    parts = s["time_travel_s"] + s["time_carry_s"] + s["time_scan_s"] + s["time_pick_s"]
    assert s["time_s"] == pytest.approx(parts) and obs["bed"][0] == pytest.approx(s["time_s"], rel=1e-6)
    assert s["time_scan_s"] == pytest.approx(0.7 * s["scans"]) and s["scans"] >= 2
    assert s["time_pick_s"] == pytest.approx(pick_time)
    assert s["time_travel_s"] > 0 and s["time_carry_s"] > 0.2 * s["picked"]
    assert s["mushrooms_per_hour"] == pytest.approx(s["picked"] / s["time_s"] * 3600)
    assert s["yield"] == pytest.approx(s["picked_clean_ready"] / s["harvest_ready"])


def test_a_tray_on_the_head_drops_where_it_picked(bed):
    env = make(bed, harvest={"collection_point": None})
    env.reset(seed=0)
    _, (obs, _, _, _, info) = first_clean_pick(env)
    w, k = env.pick.world, info["last_pick"]["target"]
    assert info["time_carry_s"] == pytest.approx(env.config.drop_time)
    np.testing.assert_allclose(obs["bed"][-3:], w.data.site_xpos[w.tool_site], atol=1e-3)  # no trip
    np.testing.assert_allclose(w.data.xpos[w.body_ids[k]], env.park_point, atol=1e-6)
    assert w.model.body_conaffinity[w.body_ids[k]] == 0


def test_orders_clear_the_bed(bed):
    env = make(bed)
    for order in ("largest", "isolated"):
        r = run_harvest(env, ScriptedOrder(order, "after_failure"), seed=0)
        assert not r["truncated"] and r["missed"] + r["picked"] >= r["harvest_ready"] > 0
        assert r["picked"] >= 1 and r["attempts"] >= r["picked"]


def test_a_planner_gives_up_on_a_spot_where_picks_failed():
    from sms3d_env.harvest.scan import BED_FEATURES, CANDIDATE_FEATURES

    rows = np.zeros((2, len(CANDIDATE_FEATURES)), np.float32)
    rows[0, :3] = [1.0, 0.1, 0.1]  # available, its cap top at (0.1, 0.1)
    bed = np.zeros(len(BED_FEATURES), np.float32)
    scans, attempts = BED_FEATURES.index("scans"), BED_FEATURES.index("attempts")
    mask = np.array([True, False, True, True])
    planner = ScriptedOrder("detection", "after_failure", give_up_after=2)
    actions = []
    for _ in range(2):  # pick, fail, re-scan (the candidate is new again), ...
        actions.append(planner({"candidates": rows, "bed": bed.copy()}, mask))
        bed[attempts] += 1
        actions.append(planner({"candidates": rows, "bed": bed.copy()}, mask))
        bed[scans] += 1
    actions.append(planner({"candidates": rows, "bed": bed.copy()}, mask))
    assert actions == [0, 2, 0, 2, 3]  # ... and after the second failure there, stop


def test_pickled_env_goes_on_the_same(bed):
    env = make(bed)
    env.reset(seed=0)
    copy = pickle.loads(pickle.dumps(env))
    a, b = env.step(0), copy.step(0)
    assert a[4]["last_pick"] == b[4]["last_pick"]
    np.testing.assert_array_equal(a[0]["candidates"], b[0]["candidates"])


def test_bad_arguments_raise_typed_errors(bed):
    with pytest.raises(ConfigError, match="perception"):
        SMS3DHarvestEnv(pose_source="perception")
    with pytest.raises(ConfigError, match="pose_error_deg"):
        SMS3DHarvestEnv(pose_error_deg=10.0)
    with pytest.raises(ConfigError, match="HarvestConfig.scan_time"):
        HarvestConfig(scan_time=-1.0)
    with pytest.raises(ConfigError, match="HarvestConfig.collection_point"):
        HarvestConfig(collection_point=(0.3,))
    with pytest.raises(ConfigError, match="max_candidates"):
        make(bed, harvest={"max_candidates": 0})
    with pytest.raises(ValueError, match="no field"):
        make(bed, harvest={"scan_seconds": 1.0})
    with pytest.raises(ConfigError, match="suction tool only"):
        SMS3DHarvestEnv(scene=[bed], robot=GantryConfig(tool="hand"))
    with pytest.raises(ValueError, match="order"):
        ScriptedOrder("random")


def test_motion_times():
    assert axis_time(0.0, 0.5, 1.0) == 0.0
    assert axis_time(0.16, 0.5, 1.0) == pytest.approx(0.8)  # a triangle: 2 sqrt(d / a)
    assert axis_time(1.0, 0.5, 1.0) == pytest.approx(2.5)  # d / v + v / a
    m = Motion(0.5, 1.0, 0.2)
    assert m.time([0, 0, 0.2], [0.16, 0.0, 0.2]) == pytest.approx(0.8)
    assert m.time([0, 0, 0.04], [0, 0, 0.2]) == pytest.approx(0.8)


def test_start_pick_checks_its_arguments(bed):
    env = make(bed)
    with pytest.raises(RuntimeError, match="reset"):
        env.pick.start_pick(0, OraclePose()(bed, 0, None))
    env.reset(seed=0)
    est = OraclePose()(bed, 0, None)
    with pytest.raises(ValueError, match="target"):
        env.pick.start_pick(len(bed.instances), est)
    with pytest.raises(ValueError, match="q_start"):
        env.pick.start_pick(0, est, q_start=np.zeros(2))
