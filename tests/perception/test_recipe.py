"""The shipped networks' recipes (perception/recipes/*.yml): what they run equals what the shipped
files record, a bad recipe or flag is an error naming the file and key (or the flag), and a tiny
recipe runs end to end and, run again, resumes rather than redoing anything."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import dataclasses
import json
import re
import shlex
from pathlib import Path

import pytest
import yaml

from generator.dataset.seeds import split_of
from generator.run_folder import SETTINGS_FILE
from perception.cli_detector import segmenter_train_config
from perception.cli_pose import axis_train_config
from perception.detection.load import SHIPPED_SEGMENTER
from perception.pose.axis_cnn import SHIPPED_AXIS_CNN, AxisCNNConfig
from perception.recipe import RECIPES_DIR, read_recipe
from perception.run_files import read_torch_file
from sms3d_env.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]
COMMAND_OF = {"segmenter": "train-segmenter", "axis_cnn": "train-axis-cnn"}


def dry_run(capsys, *argv: str) -> list[list[str]]:
    """The commands ``sms3d ARGV --dry-run`` prints, each without ``sms3d``."""
    capsys.readouterr()
    assert main([*argv, "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert all(line.startswith("sms3d ") for line in lines)
    return [shlex.split(line)[1:] for line in lines]


def parsed(argv: list[str]):
    return build_parser(argv[0]).parse_args(argv)


def test_the_shipped_recipes_are_the_ones_the_commands_name() -> None:
    assert sorted(p.stem for p in RECIPES_DIR.glob("*.yml")) == sorted(COMMAND_OF)
    for name, command in COMMAND_OF.items():
        assert read_recipe(name).command == command


def test_a_dry_run_prints_every_command_with_the_runs_folders_and_runs_none(capsys, tmp_path) -> None:
    out, data, cache = tmp_path / "out", tmp_path / "data", tmp_path / "cache"
    commands = dry_run(capsys, "train-axis-cnn", "axis_cnn", "--out", str(out), "--data-root", str(data),
                       "--cache", str(cache), "--threads", "1")
    recipe = read_recipe("axis_cnn")
    generate, train = commands[:len(recipe.datasets)], commands[len(recipe.datasets):]
    assert [c[0] for c in generate] == ["generate"] * len(recipe.datasets)
    assert [c[0] for c in train] == ["train-axis-cnn"] * len(recipe.steps)
    for argv, dataset in zip(generate, recipe.datasets):
        args = parsed(argv)
        assert (args.out, args.num_scenes, args.num_mushrooms, args.seed, args.realism) == (
            str(data / dataset.name), dataset.beds, dataset.mushrooms, dataset.seed, dataset.realism)
        assert args.split_ratios == recipe.split_ratios
    for index, (argv, step) in enumerate(zip(train, recipe.steps)):
        args = parsed(argv)
        assert args.out == str(out / step.name) and args.scenes == [str(data / name) for name in step.datasets]
        assert (args.threads, args.cache) == (1, str(cache))  # the run's flags replace the recipe's
        assert args.init == (str(out / recipe.steps[index - 1].name / "best.pt") if step.continues else None)
    assert not tmp_path.exists() or not any(tmp_path.iterdir())


def test_the_segmenter_recipe_trains_with_the_shipped_segmenters_saved_settings(capsys) -> None:
    *generate, train = dry_run(capsys, "train-segmenter", "segmenter")
    saved = read_torch_file(SHIPPED_SEGMENTER, "segmenter checkpoint")["train"]
    assert dataclasses.asdict(segmenter_train_config(parsed(train))) == saved
    # the step reads every dataset the recipe generates
    assert parsed(train).data == [parsed(argv).out for argv in generate]


def _network_shapes(steps: list) -> list[tuple[int, int]]:
    """The (width, hidden) each step trains: its flags, else the network it starts from."""
    shapes, default = [], AxisCNNConfig()
    for args in steps:
        width, hidden = shapes[-1] if args.init is not None else (default.width, default.hidden)
        shapes.append((args.width or width, args.hidden or hidden))
    return shapes


def _recorded_axis_commands() -> list:
    """The training commands the shipped axis CNN's metrics.json records, parsed; a list of
    datasets it abbreviates (``<the 16 --realism sets>``, ``...``) parses as ``None``."""
    recorded = json.loads((SHIPPED_AXIS_CNN.parent / "metrics.json").read_text())["commands"]
    commands = []
    for line in recorded:
        if not line.startswith("sms3d train-axis-cnn"):
            continue
        abbreviated = "<" in line or " ... " in line
        argv = shlex.split(re.sub(r"<[^>]*>", "ABBREVIATED", line).replace(" ... ", " "))[1:]
        args = parsed(argv)
        args.scenes = None if abbreviated else args.scenes
        commands.append(args)
    return commands


def test_the_axis_cnn_recipe_is_the_steps_that_made_the_shipped_network(capsys) -> None:
    steps = [parsed(argv) for argv in dry_run(capsys, "train-axis-cnn", "axis_cnn") if argv[0] == "train-axis-cnn"]
    recorded = _recorded_axis_commands()
    assert len(steps) == len(recorded) == 11
    for index, (ours, theirs) in enumerate(zip(steps, recorded)):
        assert axis_train_config(ours) == axis_train_config(theirs), index
        assert (ours.init is None, ours.threads, ours.masks or "shipped") == (
            theirs.init is None, theirs.threads, theirs.masks or "shipped"), index
        if theirs.scenes is not None:
            assert [Path(s).name for s in ours.scenes] == [Path(s).name for s in theirs.scenes], index
    assert _network_shapes(steps) == _network_shapes(recorded)
    # the last step is what axis_cnn.pt records of its own training
    shipped = read_torch_file(SHIPPED_AXIS_CNN, "axis-CNN checkpoint")
    assert dataclasses.asdict(axis_train_config(steps[-1])) == shipped["extra"]["train"]
    assert [Path(s).name for s in steps[-1].scenes] == [Path(s).name for s in shipped["extra"]["scenes"]]
    assert (steps[-1].masks, steps[-1].init is None) == (shipped["extra"]["masks"], shipped["extra"]["init"] is None)
    assert _network_shapes(steps)[-1] == (shipped["config"]["width"], shipped["config"]["hidden"])


def test_no_training_bed_is_an_evaluation_bed_and_shared_datasets_agree() -> None:
    # The held-out and fresh evaluation beds of docs/reproducing.md: a training dataset with one of
    # their seeds would train on the very beds the results are measured on.
    page = (ROOT / "docs" / "reproducing.md").read_text(encoding="utf-8")
    evaluation = {int(seed) for seed in re.findall(r"sms3d generate --out runs/seg/\w+ .*?--seed (\d+)", page)}
    assert {9100, 9200, 20100, 20600} <= evaluation
    datasets = {}
    for name in COMMAND_OF:
        for dataset in read_recipe(name).datasets:
            assert dataset.seed not in evaluation, (name, dataset)
            # one data_root: a name means one dataset (else `sms3d generate` refuses the second recipe's)
            assert datasets.setdefault(dataset.name, dataset) == dataset, (name, dataset)
    seeds = [d.seed for d in datasets.values()]
    assert len(seeds) == len(set(seeds))
    assert read_recipe("segmenter").data_root == read_recipe("axis_cnn").data_root


def _two_bed_seed(ratios: tuple[float, float, float]) -> int:
    """A run seed whose two beds fall one in the train split and one in val."""
    return next(seed for seed in range(1000) if {split_of(seed, 0, ratios), split_of(seed, 1, ratios)} == {"train", "val"})


SEGMENTER_STEP = {"name": "seg", "datasets": ["tiny"], "options": {"epochs": 1, "batch_size": 1, "crop": 64, "val_every": 1}}
AXIS_STEPS = [{"name": "01", "datasets": ["tiny"], "options": {"epochs": 1, "batch_size": 1}},
              {"name": "02", "datasets": ["tiny"], "continues": True, "options": {"epochs": 1, "batch_size": 1}}]
TINY_STEPS = {"train-segmenter": [SEGMENTER_STEP], "train-axis-cnn": AXIS_STEPS}


def _tiny_recipe(tmp_path: Path, command: str, /, **changes) -> Path:
    """A recipe file for ``command``: one dataset of two beds of three mushrooms, one epoch a step,
    everything under ``tmp_path``; ``changes`` replace its keys."""
    ratios = (0.5, 0.5, 0.0)
    recipe = {"command": command, "out": str(tmp_path / "run"), "data_root": str(tmp_path / "data"),
              "split_ratios": list(ratios), "options": {"threads": 1},
              "datasets": [{"name": "tiny", "beds": 2, "mushrooms": 3, "seed": _two_bed_seed(ratios)}],
              "steps": TINY_STEPS[command], **changes}
    path = tmp_path / f"{command}.yml"
    path.write_text(yaml.safe_dump(recipe, sort_keys=False))
    return path


@pytest.mark.parametrize(("command", "change", "key", "why"), [
    ("train-segmenter", {"epochs": 3}, "epochs", "no such key"),
    ("train-segmenter", {"command": "train-axis-cnn"}, "command", "sms3d train-axis-cnn"),
    ("train-segmenter", {"split_ratios": [1.0, 0.0, 0.0]}, "split_ratios", "must be > 0"),
    ("train-segmenter", {"datasets": [{"name": "tiny", "beds": "many", "mushrooms": 3, "seed": 1}]}, "datasets[0].beds",
     "integer"),
    ("train-segmenter", {"datasets": [{"name": "tiny", "beds": 2, "mushrooms": 500, "seed": 1}]},
     "datasets[0].mushrooms", "[1, 100]"),
    ("train-segmenter", {"datasets": [{"name": "tiny", "beds": 2, "mushrooms": 3, "seed": 1, "realsim": True}]},
     "datasets[0].realsim", "no such key"),
    ("train-segmenter", {"datasets": [{"name": "../up", "beds": 2, "mushrooms": 3, "seed": 1}]}, "datasets[0].name",
     "folder name"),
    ("train-segmenter", {"steps": [{**SEGMENTER_STEP, "datasets": ["huge"]}]}, "steps[0].datasets", "no dataset 'huge'"),
    ("train-segmenter", {"steps": [{**SEGMENTER_STEP, "options": {"epochz": 1}}]}, "steps[0].options.epochz",
     "no such option"),
    ("train-segmenter", {"steps": [{**SEGMENTER_STEP, "options": {"lr": "fast"}}]}, "steps[0].options.lr", "float"),
    ("train-segmenter", {"steps": [{**SEGMENTER_STEP, "options": {"epochs": 0}}]}, "steps[0].options.epochs", ">= 1"),
    ("train-segmenter", {"steps": [{**SEGMENTER_STEP, "options": {"data": ["elsewhere"]}}]}, "steps[0].options.data",
     "no recipe option"),
    ("train-segmenter", {"options": {"out": "elsewhere"}}, "options.out", "no recipe option"),
    ("train-segmenter", {"steps": [{**SEGMENTER_STEP, "continues": True}]}, "steps[0].continues", "no step before"),
    ("train-axis-cnn", {"steps": [AXIS_STEPS[0], {**AXIS_STEPS[1], "options": {"loss": "huber"}}]},
     "steps[1].options.loss", "must be one of cosine, angle"),
    ("train-axis-cnn", {"steps": [AXIS_STEPS[0], {**AXIS_STEPS[1], "options": {"width": 0}}]},
     "steps[1].options.width", ">= 1"),
    ("train-axis-cnn", {"steps": [AXIS_STEPS[0], {**AXIS_STEPS[1], "options": {"init": "other.pt"}}]},
     "steps[1].options.init", "no recipe option"),
    ("train-axis-cnn", {"steps": [AXIS_STEPS[0], {**AXIS_STEPS[1], "name": "01"}]}, "steps[1].name", "earlier"),
])
def test_a_bad_recipe_is_refused_naming_the_file_and_key(tmp_path, capsys, command, change, key, why) -> None:
    path = _tiny_recipe(tmp_path, command, **change)
    assert main([command, str(path), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert f"{path}: {key}" in err and why in err, err
    assert not (tmp_path / "run").exists() and not (tmp_path / "data").exists()


def test_a_key_given_twice_is_refused(tmp_path, capsys) -> None:
    path = _tiny_recipe(tmp_path, "train-segmenter")
    path.write_text(path.read_text() + "out: elsewhere\n")
    assert main(["train-segmenter", str(path), "--dry-run"]) == 2
    assert f"{path}" in (err := capsys.readouterr().err) and "out: duplicate key" in err


def test_flags_that_the_recipe_sets_are_refused_and_recipe_flags_need_a_recipe(tmp_path, capsys) -> None:
    out = str(tmp_path / "o")
    for argv, named in (
        # beside a recipe, a flag that sets what the recipe sets would be ignored
        (["train-segmenter", "segmenter", "--epochs", "3", "--dry-run"], "error: --epochs"),
        (["train-segmenter", "segmenter", "--data", str(tmp_path), "--dry-run"], "error: --data"),
        (["train-axis-cnn", "axis_cnn", "--resume", "--dry-run"], "error: --resume"),
        (["train-axis-cnn", "axis_cnn", "--masks", "shipped", "--dry-run"], "error: --masks"),
        (["train-axis-cnn", "no_such_recipe", "--dry-run"], "no recipe file no_such_recipe (shipped recipes: axis_cnn"),
        # without one, the recipe's flags mean nothing and the datasets and folder must be named
        (["train-segmenter", "--data", str(tmp_path), "--out", out, "--dry-run"], "error: --dry-run"),
        (["train-axis-cnn", "--scenes", str(tmp_path), "--out", out, "--data-root", out], "error: --data-root"),
        (["train-segmenter", "--out", out], "error: --data: required without a RECIPE"),
        (["train-axis-cnn", "--scenes", str(tmp_path)], "error: --out: required without a RECIPE"),
    ):
        assert main(argv) == 2, argv
        assert named in capsys.readouterr().err, argv
    assert not (tmp_path / "o").exists()


def _run_twice(capsys, command: str, path: Path, tmp_path: Path) -> tuple[str, str]:
    """The recipe run, then run again: the second run's stdout and stderr."""
    assert main([command, str(path)]) == 0
    capsys.readouterr()
    scene_files = {p: p.stat().st_mtime_ns for p in (tmp_path / "data").rglob("*.png")}
    networks = {p: p.read_bytes() for p in (tmp_path / "run").rglob("best.pt")}
    assert scene_files and networks
    assert main([command, str(path)]) == 0
    again = capsys.readouterr()
    assert {p: p.stat().st_mtime_ns for p in (tmp_path / "data").rglob("*.png")} == scene_files  # not rendered again
    assert {p: p.read_bytes() for p in (tmp_path / "run").rglob("best.pt")} == networks  # not trained again
    return again.out, again.err


