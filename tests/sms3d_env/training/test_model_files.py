"""A policy's files: saves that a kill cannot cut, observation statistics read without unpickling,
and model files or configurations that cannot be used refused by name (exit 2), not by a traceback."""

from __future__ import annotations

import json
import random
import shutil
import subprocess
import sys
import time
import zipfile

import gymnasium as gym
import numpy as np
import pytest

from sms3d_env.pickers.policy import PolicyActor
from sms3d_env.pickers.registry import make_picker_env, parse_picker
from sms3d_env.policies.files import ObservationStats, PolicyFileError, RunningStats
from sms3d_env.policies.loader import SHIPPED_POLICY, load_sb3
from sms3d_env.training import main

SAVE_LOOP = """
import sys
from stable_baselines3 import PPO
from sms3d_env.policies.files import save_model
model = PPO("MlpPolicy", "Pendulum-v1", policy_kwargs={"net_arch": [512, 512]}, device="cpu")
save_model(model, sys.argv[1])
print("saved", flush=True)
while True:
    save_model(model, sys.argv[1])
"""


def test_a_save_killed_at_any_moment_leaves_a_whole_model_or_none(tmp_path):
    path = tmp_path / "model.zip"
    rng = random.Random(0)
    for _ in range(3):
        path.unlink(missing_ok=True)
        proc = subprocess.Popen([sys.executable, "-c", SAVE_LOOP, str(path)], stdout=subprocess.PIPE, text=True)
        try:
            assert proc.stdout.readline().strip() == "saved"
            time.sleep(rng.uniform(0.0, 0.4))
        finally:
            proc.kill()
            proc.wait()
        assert path.is_file()
        assert load_sb3(path, ("ppo",)).policy is not None  # PolicyFileError for a cut file


class _TwoKeys(gym.Env):
    observation_space = gym.spaces.Dict({"a": gym.spaces.Box(-5, 5, (3,)), "b": gym.spaces.Box(-5, 5, (2,))})
    action_space = gym.spaces.Box(-1, 1, (1,))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 1.0, False, False, {}


def test_observation_statistics_read_as_vecnormalize_applies_them(tmp_path, write_obs_rms):
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    trained = VecNormalize(DummyVecEnv([_TwoKeys]), norm_reward=True, gamma=0.95, clip_obs=2.0)
    trained.reset()
    for _ in range(20):
        trained.step(np.zeros((1, 1), np.float32))
    saved = ObservationStats({k: RunningStats(r.mean, r.var, r.count) for k, r in trained.obs_rms.items()},
                             trained.clip_obs, trained.epsilon, True,
                             RunningStats(trained.ret_rms.mean, trained.ret_rms.var, trained.ret_rms.count), gamma=0.95)
    write_obs_rms(saved, tmp_path / "obs_rms.npz")
    stats = ObservationStats.load(tmp_path / "obs_rms.npz")
    obs = {"a": np.array([4.0, -3.0, 0.5], np.float32), "b": np.array([1.0, -1.0], np.float32)}
    expected = trained.normalize_obs(obs)
    for k in obs:
        np.testing.assert_array_equal(stats.normalize_obs(obs)[k], expected[k])
    assert stats.returns.count == trained.ret_rms.count and stats.gamma == 0.95


def test_observation_statistics_are_never_unpickled(tmp_path):
    """Neither an npz holding a pickled object nor SB3's ``vecnormalize.pkl`` beside a model runs
    the code in it: both are refused by name."""
    marker = tmp_path / "ran"
    payload = _Payload(str(marker))
    np.savez(tmp_path / "obs_rms.npz", meta=np.array([payload], dtype=object))
    with pytest.raises(PolicyFileError, match="obs_rms.npz"):
        ObservationStats.load(tmp_path / "obs_rms.npz")

    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(SHIPPED_POLICY, run / "model.zip")
    shutil.copy(SHIPPED_POLICY.parent / "config.json", run / "config.json")
    import pickle

    (run / "vecnormalize.pkl").write_bytes(pickle.dumps(payload))
    with pytest.raises(PolicyFileError, match="vecnormalize.pkl.*not loaded"):
        PolicyActor(run / "model.zip")
    assert not marker.exists()


class _Payload:
    """Unpickling it creates a file (what a hostile pickle could do, harmlessly)."""

    def __init__(self, path: str) -> None:
        self.path = path

    def __reduce__(self):
        return (open, (self.path, "w"))


def _copy_of_shipped(folder, config=None):
    folder.mkdir()
    shutil.copy(SHIPPED_POLICY, folder / "model.zip")
    saved = json.loads((SHIPPED_POLICY.parent / "config.json").read_text())
    (folder / "config.json").write_text(json.dumps({**saved, **(config or {})}))
    return folder / "model.zip"


def _without_data(src, dst):
    """``src``'s zip without its ``data`` entry: a cut model that still opens as a zip."""
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w") as b:
        for name in a.namelist():
            if name != "data":
                b.writestr(name, a.read(name))


@pytest.mark.parametrize("kind", ["other zip", "cut model", "cut bytes"])
def test_a_file_that_is_no_sb3_model_is_named_with_exit_2(tmp_path, capsys, kind):
    bad = tmp_path / "model.zip"
    if kind == "other zip":
        with zipfile.ZipFile(bad, "w") as z:
            z.writestr("notes.txt", "not a policy")
    elif kind == "cut model":
        _without_data(SHIPPED_POLICY, bad)
    else:
        bad.write_bytes(SHIPPED_POLICY.read_bytes()[:5000])
    assert main(["eval-policy", "--model", str(bad), "--episodes", "1"]) == 2
    assert capsys.readouterr().out.startswith(f"error: {bad}: not a stable-baselines3")
    with pytest.raises(PolicyFileError, match=str(bad)):
        make_picker_env(parse_picker(f"policy:{bad}"))  # the sweep's --picker


def test_a_config_of_another_env_layout_is_named_before_the_first_step(tmp_path, capsys):
    model = _copy_of_shipped(tmp_path / "run", {"env_id": "SMS3DPick-v2", "env_options": {}})
    config = tmp_path / "run" / "config.json"
    assert main(["eval-policy", "--model", str(model), "--episodes", "1"]) == 2
    out = capsys.readouterr().out
    assert f"error: {config}: describes an env (SMS3DPick-v2" in out and "missing keys ['" in out
    with pytest.raises(PolicyFileError, match="missing keys"):
        make_picker_env(parse_picker(f"policy:{model}"))
    config.write_text("{cut")
    assert main(["eval-policy", "--model", str(model), "--episodes", "1"]) == 2
    assert f"error: {config}: not a readable run configuration" in capsys.readouterr().out


def test_the_shipped_policy_fits_its_env():
    actor = PolicyActor(SHIPPED_POLICY)
    env = actor.make_env()
    try:
        obs, _ = env.reset(seed=0)
        assert env.action_space.contains(np.asarray(actor(obs), np.float32))
    finally:
        env.close()


@pytest.mark.parametrize("flag", [["--seed", "-1"], ["--episodes", "0"], ["--num-mushrooms", "0"],
                                  ["--num-mushrooms", "101"], ["--pose-error-deg", "-1"],
                                  ["--pose-error-deg", "nan"], ["--json", "."]], ids=lambda f: " ".join(f))
def test_eval_policy_refuses_bad_numbers_by_flag(capsys, flag):
    assert main(["eval-policy", *flag]) == 2
    assert capsys.readouterr().out.startswith(f"error: argument {flag[0]}: ")
