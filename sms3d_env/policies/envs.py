"""The env a saved policy runs in (:func:`make_env`): one of this package's registered ids
(:func:`~sms3d_env.policies.spec.package_env_ids`), as the policy's own record names it (a
run's ``config.json``, an RL Zoo run's ``args.yml``, the model zip's ``sms3d_policy.json``), as the
user gives it (``--env-id``), or else found by matching the model's observation and action spaces
against those of each registered env (:func:`match_env`).

Why only the package's ids: ``gym.make`` reads an id ``"module:Env"`` as "import ``module``
first", so an id taken from a file as it stands would let the file choose what is imported.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from generator.errors import ConfigError
from sms3d_env.policies.files import PolicyFileError
from sms3d_env.policies.quoting import clipped
from sms3d_env.policies.spec import package_env_ids, space_signature


def make_env(env_id: str, flat_observation: bool = False, **kwargs: Any) -> Any:
    """``gym.make(env_id, **kwargs)`` with this package's ids registered; ``flat_observation``
    flattens the dict observation into one vector (gymnasium's ``FlattenObservation``,
    outermost). Module-level, so that ``SubprocVecEnv`` workers can unpickle it."""
    import gymnasium as gym

    import sms3d_env  # noqa: F401  (registers the env ids)

    env = gym.make(env_id, **kwargs)
    return gym.wrappers.FlattenObservation(env) if flat_observation else env


def checked_env_id(value: Any, path: Path, field: str) -> str:
    """``value``, an env id read from ``path``'s ``field``, when it is one of this package's;
    ``PolicyFileError`` naming the file and field otherwise (before anything would import it)."""
    ids = package_env_ids()
    if not (isinstance(value, str) and value in ids):
        raise PolicyFileError(path, f"{field}: {clipped(repr(value))} is none of this package's env ids "
                                    f"({', '.join(ids)}); an env a file names is made from these only")
    return value


def chosen_env_id(given: str | None, recorded: str | None, record: Path | None) -> str | None:
    """The env a policy runs in: ``given`` (the caller's ``env_id``) or else ``recorded`` (what the
    policy's file ``record`` names); ``None`` when neither says. ``ConfigError`` naming
    ``env_id`` when ``given`` is none of this package's ids or differs from ``recorded``."""
    if given is not None:
        if given not in package_env_ids():
            raise ConfigError("env_id", f"must be one of {', '.join(package_env_ids())}, got {clipped(repr(given))}")
        if recorded is not None and given != recorded:
            raise ConfigError("env_id", f"{given} differs from {recorded}, the env that {record} says the policy "
                                        f"was trained on; leave it out, or give {recorded}")
    return given or recorded


def env_spaces(env_id: str, env_options: dict[str, Any] | None = None) -> tuple[Any, Any]:
    """``env_id``'s observation space (a ``Dict``, keys in the order ``FlattenObservation``
    concatenates them) and action space, with ``env_options``."""
    env = make_env(env_id, **(env_options or {}))
    try:
        return env.observation_space, env.action_space
    finally:
        env.close()


@dataclass(frozen=True)
class EnvMatch:
    """A registered env whose spaces are a model's: the policy's observation space (the env's
    dict observation, or it flattened) and action space, and for a flattened one the env's keys
    in their flattening order (``observation_keys``)."""

    env_id: str
    observation_space: Any
    action_space: Any
    observation_keys: list[str] | None


def match_env(path: Path, signatures: tuple[Any, Any], candidates: tuple[str, ...]) -> EnvMatch:
    """The one env of ``candidates`` (each made once, with its default options) whose observation
    (as it is, or flattened) and action spaces have a model's ``signatures``
    (:func:`~sms3d_env.policies.spec.space_signature` of both); of several versions of one
    env, the latest. ``PolicyFileError`` naming the model ``path`` and the candidates when none
    do, or several envs."""
    import warnings

    import gymnasium as gym
    from gymnasium.envs.registration import parse_env_id

    matches = []
    for env_id in candidates:
        with warnings.catch_warnings():  # gymnasium's "out of date" for a -v1 id: made to compare, not chosen
            warnings.simplefilter("ignore", DeprecationWarning)
            observation, action = env_spaces(env_id)
        for space, keys in ((observation, None), (gym.spaces.flatten_space(observation), list(observation.spaces))):
            if (space_signature(space), space_signature(action)) == signatures:
                matches.append(EnvMatch(env_id, space, action, keys))
    # Versions of one env (SMS3DPickTrain-v1 and -v2 share their spaces): the latest, which
    # supersedes the others (sms3d_env's docstring).
    versions = {parse_env_id(m.env_id)[:2]: m for m in matches}
    if len(versions) == 1:
        return max(matches, key=lambda m: parse_env_id(m.env_id)[2] or 0)
    hint = "name its env with --env-id (PolicyActor's env_id)"
    if matches:
        raise PolicyFileError(path, f"its observation and action spaces are those of "
                                    f"{', '.join(m.env_id for m in matches)}; {hint}")
    if len(candidates) == 1:
        raise PolicyFileError(path, f"its observation and action spaces are not those of {candidates[0]} "
                                    "(with its default options)")
    raise PolicyFileError(path, f"its observation and action spaces are those of none of this package's envs "
                                f"({', '.join(candidates)}, with their default options); {hint}")
