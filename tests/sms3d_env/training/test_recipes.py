"""Recipes as data: the shipped recipe files make the configs of the shipped artefacts, a
behaviour-cloning run's ``config.json`` is a recipe of that run, an RL recipe is RL Baselines3
Zoo's file as it stands, and values given by hand are read as the recipe reads them."""

from __future__ import annotations

import json
from dataclasses import asdict
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sms3d_env.training import BCConfig
from sms3d_env.training.recipes import parse_hyperparams, read_recipe
from sms3d_env.training.zoo import RECIPES_DIR, RecipeError

WEIGHTS = Path(__file__).parents[3] / "sms3d_env" / "weights"


def test_the_pick_policy_recipe_is_the_shipped_policys_config():
    """``sms3d train-policy pick_policy`` trains what the shipped policy's config.json records
    (all but the run folder it was made in)."""
    recipe = read_recipe("pick_policy")
    saved = json.loads((WEIGHTS / "pick_policy" / "config.json").read_text())
    assert recipe.kind == saved["recipe"] == "bc"
    from_saved = read_recipe(WEIGHTS / "pick_policy" / "config.json").config  # absent fields: their defaults
    assert from_saved == BCConfig(**{**asdict(recipe.config), "out": saved["out"]})
    assert saved["episodes"] == recipe.config.episodes == 600

def test_every_shipped_recipe_reads():
    names = sorted(p.stem for p in RECIPES_DIR.glob("*.yml"))
    assert names == ["pick_policy", "ppo"]
    assert {read_recipe(name).kind for name in names} == {"bc", "rl"}


def test_the_ppo_recipe_is_rl_zoos_file_for_sms3dpicktrain_v2():
    recipe = read_recipe("ppo")
    assert (recipe.kind, recipe.env_id) == ("rl", "SMS3DPickTrain-v2")
    assert recipe.config["env_kwargs"] == {"scene": {"config": {"placement": {"num_mushrooms": 10}}, "pool": 500},
                                           "start": {"share": 0.75}}


def test_a_config_mapping_recipe_starts_from_the_bc_defaults(tmp_path):
    path = tmp_path / "bc.yml"
    path.write_text("recipe: bc\npose_error_range_deg: [0, 30]\nnet_arch: [64, 64]\n")
    recipe = read_recipe(path)
    assert recipe.kind == "bc" and recipe.source == str(path)
    assert recipe.config == BCConfig(pose_error_range_deg=(0.0, 30.0), net_arch=(64, 64))


@pytest.mark.parametrize("text, named", [
    ("recipe: imitation\n", "recipe: must be bc (or no recipe key: an RL Zoo file)"),
    ("recipe: bc\nlr: 0.1\n", "no field lr in a bc recipe"),
    ("recipe: rl\ntotal_steps: 10\n", "recipe: rl: a mapping of TrainConfig fields, removed in 0.2.0"),
    ("recipe: bc\nepochs: -1\n", "BCConfig.epochs must be an integer >= 1"),
    ("- a list\n", "not a mapping of settings"),
    ("recipe: [unclosed\n", "not readable RL Zoo YAML"),
])
def test_a_recipe_file_it_cannot_follow_is_refused_naming_the_file_and_key(tmp_path, text, named):
    path = tmp_path / "bad.yml"
    path.write_text(text)
    with pytest.raises(RecipeError, match=str(path).replace(".", r"\.")) as err:
        read_recipe(path)
    assert named in str(err.value)


@given(st.one_of(st.integers(-10**6, 10**6), st.floats(allow_nan=False, allow_infinity=False, width=32)))
def test_numbers_given_by_hand_are_read_as_numbers(number):
    """``--hyperparams learning_rate=3e-4``: a number in any notation is a number (YAML 1.1 reads
    ``3e-4`` as a string)."""
    for text in (repr(number), f"{number:e}", str(number)):
        assert parse_hyperparams([f"learning_rate={text}"])["learning_rate"] == pytest.approx(number), text


def test_rates_in_exponent_notation_are_numbers_in_a_recipe_file(tmp_path):
    """``learning_rate: 3e-4`` (YAML 1.2, JSON) is a number, as a run's config.json writes it."""
    path = tmp_path / "rates.yml"
    path.write_text("recipe: bc\nlearning_rate: 3e-4\nepisodes: 1000\n")
    cfg = read_recipe(path).config
    assert (cfg.learning_rate, cfg.episodes) == (3e-4, 1000)


def test_hyperparams_read_yaml_values():
    assert parse_hyperparams(["net_arch=[64, 64]", "learning_rate_final=null", "normalize=true",
                              "vec_env=dummy"]) == {"net_arch": [64, 64], "learning_rate_final": None,
                                                    "normalize": True, "vec_env": "dummy"}
    with pytest.raises(RecipeError, match="must be KEY=VALUE"):
        parse_hyperparams(["=3"])
