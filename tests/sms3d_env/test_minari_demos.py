"""Demonstrations as Minari datasets: ``sms3d record-demos`` writes a dataset that ``minari`` loads,
whose episodes are the picker's own (the same seeds give the same outcomes as a plain run), whose
env comes back from its spec, and which the bc recipe clones into a policy that runs."""

from __future__ import annotations

import importlib.metadata
import json
import re
import shutil
import subprocess
import sys

import gymnasium as gym
import h5py
import minari
import numpy as np
import pytest

import sms3d_env  # noqa: F401  (registers the env ids)
from sms3d_env.cli import main
from sms3d_env.pickers.episode import run_episode
from sms3d_env.pickers.scripted import ScriptedPicker
from sms3d_env.pose_sources import UniformNoisyPose
from sms3d_env.training.demonstrations import DatasetError, datasets_root, labelled_steps
from sms3d_env.training.envs import env_kwargs
from sms3d_env.training.imitation import (
    BCConfig,
    NonFiniteLossError,
    behaviour_clone,
    build_policy_model,
    train_bc,
)

DATASET = "sms3d/pick-v2/scripted-v0"
SEEDS = (5, 6, 7)
BED = 8


@pytest.fixture(scope="module")
def minari_root(tmp_path_factory):
    """An empty ``MINARI_DATASETS_PATH`` for the module, holding ``DATASET``: 3 scripted episodes."""
    root = tmp_path_factory.mktemp("minari")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MINARI_DATASETS_PATH", str(root))
        assert main(["record-demos", "--dataset-id", DATASET, "--episodes", "3", "--seed", str(SEEDS[0]),
                     "--num-mushrooms", str(BED)]) == 0
        yield root


def test_the_dataset_holds_the_pickers_own_episodes(minari_root):
    dataset = minari.load_dataset(DATASET)
    assert dataset.total_episodes == 3
    outcomes = list(dataset.storage.get_episode_metadata(dataset.episode_indices))
    env = gym.make("SMS3DPickTrain-v2", **env_kwargs(BED))
    try:
        plain = [run_episode(env, ScriptedPicker.for_env(env), seed) for seed in SEEDS]
    finally:
        env.close()
    assert [m["seed"] for m in outcomes] == list(SEEDS)
    assert [(bool(m["success"]), m["failure_cause"] or None) for m in outcomes] == \
        [(r["success"], r["failure_cause"]) for r in plain]
    assert sum(r["success"] for r in plain) >= 2  # the scripted picker picks on exact poses
    for episode, row in zip(dataset.iterate_episodes(), plain, strict=True):
        assert len(episode) == row["steps"]
        assert len(episode.observations["target_pose"]) == len(episode.infos["expert_action"]) == row["steps"] + 1
        # No DART noise: the executed action is the label.
        np.testing.assert_array_equal(episode.actions, episode.infos["expert_action"][:-1])
        assert episode.infos["is_success"][-1] == row["success"]
    assert dataset.total_steps == sum(r["steps"] for r in plain)


def test_the_metadata_says_what_made_the_dataset(minari_root):
    recording = minari.load_dataset(DATASET).storage.metadata["recording"]
    assert recording["picker"] == "scripted" and recording["pose_source"] == "oracle"
    assert recording["seeds"] == list(SEEDS) and recording["env_id"] == "SMS3DPickTrain-v2"
    assert recording["version"] == importlib.metadata.version("sms3d-pick") and recording["action_noise"] == 0.0


def test_recover_environment_builds_the_recorded_env(minari_root):
    dataset = minari.load_dataset(DATASET)
    env = dataset.recover_environment()
    try:
        assert env.spec.id == "SMS3DPickTrain-v2"
        obs, _ = env.reset(seed=SEEDS[0])
        assert len(env.unwrapped.scene.instances) == BED
        first = next(dataset.iterate_episodes())
        for key, value in obs.items():
            np.testing.assert_allclose(first.observations[key][0], value)
    finally:
        env.close()


def test_an_existing_id_is_refused_unless_overwritten(minari_root, capsys):
    data = minari_root / DATASET / "data" / "main_data.hdf5"
    before = data.stat().st_mtime_ns
    assert main(["record-demos", "--dataset-id", DATASET, "--episodes", "1", "--num-mushrooms", str(BED)]) == 2
    assert "--overwrite" in capsys.readouterr().out and data.stat().st_mtime_ns == before
    other = "sms3d/pick-v2/overwritten-v0"
    for episodes in (2, 1):
        assert main(["record-demos", "--dataset-id", other, "--episodes", str(episodes), "--num-mushrooms", str(BED),
                     "--overwrite"]) == 0
    assert minari.load_dataset(other).total_episodes == 1


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_an_id_that_names_a_namespace_is_refused_listing_its_datasets(minari_root, capsys, overwrite):
    namespace = DATASET.rpartition("/")[0]
    assert main(["record-demos", "--dataset-id", namespace, "--episodes", "1", "--num-mushrooms", "5",
                 *overwrite]) == 2
    out = capsys.readouterr().out
    assert f"{namespace!r} is a Minari namespace" in out and DATASET in out
    assert minari.load_dataset(DATASET).total_episodes == 3


