"""The scripted pose-aware picker: success with oracle poses and its decline with pose error."""

import gymnasium as gym
import pytest

import sms3d_env


def _rate(err: float, episodes: int = 40) -> float:
    env = gym.make("SMS3DPick-v0", pose_source="noisy", pose_error_deg=err)
    pol = sms3d_env.ScriptedPicker.for_env(env)
    res = [sms3d_env.run_episode(env, pol, seed=s) for s in range(episodes)]
    reach = [r for r in res if r["reachable"]]
    return sum(r["success"] for r in reach) / max(1, len(reach))


@pytest.mark.slow
def test_scripted_picker_oracle_and_pose_error():
    oracle = _rate(0.0)
    assert oracle >= 0.95
    assert _rate(30.0) < oracle - 0.2
