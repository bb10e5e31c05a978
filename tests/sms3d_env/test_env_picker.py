"""The scripted pose-aware picker: success with oracle poses and its decline with pose error."""

import gymnasium as gym
import pytest
from scipy.stats import fisher_exact

import sms3d_env


def _wins(err: float, episodes: int = 40) -> tuple[int, int]:
    env = gym.make("SMS3DPick-v2", pose_source="noisy", pose_error_deg=err)
    pol = sms3d_env.ScriptedPicker.for_env(env)
    res = [sms3d_env.run_episode(env, pol, seed=s) for s in range(episodes)]
    env.close()
    reach = [r for r in res if r["reachable"]]
    return sum(r["success"] for r in reach), len(reach)


@pytest.mark.slow
def test_scripted_picker_oracle_and_pose_error():
    oracle_wins, oracle_n = _wins(0.0)
    assert oracle_n >= 30
    assert oracle_wins / oracle_n >= 0.95
    wrong_wins, wrong_n = _wins(30.0)
    # "Clearly more often": a one-sided Fisher exact test on the same 40 seeded scenes.
    table = [[oracle_wins, oracle_n - oracle_wins], [wrong_wins, wrong_n - wrong_wins]]
    assert fisher_exact(table, alternative="greater").pvalue < 0.05
