"""Training recipes as data: a YAML file says what ``sms3d train-policy RECIPE`` trains, and a
run's ``config.json`` records the same fields.

Two forms are read (the shipped recipes are ``sms3d_env/recipes/<name>.yml``):

- an **RL Baselines3 Zoo hyperparameter file**, keyed by env id (``ppo.yml``), which
  ``python -m rl_zoo3.train`` reads too; its keys map onto :class:`TrainConfig` fields as
  :func:`~sms3d_env.training.zoo.recipe_fields` says. Kind ``rl``.
- a **config mapping**: ``recipe:`` (``rl`` or ``bc``) and the fields of the kind's config
  class, :class:`TrainConfig` (``rl``) or :class:`~sms3d_env.training.imitation.BCConfig`
  (``bc``), by their names — the keys a run's
  ``config.json`` holds (``pick_policy.yml`` equals the shipped policy's).

A recipe's fields may then be replaced one by one (:meth:`Recipe.with_fields`: the command's
flags and ``--hyperparams KEY=VALUE``); every field is checked as the config class checks it,
and a key that is no field of the kind is a :class:`RecipeError` naming the file and the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from generator.config_file import parse_config_value
from generator.errors import ConfigError
from sms3d_env.training.config import (
    REMOVED_EXPERIMENTS,
    REMOVED_FIELDS,
    TrainConfig,
    removed_fields_set,
)
from sms3d_env.training.zoo import RecipeError, read_zoo_yaml, recipe_fields, recipe_path

#: What ``sms3d train-policy`` trains: PPO/SAC from scratch, or behaviour cloning of the scripted
#: picker with DAgger.
KINDS = ("rl", "bc")
#: Recipe kinds of experiments removed from the package: kind → why (a recipe or a run's
#: ``config.json`` of that kind is refused with it).
REMOVED_KINDS = {"residual": REMOVED_EXPERIMENTS["residual"], "trigger-rollouts": REMOVED_EXPERIMENTS["trigger"]}
#: How messages name a recipe of each kind ("an rl recipe").
ARTICLES = {"rl": "an", "bc": "a"}
#: Keys of a run's ``config.json`` that the trainer derives from the fields (or fixes) rather than
#: reads: a ``config.json`` is a recipe of its run, and these are skipped.
RECORD_ONLY_KEYS = {"rl": ("env_options", "observation_keys"),
                    "bc": ("env_options", "algo", "env_id", "max_episode_steps")}


def _config_class(kind: str) -> type:
    if kind == "bc":
        from sms3d_env.training.imitation import BCConfig

        return BCConfig
    return TrainConfig


def field_names(kind: str) -> tuple[str, ...]:
    """The fields a recipe of ``kind`` sets (its config class's)."""
    return tuple(f.name for f in fields(_config_class(kind)))


@dataclass(frozen=True)
class Recipe:
    """A training recipe: its ``kind`` (:data:`KINDS`), the file it came from (``None``: the
    kind's defaults) and the config it makes (``TrainConfig`` or ``BCConfig``)."""

    kind: str
    source: str
    config: Any

    def with_fields(self, values: Mapping[str, Any], origin: str) -> Recipe:
        """This recipe with ``values`` (field name → value) replacing its own; ``RecipeError``
        naming ``origin`` (what gave them, e.g. ``--hyperparams``) and the field when one is no
        field of this kind or has a value its config class refuses."""
        names = field_names(self.kind)
        unknown = sorted(set(values) - set(names))
        if unknown:
            raise RecipeError(f"{origin}: no field {', '.join(unknown)} in {ARTICLES[self.kind]} {self.kind} recipe "
                              f"(its fields: {', '.join(names)})")
        try:
            return replace(self, config=replace(self.config, **values))
        except (TypeError, ValueError) as exc:
            raise RecipeError(f"{origin}: {exc}") from None


def default_recipe(kind: str) -> Recipe:
    """The kind's defaults: its config class's."""
    if kind in REMOVED_KINDS:
        raise RecipeError(f"recipe kind {kind!r}: {REMOVED_KINDS[kind]}")
    if kind not in KINDS:
        raise RecipeError(f"recipe kind {kind!r}: must be one of {', '.join(KINDS)}")
    return Recipe(kind, f"the {kind} defaults", _config_class(kind)())


def read_recipe(name_or_path: str | Path) -> Recipe:
    """A shipped recipe by name (``"ppo"``, ``"pick_policy"``) or a recipe
    file (either form; a run's ``config.json`` is one);
    ``FileNotFoundError`` naming it when there is neither, ``RecipeError`` naming the file and
    key for anything it cannot follow."""
    path = recipe_path(name_or_path)
    data = read_zoo_yaml(path)
    if "recipe" not in data:  # an RL Zoo hyperparameter file
        _, values = recipe_fields(path)
        try:
            return Recipe("rl", str(path), TrainConfig(**values))
        except ValueError as exc:
            raise RecipeError(f"{path}: {exc}") from None
    kind = data.pop("recipe")
    if kind in REMOVED_KINDS:
        raise RecipeError(f"{path}: recipe: {kind}: {REMOVED_KINDS[kind]}")
    if kind not in KINDS:
        raise RecipeError(f"{path}: recipe: must be one of {', '.join(KINDS)}, got {kind!r}")
    values = {k: v for k, v in data.items() if k not in RECORD_ONLY_KEYS[kind]}
    removed = removed_fields_set(values)
    if removed:
        raise RecipeError(f"{path}: {removed[0]}: {REMOVED_FIELDS[removed[0]]}")
    values = {k: v for k, v in values.items() if k not in REMOVED_FIELDS}  # older runs record them at defaults
    recipe = default_recipe(kind).with_fields(values, str(path))
    return replace(recipe, source=str(path))


def parse_hyperparams(items: list[str]) -> dict[str, Any]:
    """``["learning_rate=1e-4", "net_arch=[64, 64]"]`` as a mapping, each value read as a
    configuration file holds it (:func:`generator.config_file.parse_config_value`: ``3e-4`` a
    number, ``[64, 64]`` a list, ``null``, ``true``); ``RecipeError`` naming an item without
    ``=`` or whose value does not parse."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise RecipeError(f"--hyperparams {item!r}: must be KEY=VALUE (e.g. learning_rate=1e-4)")
        try:
            out[key.strip()] = parse_config_value(text.strip(), f"--hyperparams {key.strip()}")
        except ConfigError as exc:
            raise RecipeError(str(exc)) from None
    return out
