"""The point network's training recipe: the settings ``sms3d train-pose`` reads from a YAML file.

``recipe.yml`` beside this module is the shipped network's (``perception/weights/
posenet_default.pt``, its last training step); ``--recipe FILE`` reads another and ``--set
KEY=VALUE`` replaces single entries. A recipe has three sections, each optional; a key left out
keeps its config class's default:

==================  ==========================================================================
``net``             :class:`~perception.baselines.point_transformer.config.PoseNetConfig`
``train``           :class:`~perception.baselines.point_transformer.config.TrainConfig`'s
                    optimisation fields; ``train.augment``: :class:`~perception.baselines.
                    point_transformer.augment.AugmentConfig`
``data``            :class:`TrainingData`: the rendered views and which clouds are taken
==================  ==========================================================================

What a run is, rather than how it learns, is set by the command's flags (:data:`RUN_FIELDS`:
``--epochs``, ``--seed``, ``--device``, ``--time-limit-min``, ``--quiet``), not by recipe keys.
Files are read by :func:`generator.config_file.read_config_file` (safe YAML: no code runs from a
file, a key given twice is refused, ``1e-4`` is a number). Every error is a
:class:`~perception.errors.PerceptionConfigError` naming the file or flag and the key.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, dataclass
from pathlib import Path
from typing import Any, NamedTuple

from generator.config_file import parse_config_value, read_config_file
from generator.errors import ConfigError
from perception.baselines.point_transformer.augment import AugmentConfig
from perception.baselines.point_transformer.config import PoseNetConfig, TrainConfig
from perception.errors import PerceptionConfigError

#: The shipped network's recipe (package data).
SHIPPED_RECIPE = Path(__file__).resolve().with_name("recipe.yml")

#: ``TrainConfig`` fields that the command's flags set, not the recipe: field -> flag.
RUN_FIELDS = {"epochs": "--epochs", "seed": "--seed", "device": "--device", "time_limit_s": "--time-limit-min",
              "progress": "--quiet"}


@dataclass(frozen=True)
class TrainingData:
    """Which clouds a run trains on, besides the files its flags name (``--data``, ``--scenes``).

    - ``num_train`` / ``num_val``: single-mushroom views rendered for training / validation when
      no ``--data`` / ``--val-data`` (nor ``--scenes``) is given;
    - ``model_ids``: the generator's mesh models rendered, per species (model 6 of each is held
      out for evaluation);
    - ``procedural_models``: > 0 renders the training views of this many fresh procedural shapes
      per species instead (seeded by ``--seed``); validation views stay on ``model_ids``;
    - ``add_synthetic``: with ``--scenes``, this many rendered views are added to the training
      clouds;
    - ``camera_model``: views are rendered through the dataset's stereo camera model (every depth
      effect of ``sms3d generate --realism``, D405) instead of 0.5 mm white depth noise;
    - ``cap_only``: with ``--scenes`` and the renderer's masks, the cap's points only.
    """

    num_train: int = 4000
    num_val: int = 500
    model_ids: tuple[int, ...] = (0, 1, 2, 3, 4, 5)
    procedural_models: int = 0
    add_synthetic: int = 0
    camera_model: bool = False
    cap_only: bool = False

    def __post_init__(self) -> None:
        for name, lo in (("num_train", 1), ("num_val", 1), ("procedural_models", 0), ("add_synthetic", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < lo:
                raise PerceptionConfigError(name, f"must be an int >= {lo}, got {value!r}")
        ids = self.model_ids
        if not ids or not all(isinstance(i, int) and not isinstance(i, bool) and i >= 0 for i in ids):
            raise PerceptionConfigError("model_ids", f"must be one or more ints >= 0, got {ids!r}")
        for name in ("camera_model", "cap_only"):
            if not isinstance(getattr(self, name), bool):
                raise PerceptionConfigError(name, f"must be true or false, got {getattr(self, name)!r}")


@dataclass(frozen=True)
class Recipe:
    """A recipe made into the configs that ``train`` takes, and the file it came from."""

    net: PoseNetConfig
    train: TrainConfig
    data: TrainingData
    source: str


class Override(NamedTuple):
    """One recipe entry replaced: ``key`` (``"train.lr"``) set to ``value`` by ``origin`` (the flag
    that gave it, for error messages)."""

    origin: str
    key: str
    value: Any


def _default(field: dataclasses.Field) -> Any:
    return field.default_factory() if field.default is MISSING else field.default


def _schema() -> dict[str, dataclasses.Field]:
    """Every recipe key (``section.field``) and the dataclass field it sets."""
    sections = (("net", PoseNetConfig, ()), ("train", TrainConfig, (*RUN_FIELDS, "augment")),
                ("train.augment", AugmentConfig, ()), ("data", TrainingData, ()))
    return {f"{section}.{f.name}": f for section, cls, skip in sections
            for f in dataclasses.fields(cls) if f.name not in skip}


SCHEMA = _schema()
SECTIONS = ("net", "train", "train.augment", "data")


def _unknown_key(where: str, key: str) -> PerceptionConfigError:
    section = key.rpartition(".")[0]
    if section == "train" and key.rpartition(".")[2] in RUN_FIELDS:
        return PerceptionConfigError(f"{where}: {key}", f"is set by {RUN_FIELDS[key.rpartition('.')[2]]}, not "
                                                        "by the recipe")
    if section in SECTIONS:
        keys = [k.rpartition(".")[2] for k in SCHEMA if k.rpartition(".")[0] == section]
        return PerceptionConfigError(f"{where}: {key}", f"no such key (the {section} keys: {', '.join(keys)})")
    return PerceptionConfigError(f"{where}: {key}", "no such key (keys are net.*, train.*, train.augment.*, data.*)")


def _flatten(mapping: Any, where: str, prefix: str = "") -> dict[str, Any]:
    """A recipe file's nested sections as ``{"section.field": value}``."""
    if not isinstance(mapping, Mapping):
        raise PerceptionConfigError(f"{where}: {prefix.rstrip('.') or 'recipe'}",
                                    f"must be a mapping of keys, got {type(mapping).__name__}")
    flat: dict[str, Any] = {}
    for key, value in mapping.items():
        name = f"{prefix}{key}"
        if name in SECTIONS:
            flat.update(_flatten(value, where, name + "."))
        elif name in SCHEMA:
            flat[name] = value
        else:
            raise _unknown_key(where, name)
    return flat


