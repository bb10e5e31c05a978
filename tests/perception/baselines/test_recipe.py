"""The point network's recipe (``recipe.yml``, ``--recipe``, ``--set``) and ``train-pose``'s
deprecated flags: what each sets, and errors that name the file or flag and the key."""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import pytest

from perception.baselines.point_transformer import cli
from perception.baselines.point_transformer.recipe import (
    RUN_FIELDS,
    SCHEMA,
    SHIPPED_RECIPE,
    Override,
    parse_set,
    read_recipe,
)
from perception.deprecation import DEPRECATED_ON, REMOVED_AFTER
from perception.errors import PerceptionConfigError

SHIPPED_SETTINGS = Path(__file__).resolve().parents[3] / "perception" / "weights" / "posenet_default.json"


def _train_pose_args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    cli.register(parser.add_subparsers(dest="command"))
    return parser.parse_args(["train-pose", "--out", "unused", *argv])


def test_the_shipped_recipe_is_the_shipped_networks_last_training_step() -> None:
    trained = json.loads(SHIPPED_SETTINGS.read_text())["training"]
    recipe = read_recipe()
    assert recipe.net.to_dict() == trained["net"]
    settings = {k: list(v) if isinstance(v, tuple) else v for k, v in recipe.train.to_dict().items()}
    settings["augment"] = {k: list(v) if isinstance(v, tuple) else v for k, v in settings["augment"].items()}
    differing = {k for k in trained["train"] if settings[k] != trained["train"][k]}
    assert differing <= set(RUN_FIELDS)  # epochs, seed, time limit, progress: the run's own flags


def test_every_recipe_key_has_a_type_the_reader_checks() -> None:
    # _typed refuses a field whose default is none of these; a new config field must be one.
    for key, field in SCHEMA.items():
        default = field.default_factory() if field.default is dataclasses.MISSING else field.default
        assert isinstance(default, (bool, int, float, str, tuple)), key


def test_a_file_and_set_replace_entries_in_order(tmp_path) -> None:
    path = tmp_path / "r.yml"
    path.write_text("net:\n  backbone: pointnet\n  num_points: 256\ntrain:\n  lr: 3e-4\n  augment:\n"
                    "    occlusion_fraction: [0.1, 0.3]\ndata:\n  model_ids: [2]\n")
    recipe = read_recipe(path, [Override("--lr", "train.lr", 1e-3), *parse_set(["train.lr=2e-3", "net.head=9d"])],
                         epochs=3, seed=4)
    assert (recipe.net.backbone, recipe.net.num_points, recipe.net.head) == ("pointnet", 256, "9d")
    assert recipe.train.lr == 2e-3 and (recipe.train.epochs, recipe.train.seed) == (3, 4)
    assert recipe.train.augment.occlusion_fraction == (0.1, 0.3)
    assert recipe.data.model_ids == (2,) and recipe.source == str(path)
    # Keys the file leaves out keep the config classes' defaults, not the shipped recipe's.
    assert recipe.train.loss == "geodesic" and recipe.train.augment.occlusion_prob == 0.0


@pytest.mark.parametrize(("text", "message"), [
    ("net:\n  backbone: pointnet\n  backbone: pointnet2\n", "net.backbone: duplicate key"),
    ("net:\n  num_points: 8\n", "net.num_points: must be an int >= 16"),
    ("net:\n  num_points: 512.5\n", "net.num_points: expected int"),
    ("train:\n  lerning_rate: 1e-3\n", "train.lerning_rate: no such key (the train keys: batch_size, lr"),
    ("train:\n  epochs: 3\n", "train.epochs: is set by --epochs, not by the recipe"),
    ("train:\n  augment:\n    scale_range: [0.9]\n", "train.augment.scale_range: expected a list of 2 floats"),
    ("data:\n  camera_model: 1\n", "data.camera_model: expected bool"),
    ("net: [1, 2]\n", "net: must be a mapping of keys, got list"),
    ("nets:\n  head: 6d\n", "nets: no such key (keys are net.*, train.*, train.augment.*, data.*)"),
    ("net: !!python/object/apply:os.system ['echo ran']\n", "cannot parse configuration"),
])
def test_a_bad_recipe_file_names_itself_and_the_key(tmp_path, text, message) -> None:
    path = tmp_path / "bad.yml"
    path.write_text(text)
    with pytest.raises(PerceptionConfigError) as info:
        read_recipe(path)
    assert str(path) in str(info.value) and message in str(info.value)


def test_set_errors_name_the_flag(tmp_path) -> None:
    with pytest.raises(PerceptionConfigError, match=r"^--set: 'train\.lr': must be KEY=VALUE"):
        parse_set(["train.lr"])
    with pytest.raises(PerceptionConfigError, match=r"^--set: train\.lr: expected float, got 'fast'"):
        read_recipe(overrides=parse_set(["train.lr=fast"]))
    with pytest.raises(PerceptionConfigError, match=r"^--num-points: net\.num_points: must be an int >= 16"):
        read_recipe(overrides=[Override("--num-points", "net.num_points", 4)])
    with pytest.raises(PerceptionConfigError, match=r"^--device: expected 'cpu' or 'cuda\[:i\]'"):
        read_recipe(device="tpu")


def test_a_deprecated_flag_still_sets_its_entry_and_warns_with_the_dates(capsys) -> None:
    args = _train_pose_args("--lr", "1e-3", "--occlusion-fraction", "0.1", "0.3", "--set", "net.num_points=128")
    recipe = cli._recipe(args)
    assert recipe.train.lr == 1e-3 and recipe.train.augment.occlusion_fraction == (0.1, 0.3)
    assert recipe.net.num_points == 128
    err = capsys.readouterr().err
    assert f"--lr is deprecated ({DEPRECATED_ON}) and will be removed after {REMOVED_AFTER}: use --set train.lr=0.001" in err
    assert "use --set train.augment.occlusion_fraction=[0.1, 0.3]" in err
    # --set comes last, so it wins over the flag it replaces.
    assert cli._recipe(_train_pose_args("--lr", "1e-3", "--set", "train.lr=5e-5")).train.lr == 5e-5


def test_without_deprecated_flags_nothing_is_warned(capsys) -> None:
    assert cli._recipe(_train_pose_args("--seed", "3")) == read_recipe(SHIPPED_RECIPE, seed=3)
    assert capsys.readouterr().err == ""


def test_the_measured_worse_options_are_hidden_and_warned_about(capsys) -> None:
    with pytest.raises(SystemExit):
        _train_pose_args("--help")
    usage = capsys.readouterr().out
    assert "--recipe" in usage and "--depth-smoothing-px" not in usage and "--edge-tolerance-mm" not in usage
    args = _train_pose_args("--depth-smoothing-px", "4", "--edge-tolerance-mm", "10")
    assert cli._recipe(args).net.depth_smoothing_px == 4.0 and cli._edge_tolerance_mm(args) == 10.0
    err = capsys.readouterr().err
    assert "--depth-smoothing-px is deprecated" in err and "use --set net.depth_smoothing_px=4.0" in err
    assert "--edge-tolerance-mm is deprecated" in err and "measured worse" in err
