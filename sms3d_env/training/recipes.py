"""Training recipes as data: a YAML file says what ``sms3d train-policy RECIPE`` trains.

Two kinds (the shipped recipes are ``sms3d_env/recipes/<name>.yml``):

- ``rl``: an **RL Baselines3 Zoo hyperparameter file**, keyed by env id (``ppo.yml``), trained by
  RL Zoo's own trainer (:mod:`~sms3d_env.training.zoo`); its ``config`` is the file's entry.
- ``bc``: a **config mapping**, ``recipe: bc`` and the fields of
  :class:`~sms3d_env.training.imitation.BCConfig` by their names, the keys a behaviour-cloning
  run's ``config.json`` holds (``pick_policy.yml`` equals the shipped policy's); its ``config``
  is that ``BCConfig``. Its fields may be replaced one by one (:meth:`Recipe.with_fields`: the
  command's flags and ``--hyperparams KEY=VALUE``), each checked as ``BCConfig`` checks it; a
  key that is no field is a :class:`~sms3d_env.training.zoo.RecipeError` naming the file and key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from generator.config_file import parse_config_value
from generator.errors import ConfigError
from sms3d_env.training.zoo import RecipeError, read_zoo_yaml, recipe_entry, recipe_path

KINDS = ("rl", "bc")
#: Keys of a behaviour-cloning run's ``config.json`` that the trainer derives or fixes rather than
#: reads: a ``config.json`` is a recipe of its run, and these are skipped.
RECORD_ONLY_KEYS = ("env_options", "algo", "env_id", "max_episode_steps")
#: Why a bc recipe's ``teacher`` other than the scripted picker (``estimate``) is refused.
TEACHER_REMOVED = ("the privileged teacher was removed in 0.2.0: its clone picked 24 % at 30 deg against the "
                   "scripted picker's 78 % (docs/results-training.md)")
#: What refuses a config mapping of the reinforcement-learning kind, which 0.2.0 removed.
RL_MAPPING_REMOVED = ("recipe: rl: a mapping of TrainConfig fields, removed in 0.2.0: an RL recipe is an RL "
                      "Baselines3 Zoo hyperparameter file, as sms3d_env/recipes/ppo.yml (docs/training.md)")


def bc_fields() -> tuple[str, ...]:
    """The fields a ``bc`` recipe sets (``BCConfig``'s)."""
    from sms3d_env.training.imitation import BCConfig

    return tuple(f.name for f in fields(BCConfig))


@dataclass(frozen=True)
class Recipe:
    """A training recipe: its ``kind`` (:data:`KINDS`), the file it came from and its config (a
    ``BCConfig``, or for ``rl`` the RL Zoo file's entry for ``env_id``)."""

    kind: str
    source: str
    config: Any
    env_id: str | None = None

    def with_fields(self, values: Mapping[str, Any], origin: str) -> Recipe:
        """This ``bc`` recipe with ``values`` (field name → value) replacing its own;
        ``RecipeError`` naming ``origin`` (what gave them, e.g. ``--hyperparams``) and the field
        when one is no field or has a value ``BCConfig`` refuses."""
        unknown = sorted(set(values) - set(bc_fields()))
        if unknown:
            raise RecipeError(f"{origin}: no field {', '.join(unknown)} in a bc recipe "
                              f"(its fields: {', '.join(bc_fields())})")
        try:
            return replace(self, config=replace(self.config, **values))
        except (TypeError, ValueError) as exc:
            raise RecipeError(f"{origin}: {exc}") from None


def read_recipe(name_or_path: str | Path, env_id: str | None = None) -> Recipe:
    """A shipped recipe by name (``"ppo"``, ``"pick_policy"``) or a recipe file (either kind; a
    behaviour-cloning run's ``config.json`` is one); ``env_id``: an RL Zoo file's entry (``None``:
    its first). ``FileNotFoundError`` naming it when there is neither, ``RecipeError`` naming
    the file and key for anything it cannot follow."""
    from sms3d_env.training.imitation import BCConfig

    path = recipe_path(name_or_path)
    data = read_zoo_yaml(path)
    if "recipe" not in data:  # an RL Zoo hyperparameter file
        env_id, entry = recipe_entry(path, env_id)
        return Recipe("rl", str(path), entry, env_id)
    kind = data.pop("recipe")
    if kind == "rl":
        raise RecipeError(f"{path}: {RL_MAPPING_REMOVED}")
    if kind != "bc":
        raise RecipeError(f"{path}: recipe: must be bc (or no recipe key: an RL Zoo file), got {kind!r}")
    values = {k: v for k, v in data.items() if k not in RECORD_ONLY_KEYS}
    if values.pop("teacher", "estimate") != "estimate":  # older runs record the scripted picker's
        raise RecipeError(f"{path}: teacher: {TEACHER_REMOVED}")
    return Recipe("bc", str(path), BCConfig()).with_fields(values, str(path))


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
