"""The policy picker: a saved SB3 model acting as ``actor(obs) -> action`` in the env it was
trained on (:class:`PolicyActor`), loaded through :mod:`sms3d_env.policies` without running code
from its files."""

from __future__ import annotations

import inspect
from pathlib import Path
from typing import Any

import numpy as np

from sms3d_env.env_args import translate_legacy_options
from sms3d_env.policies.envs import checked_env_id, chosen_env_id, make_env, match_env
from sms3d_env.policies.files import OBS_STATS_FILE, ObservationStats, PolicyFileError
from sms3d_env.policies.loader import (
    ModelZip,
    load_model,
    observation_stats_path,
    read_model_zip,
    read_saved_config,
    saved_config_path,
)
from sms3d_env.policies.spec import (
    PolicySpec,
    described_algo,
    described_space_signature,
    package_env_ids,
    space_signature,
)
from sms3d_env.policies.zoo_runs import read_vecnormalize, zoo_run_of


def _plain(value: Any) -> Any:
    """An env option in a comparable form: a record as its fields, tuples as lists, numbers as
    floats (so ``(10, 30)`` and ``[10.0, 30.0]``, a record and its mapping form compare equal)."""
    import dataclasses

    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = dataclasses.asdict(value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, (int, float, np.number)) and not isinstance(value, bool):
        return float(value)
    return value


