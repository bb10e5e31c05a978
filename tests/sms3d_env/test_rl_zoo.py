"""The shipped PPO recipe is an RL Baselines3 Zoo hyperparameter file: ``sms3d train-policy ppo`` and
``python -m rl_zoo3.train`` typed by hand make the same run (the same settings recorded), with the
package's callbacks (curriculum annealing, the falling rate); ``PolicyActor`` runs what RL Zoo
saved with the statistics of its ``vecnormalize.pkl`` decoded without running code, and the
learning curve reads the run."""

from __future__ import annotations

import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sms3d_env.pickers.policy import PolicyActor
from sms3d_env.policies.files import PolicyFileError
from sms3d_env.policies.zoo_runs import read_vecnormalize
from sms3d_env.training.learning_curve import read_curve
from sms3d_env.training.zoo import RecipeError, read_zoo_yaml, recipe_path

ENV_ID = "SMS3DPickTrain-v2"
BED = 8
#: 512 steps on one env, rollouts of 256, an 8-mushroom bed pool of 2, one evaluation episode per 256 steps.
ENV_KWARGS = {"scene": {"config": {"placement": {"num_mushrooms": BED}}, "pool": 2}, "start": {"share": 0.75}}
SHORT = ["--seed", "0", "--eval-freq", "256", "--eval-episodes", "1"]


def _run(cmd: list[str], cwd: Path) -> str:
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=cwd,
                            env={**os.environ, "MUJOCO_GL": "egl"})
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-3000:]
    return result.stdout


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """``{"sms3d": (run folder, stdout), "rl_zoo3": ...}``: the same short training of the shipped
    recipe through ``sms3d train-policy`` and through RL Zoo's command typed as the docs write it."""
    logs = tmp_path_factory.mktemp("zoo")
    front = _run([sys.executable, "-m", "sms3d_env.training", "train-policy", "ppo", "--out", str(logs / "front"),
                  "--steps", "512", *SHORT, "--hyperparams", "n_envs=1", "n_steps=256", "batch_size=64",
                  f"env_kwargs={ENV_KWARGS}"], logs)
    zoo = _run([sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", ENV_ID, "--conf-file",
                str(recipe_path("ppo")), "--gym-packages", "sms3d_env", "--num-threads", "1", "--device", "cpu",
                "--log-folder", str(logs / "zoo"), "-n", "512", *SHORT, "--hyperparams", "n_envs:1", "n_steps:256",
                "batch_size:64", f"env_kwargs:{ENV_KWARGS}", "--eval-env-kwargs",
                f"scene:{ENV_KWARGS['scene']['config']}"], logs)
    return {"sms3d": (logs / "front" / "ppo" / f"{ENV_ID}_1", front), "rl_zoo3": (logs / "zoo" / "ppo" / f"{ENV_ID}_1", zoo)}


def test_sms3d_train_policy_and_rl_zoo_record_the_same_run(runs):
    (front, out), (zoo, _) = runs["sms3d"], runs["rl_zoo3"]
    assert read_zoo_yaml(front / ENV_ID / "config.yml") == read_zoo_yaml(zoo / ENV_ID / "config.yml")
    args = [{k: v for k, v in read_zoo_yaml(run / ENV_ID / "args.yml").items() if k != "log_folder"}
            for run in (front, zoo)]
    assert args[0] == args[1]
    assert "python -m rl_zoo3.train --algo ppo --env SMS3DPickTrain-v2" in out  # the command it ran, printed


@pytest.mark.parametrize("trainer", ["sms3d", "rl_zoo3"])
def test_rl_zoo_trains_the_recipe_with_its_callbacks(runs, trainer):
    run, stdout = runs[trainer]
    assert (run / f"{ENV_ID}.zip").is_file() and (run / ENV_ID / "vecnormalize.pkl").is_file()
    # The annealing callback logged its share (SB3's table: "curriculum/" above "pregrasp_start").
    assert re.findall(r"pregrasp_start\s*\|\s*([0-9.]+)", stdout)[:2] == ["0.75", "0.75"]  # no home success yet
    rates = [float(r) for r in re.findall(r"learning_rate\s*\|\s*([0-9.e-]+)", stdout)]
    # Falling from 3e-4 to a tenth of it over the run: after the first of two rollouts, half way.
    assert rates and rates[0] == pytest.approx(3e-4 - 0.5 * (3e-4 - 3e-5), rel=1e-3)


def test_policy_actor_runs_a_zoo_model(runs):
    run, _ = runs["sms3d"]
    actor = PolicyActor(run / f"{ENV_ID}.zip")
    assert (actor.env_id, actor.saved["algo"], actor.saved["num_mushrooms"]) == (ENV_ID, "ppo", BED)
    assert actor.env_options == {}  # the curriculum and the bed pool are training options
    env = actor.make_env(scene={"placement": {"num_mushrooms": BED}})
    try:
        obs, _ = env.reset(seed=3)
        action = actor(obs)
        assert action.shape == (7,) and np.all(np.abs(action) <= 1)
        obs, *_ = env.step(action)
    finally:
        env.close()


def test_the_learning_curve_reads_a_zoo_run(runs):
    run, _ = runs["rl_zoo3"]
    points = read_curve(run)
    assert [p["steps"] for p in points] == [256.0, 512.0]
    assert all(p["success"] in (0.0, 1.0) and p["wall_s"] >= 0 for p in points)


def test_the_restricted_reader_gives_what_sb3_unpickles(runs):
    """The file is this test's own run's: unpickling it with SB3 here is the reference."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from sms3d_env.policies.envs import make_env

    run, _ = runs["rl_zoo3"]
    path = run / ENV_ID / "vecnormalize.pkl"
    venv = DummyVecEnv([lambda: make_env(ENV_ID, flat_observation=True)])
    try:
        reference = VecNormalize.load(str(path), venv)
        stats = read_vecnormalize(path)
        np.testing.assert_array_equal(stats.obs[None].mean, reference.obs_rms.mean)
        np.testing.assert_array_equal(stats.obs[None].var, reference.obs_rms.var)
        assert stats.returns.count == reference.ret_rms.count and stats.norm_reward and stats.clip_obs == reference.clip_obs
        x = np.random.default_rng(0).normal(size=reference.obs_rms.mean.shape)
        np.testing.assert_allclose(stats.normalize_obs(x), reference.normalize_obs(x), rtol=1e-6)
    finally:
        venv.close()


class _Payload:
    """A pickle that would create a file if unpickled normally."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_a_crafted_pickle_runs_nothing_and_is_refused(tmp_path):
    marker = tmp_path / "ran"
    crafted = tmp_path / "vecnormalize.pkl"
    crafted.write_bytes(pickle.dumps(_Payload(marker)))
    with pytest.raises(PolicyFileError, match="vecnormalize.pkl"):
        read_vecnormalize(crafted)
    assert not marker.exists()
    config = tmp_path / "config.yml"
    config.write_text(f"!!python/object/apply:os.system ['touch {marker}']\n")
    with pytest.raises(RecipeError, match="config.yml"):
        read_zoo_yaml(config)
    assert not marker.exists()