def test_a_tiny_segmenter_recipe_runs_end_to_end_and_then_says_it_is_complete(tmp_path, capsys) -> None:
    path = _tiny_recipe(tmp_path, "train-segmenter")
    out, err = _run_twice(capsys, "train-segmenter", path, tmp_path)
    assert f"{tmp_path / 'run'} is complete (1 of 1 epochs)" in err
    assert f"done; the network is {tmp_path / 'run' / 'best.pt'}" in out
    manifest = json.loads((tmp_path / "data" / "tiny" / "manifest.json").read_text())
    assert (manifest["status"], manifest["num_scenes"], manifest["config"]["placement"]["num_mushrooms"]) == (
        "complete", 2, 3)


def test_a_tiny_axis_cnn_recipe_continues_each_step_from_the_last_and_resumes(tmp_path, capsys) -> None:
    path = _tiny_recipe(tmp_path, "train-axis-cnn", options={"threads": 1, "cache": str(tmp_path / "cache")})
    out, err = _run_twice(capsys, "train-axis-cnn", path, tmp_path)
    first, second = tmp_path / "run" / "01", tmp_path / "run" / "02"
    assert json.loads((second / SETTINGS_FILE).read_text())["init"] == str(first / "best.pt")
    assert f"{first} is complete" in err and f"{second} is complete" in err
    assert f"done; the network is {second / 'best.pt'}" in out