class PolicyActor:
    """A saved SB3 model as ``actor(obs) -> action``, its observation statistics applied when they
    were saved with it (:func:`observation_stats_path`). ``env_id``/``env_options``: what it was
    trained on: the env its record names (:func:`saved_config_path`, else an rl_zoo3 run's files
    (:func:`~sms3d_env.policies.zoo_runs.zoo_run_of`), else the zip's policy description), else the
    ``env_id`` given, else the one registered env whose spaces are the model's
    (:func:`~sms3d_env.policies.envs.match_env`); options only from a record. A model
    saved by SB3's own ``save`` (no record, no description) runs too: its policy is built for the
    spaces of that env (:meth:`_matched_spec`).

    Files that cannot be used raise ``PolicyFileError`` naming them, here or, for a
    ``config.json`` whose env does not give the observation the policy was trained on, in
    :meth:`make_env` (before any step); an ``env_id`` that is none of the package's or differs
    from the record, ``ConfigError`` naming ``env_id``. Loading runs no code from the files
    (:func:`load_sb3`; an env a file names is one of the package's registered ids)."""

    def __init__(self, model_path: str | Path, algo: str | None = None, deterministic: bool = True,
                 env_id: str | None = None) -> None:
        path = Path(model_path)
        if not path.is_file():
            raise FileNotFoundError(f"model not found: {path}")
        self.path, self.deterministic = path, deterministic
        self.config_path = saved_config_path(path)
        zoo_run = zoo_run_of(path) if self.config_path is None else None
        self.saved: dict[str, Any] = (read_saved_config(self.config_path) if self.config_path is not None
                                      else zoo_run.saved_config() if zoo_run is not None else {})
        recorded = self.saved.get("env_id")
        record = self.config_path if zoo_run is None else zoo_run.params / "args.yml"
        if recorded is not None:  # an rl_zoo3 run's was checked as args.yml's env
            checked_env_id(recorded, record, "env_id")
        # Options saved by earlier versions (e.g. a top-level posture_target) read as now.
        self.env_options = translate_legacy_options(self.saved.get("env_options", {}))
        self._check_option_names()
        if self.saved.get("residual_scale"):
            raise PolicyFileError(self.config_path, "a residual policy, whose actions corrected the scripted "
                                                    "picker's; residual PPO was removed in 0.2.0 (CHANGELOG.md)")
        # A policy trained on the flattened observation: the keys in their concatenation order.
        self.observation_keys: list[str] | None = self.saved.get("observation_keys")
        if self.saved.get("flat_observation") and self.observation_keys is None:
            raise PolicyFileError(self.config_path, "flat_observation is set but observation_keys (the flattening "
                                                    "order) is missing; retrain, or add the keys of the env's "
                                                    "observation space")
        algo = algo or self.saved.get("algo")
        if zoo_run is not None:
            spec = zoo_run.policy_spec(self.saved)
            self.env_id = chosen_env_id(env_id, recorded, record)
        else:
            model_zip = read_model_zip(path)
            spec = model_zip.spec
            if recorded is None and spec is not None and spec.env_id is not None:
                recorded, record = spec.env_id, path
            self.env_id = chosen_env_id(env_id, recorded, record)
            if self.env_id is None or (spec is None and self.config_path is None):
                spec = self._matched_spec(model_zip, algo)
        self.model = load_model(path, algo, spec)
        stats = observation_stats_path(path)
        if stats is not None:
            self.obs_stats = ObservationStats.load(stats)
        elif zoo_run is not None and self.saved["normalize"]:
            stats, self.obs_stats = zoo_run.stats_path, read_vecnormalize(zoo_run.stats_path)
        else:
            self.obs_stats = None
        if self.obs_stats is not None:
            self.obs_stats.check_usable(stats, self.model.observation_space)
        elif self.saved.get("normalize"):
            raise PolicyFileError(path, f"was trained on normalised observations, but no {OBS_STATS_FILE} "
                                        "(or its checkpoint's) lies beside it")

    def _matched_spec(self, model_zip: ModelZip, algo: str | None) -> PolicySpec:
        """The policy of a model whose env no record names, or that holds no description of its
        policy, and :attr:`env_id` set to its env: the registered env (:attr:`env_id` when
        given) whose spaces are the model's (its description's, else those its SB3 ``data``
        gives in readable text beside their pickles). Without a description, the policy is built
        for those spaces: ``MultiInputPolicy`` for a dict observation, else ``MlpPolicy``; of
        ``algo`` or else the algorithm whose policy class the data names; its ``policy_kwargs``
        the data's own, which must be plain JSON (:func:`_trusted_entries`)."""
        import gymnasium as gym

        spec, data = model_zip.spec, model_zip.data
        if spec is not None:
            signatures = (space_signature(spec.observation_space), space_signature(spec.action_space))
        else:
            signatures = (described_space_signature(data.get("observation_space")),
                          described_space_signature(data.get("action_space")))
            if None in signatures:
                raise PolicyFileError(self.path, "its data describes no Box or Dict observation space and Box action "
                                                 "space (in the text SB3 writes beside their pickles)")
        match = match_env(self.path, signatures, (self.env_id,) if self.env_id else package_env_ids())
        self.env_id = match.env_id
        self.observation_keys = self.observation_keys or match.observation_keys
        if spec is not None:
            return spec
        algo = algo or described_algo(data)
        if algo is None:
            raise PolicyFileError(self.path, "its data names the policy class of neither PPO nor SAC "
                                             "(policy_class.__module__); give the algorithm")
        policy = "MultiInputPolicy" if isinstance(match.observation_space, gym.spaces.Dict) else "MlpPolicy"
        return PolicySpec(algo, policy, match.observation_space, match.action_space, env_id=match.env_id)

    def make_env(self, **kwargs: Any) -> Any:
        """The env this policy runs in: its env id and options, with ``kwargs`` (bed size, pose
        source, ...) for the rest. Its observation is the dict one even for a policy trained on the
        flattened observation (``__call__`` flattens it). ``PolicyFileError`` naming
        ``config.json`` when that env's observation is not the one the policy was trained on."""
        self._check_no_conflict(kwargs)
        env = make_env(self.env_id, **{**kwargs, **self.env_options})
        try:
            self._check_observation(env.observation_space)
        except PolicyFileError:
            env.close()
            raise
        return env

    def _check_option_names(self) -> None:
        """Saved env options are arguments of the env, nothing else ``gym.make`` takes (a
        ``max_episode_steps`` there would cut every episode the caller runs)."""
        from sms3d_env.pick_env import SMS3DPickEnv

        arguments = set(inspect.signature(SMS3DPickEnv.__init__).parameters) - {"self", "render_mode"}
        unknown = sorted(set(self.env_options) - arguments)
        if unknown:
            raise PolicyFileError(self.config_path or self.path,
                                  f"env_options: {', '.join(map(repr, unknown))} are no arguments of the env "
                                  f"({', '.join(sorted(arguments))})")

    def _check_no_conflict(self, kwargs: dict[str, Any]) -> None:
        """The options the policy was trained with win over ``kwargs``; one that says otherwise
        is refused by name (applying either would run another env than the caller reports)."""
        conflicts = [f"{name}={_plain(kwargs[name])!r} (trained with {_plain(saved)!r})"
                     for name, saved in self.env_options.items()
                     if name in kwargs and _plain(kwargs[name]) != _plain(saved)]
        if conflicts:
            where = self.config_path or self.path
            raise PolicyFileError(where, f"the policy was trained with env options that the command contradicts: "
                                         f"{'; '.join(conflicts)}; leave those out or set them as trained")

    def _check_observation(self, space: Any) -> None:
        """``space`` (the env's dict observation) has the keys and sizes the policy was trained on."""
        env_sizes = {k: int(np.prod(s.shape)) for k, s in space.spaces.items()}
        trained = self.model.observation_space
        if self.observation_keys is not None:
            keys, size = list(self.observation_keys), int(np.prod(trained.shape))
            wrong = [] if sum(env_sizes.get(k, 0) for k in keys) == size else [f"{size} flattened entries"]
        else:
            keys = list(trained.spaces)
            wrong = [f"{k} ({int(np.prod(s.shape))} entries, the env's {env_sizes[k]})"
                     for k, s in trained.spaces.items() if k in env_sizes and env_sizes[k] != int(np.prod(s.shape))]
        missing, extra = sorted(set(keys) - set(env_sizes)), sorted(set(env_sizes) - set(keys))
        if missing or extra or wrong:
            where = self.config_path or f"{self.path} (no config.json beside it)"
            raise PolicyFileError(where, f"describes an env ({self.env_id}, options {self.env_options}) whose "
                                         f"observation does not fit the policy {self.path}: missing keys {missing}, "
                                         f"extra keys {extra}" + (f", other sizes: {', '.join(wrong)}" if wrong else "")
                                  + "; a config.json from another run?")

    def __call__(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        if self.observation_keys is not None:  # as gymnasium's FlattenObservation did in training
            obs = np.concatenate([np.ravel(obs[k]) for k in self.observation_keys])
        if self.obs_stats is not None:
            obs = self.obs_stats.normalize_obs(obs)
        action, _ = self.model.predict(obs, deterministic=self.deterministic)
        return action