def test_an_empty_minari_datasets_path_is_refused_as_minari_takes_it_as_set(monkeypatch, capsys):
    monkeypatch.setenv("MINARI_DATASETS_PATH", "")
    with pytest.raises(DatasetError, match="MINARI_DATASETS_PATH is set but empty"):
        datasets_root()
    assert main(["record-demos", "--dataset-id", "sms3d/pick-v2/empty-v0", "--episodes", "1"]) == 2
    assert "MINARI_DATASETS_PATH is set but empty" in capsys.readouterr().out


def test_a_killed_recordings_cache_is_removed_by_the_next_recording(minari_root):
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                           text=True, check=True)
    orphan = minari_root / f".recording.tmp{ended.stdout.strip()}"
    (orphan / "tmpcut" / "data").mkdir(parents=True)  # what a DataCollector killed with -9 left
    running = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        live = minari_root / f".recording.tmp{running.pid}"
        (live / "tmpbusy").mkdir(parents=True)
        assert main(["record-demos", "--dataset-id", "sms3d/pick-v2/after-kill-v0", "--episodes", "1",
                     "--num-mushrooms", "5"]) == 0
        assert not orphan.exists() and live.is_dir()  # a running recording's cache stays
        assert sorted(p.name for p in minari_root.iterdir() if p.name.startswith(".")) == [live.name]
    finally:
        running.kill()
        running.wait()
        shutil.rmtree(live, ignore_errors=True)


def _spoilt_copy(root, dataset_id: str, field: str) -> str:
    """A copy of ``DATASET`` under ``root`` named ``dataset_id`` whose first episode holds a NaN in
    ``field`` (a path inside the episode's HDF5 group)."""
    shutil.copytree(root / DATASET, root / dataset_id)
    metadata = root / dataset_id / "data" / "metadata.json"
    metadata.write_text(json.dumps({**json.loads(metadata.read_text()), "dataset_id": dataset_id}))
    with h5py.File(root / dataset_id / "data" / "main_data.hdf5", "r+") as f:
        values = f[f"episode_0/{field}"]
        row = values[1]
        row[0] = np.nan
        values[1] = row
    return dataset_id


@pytest.mark.parametrize("field, named", [("infos/expert_action", "infos['expert_action']"),
                                          ("observations/target_pose", "observations['target_pose']")])
def test_bc_refuses_a_dataset_holding_nan_before_training(minari_root, tmp_path, capsys, field, named):
    dataset_id = _spoilt_copy(minari_root, f"sms3d/pick-v2/nan-{field.split('/')[-1].replace('_', '-')}-v0",
                              field)
    out = tmp_path / "bc"
    assert main(["train-policy", "pick_policy", "--demos", dataset_id, "--out", str(out)]) == 2
    message = capsys.readouterr().out
    assert f"dataset {dataset_id!r}, episode 0: {named} holds non-finite values" in message
    assert not out.exists()
    with pytest.raises(DatasetError, match=rf"episode 0: {re.escape(named)} holds non-finite"):
        labelled_steps([minari.load_dataset(dataset_id)], ["target_pose"])  # DAgger rounds' data too


def test_a_loss_that_becomes_nan_stops_behaviour_cloning_before_the_weights(minari_root):
    import torch as th

    env = gym.make("SMS3DPickTrain-v2", **env_kwargs(BED))
    try:
        keys = list(env.observation_space.spaces)
        demos = labelled_steps([minari.load_dataset(DATASET)], keys)
        model = build_policy_model(env, demos, (16,), -2.0, 0)
    finally:
        env.close()
    demos["actions"][3, 0] = np.nan  # past the dataset checks, as a diverging regression would be
    with pytest.raises(NonFiniteLossError, match="loss became nan in epoch 1 of 2"):
        behaviour_clone(model, demos, 2, len(demos["actions"]), 1e-3, 0, progress=False)
    assert all(bool(th.isfinite(p).all()) for p in model.policy.parameters())


