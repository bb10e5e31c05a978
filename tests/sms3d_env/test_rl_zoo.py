"""The shipped PPO recipe as an RL Baselines3 Zoo hyperparameter file: ``rl_zoo3.train`` trains from
it (curriculum annealing and the falling rate included), ``PolicyActor`` runs what it saved with
the statistics of its ``vecnormalize.pkl`` decoded without running code, and ``sms3d
train-policy --conf-file`` reads the same file into the same settings."""

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
from sms3d_env.training.config import TrainConfig
from sms3d_env.training.recipes import read_recipe
from sms3d_env.training.zoo import RecipeError, read_zoo_yaml, recipe_path, with_recipe

ENV_ID = "SMS3DPickTrain-v1"
BED = 8


@pytest.fixture(scope="module")
def zoo_run(tmp_path_factory):
    """``(run folder, stdout)`` of ``python -m rl_zoo3.train`` on the shipped recipe for 512 steps
    (one env, rollouts of 256, an 8-mushroom bed pool of 2)."""
    logs = tmp_path_factory.mktemp("zoo")
    env_kwargs = f"dict(scene=dict(config=dict(placement=dict(num_mushrooms={BED})), pool=2), start=dict(share=0.75))"
    cmd = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", ENV_ID, "--gym-packages", "sms3d_env",
           "--conf-file", str(recipe_path("ppo")), "--n-timesteps", "512", "--eval-freq", "-1", "--seed", "0",
           "--log-folder", str(logs), "--hyperparams", "n_envs:1", "n_steps:256", "batch_size:64",
           f"env_kwargs:{env_kwargs}"]
    result = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=logs,
                            env={**os.environ, "MUJOCO_GL": "egl"})
    assert result.returncode == 0, result.stderr[-3000:]
    return logs / "ppo" / f"{ENV_ID}_1", result.stdout


def test_rl_zoo_trains_the_recipe_with_its_callbacks(zoo_run):
    run, stdout = zoo_run
    assert (run / f"{ENV_ID}.zip").is_file() and (run / ENV_ID / "vecnormalize.pkl").is_file()
    # The annealing callback logged its share (SB3's table: "curriculum/" above "pregrasp_start").
    assert re.findall(r"pregrasp_start\s*\|\s*([0-9.]+)", stdout) == ["0.75", "0.75"]  # no home success yet
    rates = [float(r) for r in re.findall(r"learning_rate\s*\|\s*([0-9.e-]+)", stdout)]
    # Falling from 3e-4 to a tenth of it over the run: after the first of two rollouts, half way.
    assert rates and rates[0] == pytest.approx(3e-4 - 0.5 * (3e-4 - 3e-5), rel=1e-3)


def test_policy_actor_runs_a_zoo_model(zoo_run):
    run, _ = zoo_run
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


def test_the_restricted_reader_gives_what_sb3_unpickles(zoo_run):
    """The file is this test's own run's: unpickling it with SB3 here is the reference."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from sms3d_env.policies.envs import make_env

    run, _ = zoo_run
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


def test_train_policy_reads_the_recipe_into_the_same_settings():
    recipe = read_recipe("ppo")
    cfg = recipe.config
    assert recipe.kind == "rl" and cfg.env_id == ENV_ID and (cfg.normalize, cfg.normalize_reward, cfg.flat_observation) == (True, True, True)
    assert (cfg.pregrasp_start, cfg.pregrasp_anneal, cfg.num_mushrooms, cfg.scene_pool) == (0.75, True, 10, 500)
    assert cfg.learning_rate_final == pytest.approx(cfg.learning_rate / 10) and cfg.learning_rate_by_wall
    assert cfg.max_wall_s == 2400 and cfg.target_kl == 0.02 and cfg.log_std_init == -1.0


def test_a_recipe_with_the_env_arguments_of_earlier_versions_reads_the_same(tmp_path):
    shipped = recipe_path("ppo").read_text()
    earlier = shipped.replace("scene: {config: {placement: {num_mushrooms: 10}}, pool: 500}",
                              "scene_config: {placement: {num_mushrooms: 10}}\n    scene_pool: 500")
    earlier = earlier.replace("start: {share: 0.75}", "pregrasp_start: 0.75")
    assert earlier.count("scene_pool") == 1 and earlier.count("pregrasp_start") == 1
    path = tmp_path / "earlier.yml"
    path.write_text(earlier)
    assert read_recipe(path).config == read_recipe("ppo").config


@pytest.mark.parametrize("entry, named", [
    ("  learning_rate: lin_3e-4\n", "learning_rate"),
    ("  policy_kwargs: \"dict(net_arch=[64])\"\n", "policy_kwargs"),
    ("  frame_stack: 4\n", "frame_stack"),
    ("  env_kwargs: {scene: /data}\n", "env_kwargs.scene"),
    ("  env_kwargs: {scene: {config: {placement: {num_mushrooms: 8}}, pool_seed: 3}}\n", "pool_seed"),
    ("  env_kwargs: {controller: {substeps: 10}}\n", "env_kwargs.controller"),
    ("  callback: [stable_baselines3.common.callbacks.CheckpointCallback]\n", "CheckpointCallback"),
    ("  env_kwargs: {start: {share: 0.5}}\n  callback:\n"
     "    - sms3d_env.training.curriculum.pregrasp_annealing: {initial: 0.75}\n", "initial"),
])
def test_recipe_keys_without_a_setting_are_refused_by_name(tmp_path, entry, named):
    path = tmp_path / "recipe.yml"
    path.write_text(f"{ENV_ID}:\n  n_envs: 1\n{entry}")
    with pytest.raises(RecipeError, match=re.escape(named)):
        read_recipe(path)


def test_with_recipe_is_deprecated_and_still_reads_the_recipe():
    with pytest.warns(DeprecationWarning, match="2026-12-06.*read_recipe"):
        cfg = with_recipe(TrainConfig(), "ppo")
    assert cfg == read_recipe("ppo").config
