"""Files beside a saved policy choose nothing that runs: an env id a file names is one of the
package's or is refused before anything is imported; a model SB3's own ``save`` wrote runs in the
env whose spaces are its own, unpickled never; no file makes a loader inflate, expand or recurse
without bound; and what loads is checked (finite weights, usable statistics) naming the file."""

from __future__ import annotations

import io
import json
import os
import pickle
import re
import subprocess
import sys
import zipfile

import cloudpickle
import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from generator.errors import ConfigError
from sms3d_env.pickers.policy import PolicyActor
from sms3d_env.pickers.registry import make_picker_env, parse_picker
from sms3d_env.policies import files as model_files
from sms3d_env.policies.files import (
    POLICY_SPEC_MEMBER,
    ObservationStats,
    PolicyFileError,
    RunningStats,
    read_policy_spec,
    save_model,
)
from sms3d_env.policies.loader import load_sb3
from sms3d_env.policies.zoo_runs import read_run_yaml, read_vecnormalize
from sms3d_env.training.cli import main
from sms3d_env.training.zoo import RecipeError, read_zoo_yaml

ENV_ID = "SMS3DPickTrain-v1"
#: The newest version of ENV_ID's env: a model with no record of its env runs there.
NEWEST_ENV_ID = "SMS3DPickTrain-v2"


def no_unpickling(monkeypatch) -> None:
    """From now on in the test, any unpickling fails it."""
    def refuse(*_args, **_kwargs):
        raise AssertionError("something was unpickled")

    for module in (pickle, cloudpickle):
        monkeypatch.setattr(module, "loads", refuse)
    monkeypatch.setattr(pickle, "load", refuse)


