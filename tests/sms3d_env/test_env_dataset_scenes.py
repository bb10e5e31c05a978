import json

import gymnasium as gym
import numpy as np
import pytest

import sms3d_env  # noqa: F401
from generator.dataset.readers import load_scenes
from sms3d_env.cli import main as sms3d


def _hulls_apart(tmp_path):
    """A scene configuration whose beds SMS3DPick-v2 takes: no two collision hulls interpenetrating
    (its mushrooms collide)."""
    path = tmp_path / "hulls.json"
    path.write_text(json.dumps({"placement": {"overlap_iou": 0.0, "overlap_solids": "hulls"}}))
    return ["--config", str(path)]


def test_env_reads_scenes_from_a_dataset_folder(tmp_path):
    out = tmp_path / "beds"
    assert sms3d(["generate", "--out", str(out), "--num-scenes", "2", "--num-mushrooms", "6",
                  "--workers", "1", "--seed", "3", *_hulls_apart(tmp_path)]) == 0
    scenes = load_scenes(out)
    assert len(scenes) == 2
    env = gym.make("SMS3DPick-v2", scene=str(out))
    env.reset(seed=0, options={"scene": 1})
    assert env.unwrapped.scene.to_json() == scenes[1].to_json()
    obs, *_ = env.step(np.zeros(env.action_space.shape, np.float32))
    assert all(np.all(np.isfinite(v)) for v in obs.values())
    env.close()
    (tmp_path / "empty").mkdir()
    with pytest.raises(Exception, match="manifest"):
        gym.make("SMS3DPick-v2", scene=str(tmp_path / "empty"))


def test_env_refuses_a_dataset_scene_whose_checksum_differs(tmp_path):
    from generator.dataset.errors import CorruptFileError

    out = tmp_path / "beds"
    assert sms3d(["generate", "--out", str(out), "--num-scenes", "1", "--num-mushrooms", "4",
                  "--workers", "1", "--seed", "5"]) == 0
    scene_json = next(out.glob("*/scene.json"))
    scene_json.write_text(scene_json.read_text().replace('"species"', ' "species"', 1))
    with pytest.raises(CorruptFileError, match="scene.json"):
        gym.make("SMS3DPick-v2", scene=str(out))
    assert len(load_scenes(out, verify=False)) == 1  # an explicit opt-out still reads it
