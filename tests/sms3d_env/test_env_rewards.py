import numpy as np

from sms3d_env.rewards import RewardState, compute_reward


def _state(**kw):
    base = dict(tool_pos=np.zeros(3), tool_axis=np.array([0, 0, -1.0]), goal_cap_top=np.array([0, 0, 0.1]),
                goal_axis=np.array([0, 0, 1.0]), gripped_target=False, target_detached=False, lift=0.0,
                lift_goal=0.03, success=False, bruised=False)
    base.update(kw)
    return RewardState(**base)


def test_detaching_without_holding_earns_nothing():
    idle = compute_reward(_state(), "dense")
    knocked_off = compute_reward(_state(target_detached=True), "dense")
    held_and_detached = compute_reward(_state(target_detached=True, gripped_target=True), "dense")
    assert knocked_off == idle
    assert held_and_detached > idle + 1.0


def test_dense_reward_orders_progress_and_sparse_is_binary():
    far = compute_reward(_state(tool_pos=np.array([0.2, 0, 0.3])), "dense")
    near = compute_reward(_state(tool_pos=np.array([0, 0, 0.11])), "dense")
    lifted = compute_reward(_state(gripped_target=True, target_detached=True, lift=0.03), "dense")
    assert far < near < lifted
    assert compute_reward(_state(success=True), "sparse") == 0.0
    assert compute_reward(_state(), "sparse") == -1.0
    assert compute_reward(_state(bruised=True), "dense") < compute_reward(_state(), "dense")