@pytest.mark.parametrize("argv, named", [
    (["--episodes", "0"], "--episodes"),
    (["--dataset-id", "no-version"], "dataset_id"),
    (["--dataset-id", "a/pick-v0"], "namespace 'a'"),
    (["--num-mushrooms", "0"], "--num-mushrooms"),
    (["--pose-error-deg", "10", "--pose-source", "oracle"], "--pose-source"),
    (["--pose-error-range", "30", "10"], "--pose-error-range"),
    (["--picker", "residual"], "residual"),
    (["--picker", "policy:/no/such/model.zip"], "/no/such/model.zip"),
])
def test_bad_arguments_are_refused_by_name_before_recording(minari_root, capsys, argv, named):
    args = ["record-demos", "--dataset-id", "sms3d/pick-v2/bad-v0", *argv]
    if "--dataset-id" in argv:
        args = ["record-demos", *argv]
    assert main(args) == 2
    assert named in capsys.readouterr().out
    assert not (minari_root / "sms3d/pick-v2/bad-v0").exists()


def test_dart_noise_and_a_drawn_pose_error_are_recorded(minari_root):
    dataset_id = "sms3d/pick-v2/noisy-v0"
    assert main(["record-demos", "--dataset-id", dataset_id, "--episodes", "1", "--num-mushrooms", str(BED),
                 "--pose-error-range", "5", "20", "--action-noise", "0.3"]) == 0
    dataset = minari.load_dataset(dataset_id)
    episode = next(dataset.iterate_episodes())
    labels = episode.infos["expert_action"][:-1]
    # The twist carries the noise; the suction command and the label stay clean.
    assert not np.allclose(episode.actions[:, :6], labels[:, :6])
    np.testing.assert_array_equal(episode.actions[:, 6], labels[:, 6])
    recording = dataset.storage.metadata["recording"]
    assert (recording["pose_source"], recording["pose_error_deg"], recording["action_noise"]) == \
        ("noisy", [5.0, 20.0], 0.3)
    env = dataset.recover_environment()
    try:
        assert isinstance(env.unwrapped.pose_source, UniformNoisyPose)
    finally:
        env.close()


def test_bc_clones_a_recorded_dataset_into_a_policy_that_runs(minari_root, tmp_path):
    from sms3d_env.training.evaluation import evaluate_policy_success

    cfg = BCConfig(demos=(DATASET,), epochs=2, dagger_rounds=1, dagger_episodes=1, dagger_epochs=1,
                   net_arch=(32, 32), out=str(tmp_path / "bc"))
    summary = train_bc(cfg, progress=False)
    dataset = minari.load_dataset(DATASET)
    kept = sum(bool(m["success"]) for m in dataset.storage.get_episode_metadata(dataset.episode_indices))
    assert summary["demos"] == [DATASET] and summary["demo_episodes"] == 3
    assert summary["demo_episodes_kept"] == kept and summary["training_steps"] > summary["demo_steps"]
    dagger = minari.MinariDataset(tmp_path / "bc" / "datasets" / "bc" / "dagger1-0-v0" / "data")
    assert dagger.env_spec == dataset.env_spec  # the round ran in the demonstrations' env
    result = evaluate_policy_success(tmp_path / "bc" / "model.zip", episodes=1, num_mushrooms=BED, seed=SEEDS[0])
    assert result["episodes"] == 1 and result["env_id"] == "SMS3DPickTrain-v2"


def test_bc_refuses_recording_settings_beside_given_demos():
    with pytest.raises(ValueError, match="episodes"):
        BCConfig(demos=(DATASET,), episodes=5)
    with pytest.raises(ValueError, match="demos"):
        BCConfig(demos=("",))


def test_bc_refuses_demos_of_another_env_before_writing(minari_root, tmp_path):
    dataset_id = "sms3d/pick-v2/base-v0"
    assert main(["record-demos", "--dataset-id", dataset_id, "--episodes", "1", "--num-mushrooms", str(BED),
                 "--env-id", "SMS3DPick-v1"]) == 0
    out = tmp_path / "bc"
    with pytest.raises(DatasetError, match=dataset_id):
        train_bc(BCConfig(demos=(dataset_id,), out=str(out)), progress=False)
    with pytest.raises(DatasetError, match="no Minari dataset"):
        train_bc(BCConfig(demos=("sms3d/pick-v2/missing-v0",), out=str(out)), progress=False)
    assert not out.exists()


