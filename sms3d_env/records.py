"""Checks shared by the env's option records (``SceneSourceConfig``, ``TargetRule``,
``RewardConfig``, ``ControllerConfig``, ``PregraspStart``, ``ImageObservation``,
``RenderCamera``) and its argument checks (:mod:`sms3d_env.env_args`): each refuses a bad value
with a ``ValueError`` (a ``TypeError`` for a wrong kind of value) naming the field.

``record_of`` reads a record's mapping form, the JSON that an env spec holds (Minari datasets
and RL Zoo recipes rebuild the env from its spec, and ``config.json`` stores a policy's env
options): ``{"share": 0.5}`` for ``PregraspStart(share=0.5)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, TypeVar

import numpy as np

R = TypeVar("R")


def check_int(name: str, value: Any, least: int = 0) -> None:
    """ValueError unless ``value`` is an integer (not a bool) >= ``least``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")


def check_number(name: str, value: Any, low: float, high: float, what: str) -> None:
    """ValueError unless ``value`` is a finite real number (not a bool) in ``[low, high]``;
    ``what`` says what is expected."""
    if (isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating))
            or not (math.isfinite(value) and low <= value <= high)):
        raise ValueError(f"{name} must be {what}, got {value!r}")


def check_flag(name: str, value: Any) -> None:
    """TypeError unless ``value`` is a bool (numpy's too): by truthiness, ``"no"`` or ``"false"``
    would switch the option on."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be True or False, got {type(value).__name__} {value!r}")


def check_choice(name: str, value: Any, choices: tuple[str, ...]) -> None:
    """ValueError unless ``value`` is one of ``choices``."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {choices}, got {value!r}")


def image_size(name: str, value: Any) -> tuple[int, int]:
    """``value`` as an image's ``(height, width)`` in pixels (ValueError unless two integers >= 1)."""
    ok = (isinstance(value, (tuple, list)) and len(value) == 2
          and all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) and n >= 1 for n in value))
    if not ok:
        raise ValueError(f"{name} must be two integers >= 1 (height, width), got {value!r}")
    return int(value[0]), int(value[1])


def record_of(cls: type[R], value: Any, argument: str, shorthand: str | None = None) -> R:
    """``value`` as a ``cls`` record (a frozen dataclass): the record itself, one built from its
    mapping form (field name -> value; a key that is no field is refused by name), or, with
    ``shorthand`` (a field's name), the record with that field set to ``value`` and the others
    at their defaults (``record_of(RewardConfig, "staged", ..., "kind")``). ``argument`` names
    where the value was given, for the errors."""
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        names = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(str(k) for k in value if k not in names)
        if unknown:
            raise ValueError(f"{argument}: {cls.__name__} has no field {unknown[0]!r} (its fields: {names})")
        return cls(**value)
    if shorthand is not None:
        return cls(**{shorthand: value})
    raise TypeError(f"{argument} must be a record {cls.__name__} or its mapping form, got {type(value).__name__} "
                    f"{value!r}")