@pytest.fixture
def evilmod(tmp_path, monkeypatch):
    """A module ``evilmod`` importable from the working folder (as it would be beside a run a
    user evaluates there); importing it creates the returned marker file."""
    marker = tmp_path / "evilmod_ran"
    (tmp_path / "evilmod.py").write_text(f"open({str(marker)!r}, 'w').close()\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "evilmod", raising=False)
    return marker


def _zoo_run(folder, args_yml):
    """An rl_zoo3 run's layout: ``<ENV>.zip`` beside ``<ENV>/args.yml`` and ``config.yml``."""
    (folder / ENV_ID).mkdir(parents=True)
    (folder / f"{ENV_ID}.zip").write_bytes(b"never read")
    (folder / ENV_ID / "args.yml").write_text(args_yml)
    (folder / ENV_ID / "config.yml").write_text("policy: MultiInputPolicy\n")
    return folder / f"{ENV_ID}.zip"


@pytest.mark.parametrize("record", ["config.json", "args.yml"])
def test_an_env_id_that_a_file_names_imports_nothing_and_is_refused_by_file_and_field(tmp_path, evilmod, capsys,
                                                                                        record):
    if record == "config.json":
        (tmp_path / "run").mkdir()
        model = tmp_path / "run" / "model.zip"
        model.write_bytes(b"never read")
        (tmp_path / "run" / "config.json").write_text(json.dumps({"env_id": f"evilmod:{ENV_ID}", "algo": "ppo"}))
        named, field = tmp_path / "run" / "config.json", "env_id"
    else:
        model = _zoo_run(tmp_path / "zoo", f"algo: ppo\nenv: evilmod:{ENV_ID}\n")
        named, field = tmp_path / "zoo" / ENV_ID / "args.yml", "env"
    assert main(["eval-policy", "--model", str(model), "--episodes", "1"]) == 2
    out = capsys.readouterr().out
    assert out.startswith(f"error: {named}: {field}: 'evilmod:{ENV_ID}' is none of this package's env ids")
    assert out.count("\n") == 1
    with pytest.raises(PolicyFileError, match=f"{field}: 'evilmod:"):
        PolicyActor(model)
    with pytest.raises(PolicyFileError, match=f"{field}: 'evilmod:"):
        make_picker_env(parse_picker(f"policy:{model}"))
    assert not evilmod.exists()


@pytest.fixture(scope="module")
def sb3_saved(tmp_path_factory):
    """The README's snippet, its model saved by SB3's own ``save`` (no description, no config.json)."""
    folder = tmp_path_factory.mktemp("readme")
    env = gym.make(ENV_ID, scene={"pool": 4})
    model = PPO("MultiInputPolicy", env, n_steps=64, batch_size=64, device="cpu", seed=0)
    model.learn(total_timesteps=64)
    model.save(folder / "ppo_pick")
    env.close()
    return folder / "ppo_pick.zip", model


def test_a_model_sb3_saved_runs_in_the_env_its_spaces_are_with_nothing_unpickled(sb3_saved, capsys, monkeypatch):
    path, model = sb3_saved
    with zipfile.ZipFile(path) as z:
        assert POLICY_SPEC_MEMBER not in z.namelist()
    with monkeypatch.context() as m:
        no_unpickling(m)
        actor = PolicyActor(path)
        # SMS3DPickTrain-v1 (ENV_ID, where it trained) and -v2 have the same spaces; v2 supersedes v1.
        assert actor.env_id == NEWEST_ENV_ID
        assert PolicyActor(path, env_id=ENV_ID).env_id == ENV_ID
    env = actor.make_env(scene={"placement": {"num_mushrooms": 8}})
    try:
        obs, _ = env.reset(seed=0)
        np.testing.assert_array_equal(actor(obs), model.predict(obs, deterministic=True)[0])
    finally:
        env.close()
    for extra, env_id in (([], NEWEST_ENV_ID), (["--env-id", ENV_ID], ENV_ID)):
        assert main(["eval-policy", "--model", str(path), "--episodes", "1", "--num-mushrooms", "8", *extra]) == 0
        assert f'"env_id": "{env_id}"' in capsys.readouterr().out
    assert main(["eval-policy", "--model", str(path), "--episodes", "1", "--env-id", "SMS3DPick-v1"]) == 2
    assert capsys.readouterr().out == (f"error: {path}: its observation and action spaces are not those of "
                                       "SMS3DPick-v1 (with its default options)\n")
    env, picker = make_picker_env(parse_picker(f"policy@{ENV_ID}:{path}"))
    env.close()
    assert picker.env_id == ENV_ID
    with pytest.raises(ValueError, match="policy@ENV_ID:PATH"):
        parse_picker(f"policy@evilmod:X:{path}")


def test_an_env_id_given_against_the_models_record_is_refused_by_name(tmp_path, sb3_saved, capsys):
    _, model = sb3_saved
    save_model(model, tmp_path / "model.zip")  # its description names the env it trained in
    with zipfile.ZipFile(tmp_path / "model.zip") as z:
        assert read_policy_spec(z).env_id == ENV_ID
    assert PolicyActor(tmp_path / "model.zip").env_id == ENV_ID
    with pytest.raises(ConfigError, match=f"env_id: {NEWEST_ENV_ID} differs from {ENV_ID}, the env that "
                                          f"{tmp_path / 'model.zip'} says"):
        PolicyActor(tmp_path / "model.zip", env_id=NEWEST_ENV_ID)
    (tmp_path / "config.json").write_text(json.dumps({"env_id": ENV_ID, "algo": "ppo"}))
    assert main(["eval-policy", "--model", str(tmp_path / "model.zip"), "--env-id", "SMS3DPick-v1"]) == 2
    assert capsys.readouterr().out.startswith(f"error: argument --env-id: SMS3DPick-v1 differs from {ENV_ID}, the "
                                              f"env that {tmp_path / 'config.json'} says")


@pytest.fixture
def sparse_copy():
    """A second env of this package with SMS3DPick's spaces (registered for the test alone):
    the package's own ids have one env per set of spaces, in versions."""
    from gymnasium.envs.registration import register, registry

    register(id="SMS3DPickSparseCopy-v0", entry_point="sms3d_env.pick_env:SMS3DPickEnv",
             max_episode_steps=250, kwargs={"reward_type": "sparse"})
    yield "SMS3DPickSparseCopy-v0"
    del registry["SMS3DPickSparseCopy-v0"]


def _untrained_model(path):
    env = gym.make("SMS3DPick-v2")
    PPO("MultiInputPolicy", env, n_steps=64, batch_size=64, device="cpu").save(path)
    env.close()
    return path


def test_a_model_whose_spaces_fit_versions_of_one_env_runs_in_the_latest(tmp_path):
    # SMS3DPick-v1 has v2's spaces: one env in two versions.
    assert PolicyActor(_untrained_model(tmp_path / "model.zip")).env_id == "SMS3DPick-v2"


def test_a_model_whose_spaces_fit_several_envs_is_refused_naming_them(tmp_path, sparse_copy):
    model = _untrained_model(tmp_path / "model.zip")
    with pytest.raises(PolicyFileError, match=f"are those of SMS3DPick-v1, SMS3DPick-v2, {sparse_copy}; "
                                              "name its env with --env-id"):
        PolicyActor(model)
    assert PolicyActor(model, env_id=sparse_copy).env_id == sparse_copy


def _rewritten(src, dst, members):
    """``src``'s zip with ``members`` (name -> bytes) replaced or added."""
    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as b:
        for name in a.namelist():
            b.writestr(name, members.pop(name, None) or a.read(name))
        for name, content in members.items():
            b.writestr(name, content)
    return dst


def test_zip_members_are_not_inflated_past_their_limits(tmp_path, sb3_saved, monkeypatch):
    path, _ = sb3_saved
    bomb = _rewritten(path, tmp_path / "bomb.zip", {"data": b" " * (model_files.MAX_METADATA_BYTES + 1)})
    assert bomb.stat().st_size < 200_000
    with pytest.raises(PolicyFileError, match=r"member 'data' inflates to \d+ bytes, more than any such member") as e:
        PolicyActor(bomb)
    assert len(str(e.value)) < 400
    monkeypatch.setattr(model_files, "MAX_WEIGHTS_BYTES", 10_000)  # pytorch_variables.pth is 1.3 kB
    with pytest.raises(PolicyFileError, match=r"member 'policy(\.optimizer)?\.pth' inflates"):
        load_sb3(path, ("ppo",))


def test_run_files_that_expand_or_nest_without_bound_are_refused_in_one_short_line(tmp_path):
    laughs = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    laughs += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 10)]
    (tmp_path / "args.yml").write_text("\n".join(laughs) + "\nalgo: ppo\nenv: *a9\n")
    (tmp_path / "deep.yml").write_text("a: " + "[" * 100_000 + "]" * 100_000 + "\n")
    for name in ("args.yml", "deep.yml"):
        with pytest.raises(PolicyFileError, match=f"{tmp_path / name}: not readable RL Zoo YAML") as e:
            read_run_yaml(tmp_path / name)
        assert len(str(e.value)) < 500
        with pytest.raises(RecipeError, match=name):
            read_zoo_yaml(tmp_path / name)
    (tmp_path / "big.yml").write_text("a: " + "x" * (model_files.MAX_RUN_FILE_BYTES + 1))
    with pytest.raises(PolicyFileError, match="more than any RL Zoo YAML file"):
        read_run_yaml(tmp_path / "big.yml")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.zip").write_bytes(b"never read")
    (tmp_path / "run" / "config.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(PolicyFileError, match=r"config.json: not a readable run configuration \(RecursionError"):
        PolicyActor(tmp_path / "run" / "model.zip")


def test_a_policy_description_nested_without_bound_is_refused_naming_the_file(tmp_path, sb3_saved):
    path, model = sb3_saved
    save_model(model, tmp_path / "model.zip")
    with zipfile.ZipFile(tmp_path / "model.zip") as z:
        spec = json.loads(z.read(POLICY_SPEC_MEMBER))
    depth = 5000  # spaces in spaces, past the recursion limit: written as text (json.dumps recurses too)
    space = '{"type": "Dict", "spaces": [["k", ' * depth + json.dumps(spec["observation_space"]) + "]]}" * depth
    text = json.dumps({**spec, "observation_space": None}).replace('"observation_space": null',
                                                                   f'"observation_space": {space}')
    bad = _rewritten(tmp_path / "model.zip", tmp_path / "deep.zip", {POLICY_SPEC_MEMBER: text.encode()})
    with pytest.raises(PolicyFileError, match=f"{bad}: its {POLICY_SPEC_MEMBER} is no policy description "
                                              r"\(nested deeper"):
        load_sb3(bad, ("ppo",))


class _DictEnv(gym.Env):
    observation_space = gym.spaces.Dict({"b": gym.spaces.Box(-1, 1, (2,)), "a": gym.spaces.Box(0, np.inf, (3,))})
    action_space = gym.spaces.Box(-1, 1, (2,))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return self.observation_space.sample(), {}

    def step(self, action):
        return self.observation_space.sample(), 1.0, False, False, {}


def test_dict_observation_vecnormalize_statistics_read_as_sb3_loads_them(tmp_path):
    """The pickle is this test's own: SB3's load of it is the reference."""
    venv = VecNormalize(DummyVecEnv([_DictEnv]), norm_obs=True, norm_reward=True)
    venv.seed(0)
    venv.reset()
    for _ in range(20):
        venv.step(np.zeros((1, 2), np.float32))
    venv.save(str(tmp_path / "vecnormalize.pkl"))
    reference = VecNormalize.load(str(tmp_path / "vecnormalize.pkl"), DummyVecEnv([_DictEnv]))
    stats = read_vecnormalize(tmp_path / "vecnormalize.pkl")
    assert set(stats.obs) == {"a", "b"} and stats.returns.count == reference.ret_rms.count
    obs = {k: np.random.default_rng(1).normal(size=s.shape) for k, s in _DictEnv.observation_space.spaces.items()}
    for key, value in stats.normalize_obs(obs).items():
        np.testing.assert_allclose(value, reference.normalize_obs(obs)[key], rtol=1e-6)
    stats.check_usable(tmp_path / "vecnormalize.pkl", _DictEnv.observation_space)


@pytest.mark.parametrize("change, why", [
    ({"var": np.array([1.0, -1.0, 1.0])}, "a variance below 0"),
    ({"mean": np.array([np.nan, 0.0, 0.0])}, "not finite"),
    ({"mean": np.zeros(4), "var": np.ones(4)}, "statistics of shape"),
])
def test_observation_statistics_that_cannot_normalise_are_refused_naming_the_file(tmp_path, change, why,
                                                                                   write_obs_rms):
    good = {"mean": np.zeros(3), "var": np.ones(3), "count": 5.0}
    stats = ObservationStats({"a": RunningStats(**{**good, **change}), "b": RunningStats(np.zeros(2), np.ones(2), 5.0)},
                             10.0, 1e-8)
    write_obs_rms(stats, tmp_path / "obs_rms.npz")
    with pytest.raises(PolicyFileError, match=f"{tmp_path / 'obs_rms.npz'}: obs\\['a'\\]: .*{why}"):
        ObservationStats.load(tmp_path / "obs_rms.npz").check_usable(tmp_path / "obs_rms.npz",
                                                                      _DictEnv.observation_space)


def _tensors(obj):
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


def test_weights_that_are_not_finite_or_variables_that_are_not_the_models_are_refused(tmp_path):
    model = PPO("MultiInputPolicy", _DictEnv(), n_steps=16, batch_size=16, device="cpu")
    save_model(model, tmp_path / "model.zip")
    weights = {k: v.clone() for k, v in model.policy.state_dict().items()}
    weights["action_net.weight"][0, 0] = float("nan")
    nan = _rewritten(tmp_path / "model.zip", tmp_path / "nan.zip", {"policy.pth": _tensors(weights)})
    with pytest.raises(PolicyFileError, match=f"{nan}: policy.pth: action_net.weight holds values that are not "
                                              "finite"):
        load_sb3(nan, ("ppo",))
    overwrite = _rewritten(tmp_path / "model.zip", tmp_path / "variables.zip",
                           {"pytorch_variables.pth": _tensors({"policy.log_std": torch.zeros(7)})})
    with pytest.raises(PolicyFileError, match=f"{overwrite}: pytorch_variables.pth: entries \\['policy.log_std'\\], "
                                              "which loading would set as attributes"):
        load_sb3(overwrite, ("ppo",))


def test_the_suggested_record_command_survives_quotes_and_runs_nothing_else(tmp_path):
    folder = tmp_path / """it's "quoted" $(touch MARKER) `touch MARKER2`"""
    folder.mkdir()
    PPO("MlpPolicy", "Pendulum-v1", policy_kwargs={"net_arch": [8]}, device="cpu").save(folder / "model.zip")
    with pytest.raises(PolicyFileError) as e:
        load_sb3(folder / "model.zip", ("ppo",))
    command = re.search(r"add one with (python -c .*) \(that load runs", str(e.value)).group(1)
    env = {**os.environ, "PATH": f"{os.path.dirname(sys.executable)}{os.pathsep}{os.environ['PATH']}"}
    result = subprocess.run(["bash", "-c", command], cwd=tmp_path, env=env, capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert not list(tmp_path.glob("MARKER*")) and not list(folder.glob("MARKER*"))
    assert load_sb3(folder / "model.zip", ("ppo",)).observation_space.shape == (3,)


def test_a_command_contradicting_the_options_a_policy_was_trained_with_is_refused_by_name(tmp_path):
    """A policy trained on the Jaco that a sweep asked for the gantry ran the Jaco and labelled
    every row gantry. Options the command repeats as trained pass."""
    import shutil

    from sms3d_env.policies.files import PolicyFileError
    from sms3d_env.policies.loader import SHIPPED_POLICY

    for name in ("model.zip", "config.json"):
        shutil.copy(SHIPPED_POLICY.parent / name, tmp_path / name)
    config = json.loads((tmp_path / "config.json").read_text())
    config["env_options"]["robot"] = "gantry"  # recorded as trained
    (tmp_path / "config.json").write_text(json.dumps(config))
    actor = PolicyActor(tmp_path / "model.zip")
    with pytest.raises(PolicyFileError, match=r"robot='jaco' \(trained with 'gantry'\)"):
        actor.make_env(robot="jaco")
    env = actor.make_env(robot="gantry", task_obs=True, scene={"placement": {"num_mushrooms": 5}})
    assert env.unwrapped.robot_cfg.name == "gantry"
    env.close()


def test_saved_env_options_that_are_no_env_arguments_are_refused_naming_the_file(tmp_path):
    import shutil

    from sms3d_env.policies.files import PolicyFileError
    from sms3d_env.policies.loader import SHIPPED_POLICY

    for name in ("model.zip", "config.json"):
        shutil.copy(SHIPPED_POLICY.parent / name, tmp_path / name)
    config = json.loads((tmp_path / "config.json").read_text())
    config["env_options"]["max_episode_steps"] = 1  # would cut every episode to one step
    (tmp_path / "config.json").write_text(json.dumps(config))
    with pytest.raises(PolicyFileError, match=r"config.json.*'max_episode_steps' are no arguments of the env"):
        PolicyActor(tmp_path / "model.zip")