def test_the_env_takes_its_json_forms_and_refuses_bad_ones_by_name():
    """What makes a dataset's env spec rebuildable: the bed as the ``SceneConfig``'s mapping gives
    the same beds as the ``SceneConfig``, every record argument has a mapping form, a drawn pose
    error is a ``pose_error_deg`` pair."""
    import generator
    from generator.errors import ConfigError
    from sms3d_env.scene_source import TOUCHING_PLACEMENT

    # The object form says the hull-apart placement the mapping form gets by default.
    placement = {f"placement__{k}": v for k, v in {"num_mushrooms": BED, **TOUCHING_PLACEMENT}.items()}
    as_object = gym.make("SMS3DPickTrain-v2", scene=generator.SceneConfig().replace(**placement))
    as_mapping = gym.make("SMS3DPickTrain-v2", scene={"placement": {"num_mushrooms": BED}})
    try:
        for env in (as_object, as_mapping):
            env.reset(seed=4)
        assert as_object.unwrapped.scene.to_dict() == as_mapping.unwrapped.scene.to_dict()
        rebuilt = gym.make(gym.envs.registration.EnvSpec.from_json(as_object.spec.to_json()))
        rebuilt.reset(seed=4)
        assert rebuilt.unwrapped.scene.to_dict() == as_object.unwrapped.scene.to_dict()
        rebuilt.close()
    finally:
        as_object.close()
        as_mapping.close()
    with pytest.raises(ConfigError, match="num_mushroomz"):
        gym.make("SMS3DPickTrain-v2", scene={"placement": {"num_mushroomz": 3}})
    with pytest.raises(TypeError, match="scene must be"):
        gym.make("SMS3DPickTrain-v2", scene=3)
    for bad in ({"pose_error_deg": (0, 30)},  # needs the noisy source
                {"pose_source": "noisy", "pose_error_deg": (30, 10)},
                {"pose_source": "noisy", "pose_error_deg": (0, 30, 60)}):
        with pytest.raises(ValueError, match="pose_error_deg"):
            gym.make("SMS3DPickTrain-v2", **bad)


def test_every_record_argument_has_a_json_form_that_rebuilds_the_same_env():
    from sms3d_env.cameras import ImageObservation, RenderCamera
    from sms3d_env.controller import ControllerConfig
    from sms3d_env.rewards import RewardConfig
    from sms3d_env.scene_source import TOUCHING_PLACEMENT, SceneSourceConfig
    from sms3d_env.start_states import PregraspStart
    from sms3d_env.targets import TargetRule

    records = {"scene": SceneSourceConfig(config={"placement": {"num_mushrooms": BED, **TOUCHING_PLACEMENT}},
                                          pool=2, pool_seed=3),
               "target": TargetRule("random", max_tilt_deg=30.0), "reward_type": RewardConfig("staged", 200),
               "controller": ControllerConfig(substeps=10, posture_target="tool"), "start": PregraspStart(0.5),
               "image_obs": ImageObservation((16, 24)), "render_camera": RenderCamera("side", (32, 48))}
    forms = {"scene": {"config": {"placement": {"num_mushrooms": BED}}, "pool": 2, "pool_seed": 3},
             "target": {"rule": "random", "max_tilt_deg": 30.0}, "reward_type": {"kind": "staged", "horizon": 200},
             "controller": {"substeps": 10, "posture_target": "tool"}, "start": {"share": 0.5},
             "image_obs": {"size": [16, 24]}, "render_camera": {"name": "side", "size": [32, 48]}}
    env = gym.make("SMS3DPickTrain-v2", **forms)
    rebuilt = gym.make(gym.envs.registration.EnvSpec.from_json(env.spec.to_json()))
    try:
        for made in (env, rebuilt):
            u = made.unwrapped
            assert (u.scene_source.config, u.target_rule, u.reward_config, u.ctrl_cfg, u.start, u.image_obs,
                    u.render_camera.size) == (records["scene"], records["target"], records["reward_type"],
                                              records["controller"], records["start"], records["image_obs"], (32, 48))
    finally:
        env.close()
        rebuilt.close()


def test_an_overwrite_that_fails_keeps_the_dataset_it_was_to_replace(minari_root, monkeypatch):
    from sms3d_env.training import demonstrations

    def cut_short(specs, *args, **kwargs):
        (demonstrations.dataset_path(specs[0][0]) / "data").mkdir(parents=True)  # a partial recording
        raise KeyboardInterrupt

    monkeypatch.setattr(demonstrations, "record_datasets", cut_short)
    with pytest.raises(KeyboardInterrupt):
        main(["record-demos", "--dataset-id", DATASET, "--episodes", "1", "--num-mushrooms", "5", "--overwrite"])
    assert minari.load_dataset(DATASET).total_episodes == 3
    assert not (minari_root / demonstrations.REPLACED_FOLDER).exists() or not any(
        (minari_root / demonstrations.REPLACED_FOLDER).rglob("*-v0*"))