def _typed(where: str, key: str, value: Any) -> Any:
    """``value`` as the field ``key`` holds it (lists become tuples, ints floats where a float is
    wanted), or ``PerceptionConfigError`` naming ``where`` and ``key`` for a value of another
    type; ranges are then checked by the config class."""
    field = SCHEMA[key]
    default = _default(field)

    def number(v: Any, kind: type) -> bool:
        return isinstance(v, (int, float) if kind is float else kind) and not isinstance(v, bool)

    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, (int, float)):
        ok = number(value, type(default))
        value = type(default)(value) if ok else value
    elif isinstance(default, str):
        ok = isinstance(value, str)
    elif isinstance(default, tuple):
        kind = type(default[0])
        fixed = "..." not in str(field.type)
        ok = (isinstance(value, (list, tuple)) and all(number(v, kind) for v in value)
              and (not fixed or len(value) == len(default)))
        value = tuple(kind(v) for v in value) if ok else value
    else:  # every recipe field has one of the types above (a test keeps it so)
        raise TypeError(f"{key}: no recipe type for {type(default).__name__}")
    if not ok:
        shape = f"a list of {len(default)} " if isinstance(default, tuple) and "..." not in str(field.type) else ""
        wanted = f"{shape}{type(default[0] if isinstance(default, tuple) else default).__name__}"
        raise PerceptionConfigError(f"{where}: {key}", f"expected {wanted}{'s' if shape else ''}, got {value!r}")
    return value


def parse_set(items: Sequence[str]) -> list[Override]:
    """``--set`` arguments (``["train.lr=3e-4", "data.model_ids=[0, 1]"]``) as overrides, each
    value read as a recipe file would hold it."""
    out = []
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise PerceptionConfigError("--set", f"{item!r}: must be KEY=VALUE, e.g. train.lr=3e-4")
        try:
            value = parse_config_value(text.strip(), f"--set {key}")
        except ConfigError as exc:
            raise PerceptionConfigError(exc.field, exc.message) from None
        out.append(Override("--set", key, value))
    return out


def read_recipe(path: str | Path = SHIPPED_RECIPE, overrides: Sequence[Override] = (), **run: Any) -> Recipe:
    """The recipe in ``path`` with ``overrides`` applied in order, made into configs; ``run``
    gives the :data:`RUN_FIELDS` of ``TrainConfig`` (``epochs``, ``seed``, ...).

    Raises:
        PerceptionConfigError: naming the file (or the override's flag) and the key, for a file
            that cannot be read or parsed, a key that is no recipe key, or a value the config
            classes refuse.
    """
    source = str(path)
    try:
        raw = read_config_file(path)
    except ConfigError as exc:
        raise PerceptionConfigError(exc.field, exc.message) from None
    values = _flatten(raw, source)
    origin = dict.fromkeys(values, source)  # who set each key, for error messages
    for override in overrides:
        if override.key not in SCHEMA:
            raise _unknown_key(override.origin, override.key)
        values[override.key], origin[override.key] = override.value, override.origin
    values = {key: _typed(origin[key], key, value) for key, value in values.items()}

    def section(name: str) -> dict[str, Any]:
        return {key.rpartition(".")[2]: v for key, v in values.items() if key.rpartition(".")[0] == name}

    def made(name: str, build):
        try:
            return build()
        except PerceptionConfigError as exc:
            message = str(exc).removeprefix(f"{exc.field}: ")
            if name == "train" and exc.field in RUN_FIELDS:
                raise PerceptionConfigError(RUN_FIELDS[exc.field], message) from None
            key = f"{name}.{exc.field}"
            raise PerceptionConfigError(f"{origin.get(key, source)}: {key}", message) from None

    augment = made("train.augment", lambda: AugmentConfig(**section("train.augment")))
    return Recipe(
        net=made("net", lambda: PoseNetConfig(**section("net"))),
        train=made("train", lambda: TrainConfig(**section("train"), augment=augment, **run)),
        data=made("data", lambda: TrainingData(**section("data"))),
        source=source,
    )
