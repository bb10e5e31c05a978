"""Runs that RL Baselines3 Zoo (``python -m rl_zoo3.train``, and so ``sms3d train-policy`` on an
RL recipe) saved, read without running code from their files: a model of such a run loads as a
picker (:func:`zoo_run_of`, used by :class:`~sms3d_env.pickers.policy.PolicyActor`).

A zoo run folder (``logs/ppo/SMS3DPickTrain-v2_1/``) holds the model (``SMS3DPickTrain-v2.zip``,
``best_model.zip``, ``rl_model_<N>_steps.zip``) and a folder named after the env with
``args.yml`` (the command's arguments), ``config.yml`` (the hyperparameters) and, for a
normalised run, ``vecnormalize.pkl``. The YAML files carry one Python tag (an ``OrderedDict``),
read as a plain mapping; every other tag is refused. ``vecnormalize.pkl`` is a pickle of SB3's
``VecNormalize``: it is decoded by a restricted reader (:func:`read_vecnormalize`) that imports
and calls no class or function named in the file besides numpy's array and dtype constructors;
every other object becomes an inert record of its state, from which the running means and
variances are taken. The model zip's pickled entries are not unpickled either: its policy is
built from the run's algorithm and policy name, the spaces of the env it names and the zip's
readable ``policy_kwargs`` (:meth:`ZooRun.policy_spec`, loaded by
:func:`~sms3d_env.policies.loader.load_sb3`).
"""
from __future__ import annotations

import io
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from generator.config_file import read_exponent_floats
from sms3d_env.env_args import translate_legacy_options
from sms3d_env.policies.envs import checked_env_id, env_spaces
from sms3d_env.policies.files import (
    MAX_STATS_BYTES,
    ObservationStats,
    PolicyFileError,
    RunningStats,
    check_file_size,
    read_run_text,
)
from sms3d_env.policies.quoting import described_error
from sms3d_env.policies.spec import PolicySpec

#: The one env wrapper a zoo run's policy may have been trained in: the flattened observation.
FLATTEN_WRAPPER = "gymnasium.wrappers.FlattenObservation"
#: ``env_kwargs`` entries a policy was trained with but need not run with: the training beds, the
#: start curriculum and the pose source (the evaluation chooses its own).
TRAINING_ONLY_ENV_KWARGS = ("scene", "start", "pose_source", "pose_error_deg", "render_mode")


#: RL Zoo's one Python tag: its ``yaml.dump`` of an ``OrderedDict`` (``config.yml``, ``args.yml``).
ORDERED_DICT_TAG = "tag:yaml.org,2002:python/object/apply:collections.OrderedDict"


#: The most nodes an RL Zoo YAML file may expand to, each alias counted as what it repeats (a
#: recipe or an RL Zoo run's ``config.yml``/``args.yml`` has a few hundred): nested aliases of a
#: small file otherwise expand to gigabytes wherever the value is used or quoted.
MAX_YAML_NODES = 10_000


def _expands_within(root: Any, limit: int) -> bool:
    """Whether the YAML node ``root``, its aliases expanded, has at most ``limit`` nodes (counted
    without expanding more than ``limit``: a file's aliases may nest or refer to themselves)."""
    import yaml

    stack, seen = [root], 0
    while stack:
        node = stack.pop()
        seen += 1
        if seen > limit:
            return False
        if isinstance(node, yaml.SequenceNode):
            stack.extend(node.value)
        elif isinstance(node, yaml.MappingNode):
            stack.extend(n for pair in node.value for n in pair)
    return True


def _safe_zoo_yaml(text: str) -> Any:
    """YAML as ``yaml.safe_load`` reads it, plus :data:`ORDERED_DICT_TAG` read as a plain mapping
    (its ``[[key, value], ...]`` argument) and exponent-notation numbers read as floats (a run's
    ``config.json`` writes rates so; :data:`generator.config_file.EXPONENT_FLOAT`); any other
    Python tag stays refused. ``ValueError`` saying why for a document that expands past
    :data:`MAX_YAML_NODES` or nests deeper than Python's recursion limit."""
    import yaml

    class Loader(yaml.SafeLoader):
        def construct_document(self, node: Any) -> Any:
            if not _expands_within(node, MAX_YAML_NODES):
                raise ValueError(f"expands to more than {MAX_YAML_NODES} values (aliases counted as what they "
                                 "repeat)")
            return super().construct_document(node)

    read_exponent_floats(Loader)

    def ordered_dict(loader: Any, node: Any) -> dict[str, Any]:
        (pairs,) = loader.construct_sequence(node, deep=True)
        return dict(pairs)

    Loader.add_constructor(ORDERED_DICT_TAG, ordered_dict)
    try:
        return yaml.load(text, Loader=Loader)  # noqa: S506  (a SafeLoader with one data-only constructor)
    except RecursionError:
        raise ValueError("nested deeper than Python's recursion limit") from None


def zoo_yaml_or_why(path: Path) -> tuple[dict[str, Any] | None, str]:
    """An RL Zoo YAML file as a mapping and ``""``, or ``None`` and why it is not one (larger than
    :data:`~sms3d_env.policies.files.MAX_RUN_FILE_BYTES`, unreadable, not YAML of a mapping)."""
    import yaml

    try:
        data = _safe_zoo_yaml(read_run_text(Path(path), "RL Zoo YAML file"))
    except PolicyFileError as exc:
        return None, exc.message
    except (yaml.YAMLError, TypeError, ValueError) as exc:
        return None, f"not readable RL Zoo YAML ({described_error(exc)})"
    if not isinstance(data, dict):
        return None, "not a mapping of settings"
    return data, ""


def read_run_yaml(path: Path) -> dict[str, Any]:
    """An RL Zoo run's ``args.yml`` or ``config.yml`` as a mapping; ``PolicyFileError`` naming
    the file when it is not readable YAML of a mapping (:func:`zoo_yaml_or_why`)."""
    data, why = zoo_yaml_or_why(path)
    if data is None:
        raise PolicyFileError(path, why)
    return data



class _Inert:
    """An object the restricted reader does not build: the global's name, its constructor's
    arguments, its pickled state and, for a container, its items and elements, kept as data."""

    global_name = ""

    # __new__, not __init__: pickle's NEWOBJ makes an object by its class's __new__ alone.
    def __new__(cls, *args: Any, **kwargs: Any) -> _Inert:
        self = super().__new__(cls)
        self.args, self.kwargs, self.state = args, kwargs, None
        self.items: dict[Any, Any] = {}
        self.elements: list[Any] = []
        return self

    def __setstate__(self, state: Any) -> None:
        self.state = state

    # A pickled container (an OrderedDict, a gymnasium Dict space's mapping) gets its items so;
    # kept as data like the rest.
    def __setitem__(self, key: Any, value: Any) -> None:
        self.items[key] = value

    def append(self, value: Any) -> None:
        self.elements.append(value)

    def extend(self, values: Any) -> None:
        self.elements.extend(values)


def _array_globals() -> dict[tuple[str, str], Any]:
    """numpy's constructors of arrays, scalars and dtypes: what a pickled array needs, and data only."""
    from numpy._core import multiarray, numeric

    found = {("numpy", "ndarray"): np.ndarray, ("numpy", "dtype"): np.dtype}
    for module in ("numpy._core.multiarray", "numpy.core.multiarray"):
        found[(module, "_reconstruct")] = multiarray._reconstruct
        found[(module, "scalar")] = multiarray.scalar
    for module in ("numpy._core.numeric", "numpy.core.numeric"):
        found[(module, "_frombuffer")] = numeric._frombuffer
    return found


class _RestrictedUnpickler(pickle.Unpickler):
    ARRAYS = _array_globals()

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) in self.ARRAYS:
            return self.ARRAYS[(module, name)]
        return type(name, (_Inert,), {"global_name": f"{module}.{name}"})

    def persistent_load(self, pid: Any) -> Any:
        raise pickle.UnpicklingError("persistent ids are not supported")


def _running_stats(value: Any, path: Path, what: str) -> RunningStats:
    state = getattr(value, "state", None)
    if getattr(value, "global_name", "") != "stable_baselines3.common.running_mean_std.RunningMeanStd" \
            or not isinstance(state, dict):
        raise PolicyFileError(path, f"{what} is not SB3's RunningMeanStd")
    mean, var = np.asarray(state.get("mean"), np.float64), np.asarray(state.get("var"), np.float64)
    if mean.shape != var.shape or not (np.all(np.isfinite(mean)) and np.all(np.isfinite(var))):
        raise PolicyFileError(path, f"{what}: mean and variance of different shapes or not finite")
    return RunningStats(mean, var, float(state.get("count")))


def read_vecnormalize(path: str | Path) -> ObservationStats | None:
    """The observation statistics in SB3's ``vecnormalize.pkl``, decoded by the restricted reader
    (nothing named in the file is imported or called but numpy's array constructors); ``None``
    when the wrapper did not normalise observations. ``PolicyFileError`` naming the file when it
    is not a pickled ``VecNormalize``."""
    path = Path(path)
    try:
        check_file_size(path, MAX_STATS_BYTES, "VecNormalize statistics")
        root = _RestrictedUnpickler(io.BytesIO(path.read_bytes())).load()
    except PolicyFileError:
        raise
    except (OSError, pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError, IndexError,
            KeyError) as exc:
        raise PolicyFileError(path, f"not readable VecNormalize statistics ({described_error(exc)})") from None
    state = getattr(root, "state", None)
    if getattr(root, "global_name", "") != "stable_baselines3.common.vec_env.vec_normalize.VecNormalize" \
            or not isinstance(state, dict):
        raise PolicyFileError(path, "not a pickled SB3 VecNormalize")
    if not state.get("norm_obs", True):
        return None
    rms = state.get("obs_rms")
    obs = ({k: _running_stats(v, path, f"obs_rms[{k!r}]") for k, v in rms.items()} if isinstance(rms, dict)
           else {None: _running_stats(rms, path, "obs_rms")})
    returns = _running_stats(state["ret_rms"], path, "ret_rms") if state.get("ret_rms") is not None else None
    return ObservationStats(obs, float(state.get("clip_obs", 10.0)), float(state.get("epsilon", 1e-8)),
                            bool(state.get("norm_reward", False)), returns, float(state.get("clip_reward", 10.0)),
                            float(state.get("gamma", 0.99)))


@dataclass(frozen=True)
class ZooRun:
    """The files of the rl_zoo3 run a model belongs to: its ``args.yml``/``config.yml`` folder
    (``params``) and, for a normalised run, ``vecnormalize.pkl`` in it."""

    params: Path

    @property
    def stats_path(self) -> Path:
        return self.params / "vecnormalize.pkl"

    def saved_config(self) -> dict[str, Any]:
        """What a run's ``config.json`` says, from the zoo's files: ``algo``, ``env_id``,
        ``env_options`` (the env keyword arguments a policy must run with), ``num_mushrooms``,
        ``normalize``, ``flat_observation`` and ``observation_keys`` (``PolicyFileError`` naming
        a file that does not say them, or a wrapper other than ``FlattenObservation``)."""
        args, hyper = (read_run_yaml(self.params / name) for name in ("args.yml", "config.yml"))
        env_id, algo = args.get("env"), args.get("algo")
        if env_id is None or not isinstance(algo, str):
            raise PolicyFileError(self.params / "args.yml", "names no env and algo: not an rl_zoo3 run's")
        checked_env_id(env_id, self.params / "args.yml", "env")
        wrappers = hyper.get("env_wrapper") or []
        wrappers = wrappers if isinstance(wrappers, list) else [wrappers]
        if any(w != FLATTEN_WRAPPER for w in wrappers):
            raise PolicyFileError(self.params / "config.yml", f"env_wrapper {wrappers}: the one wrapper a saved "
                                                             f"policy can run in here is {FLATTEN_WRAPPER}")
        env_kwargs = translate_legacy_options(args.get("env_kwargs") or hyper.get("env_kwargs") or {})
        scene = env_kwargs.get("scene") or {}
        placement = ((scene.get("config") if "config" in scene else scene) or {}).get("placement") or {}
        saved: dict[str, Any] = {
            "recipe": "rl_zoo3", "algo": algo, "env_id": env_id,
            "env_options": {k: v for k, v in env_kwargs.items() if k not in TRAINING_ONLY_ENV_KWARGS},
            "normalize": self.stats_path.is_file(), "flat_observation": bool(wrappers)}
        if isinstance(placement.get("num_mushrooms"), int):
            saved["num_mushrooms"] = placement["num_mushrooms"]
        if wrappers:
            saved["observation_keys"] = list(env_spaces(env_id, saved["env_options"])[0].spaces)
        return saved

    def policy_spec(self, saved: dict[str, Any]) -> PolicySpec:
        """What the run's model is loaded with instead of its pickled entries: the algorithm of
        ``saved`` (:meth:`saved_config`), the policy named in ``config.yml``, and the observation
        (flattened as ``FlattenObservation`` flattens it, for a flat run) and action spaces of
        the env it names; its ``policy_kwargs`` are the model zip's readable ones.
        ``PolicyFileError`` naming ``config.yml`` when these do not make a policy spec."""
        import gymnasium as gym

        config = self.params / "config.yml"
        observation, action = env_spaces(saved["env_id"], saved["env_options"])
        if saved["flat_observation"]:
            observation = gym.spaces.flatten_space(observation)
        try:
            return PolicySpec(saved["algo"], read_run_yaml(config).get("policy"), observation, action)
        except ValueError as exc:
            raise PolicyFileError(config, f"not a policy this package loads ({exc})") from None


def zoo_run_of(model_path: str | Path) -> ZooRun | None:
    """The rl_zoo3 run of ``model_path`` (its final ``<ENV>.zip``, ``best_model.zip`` or a
    ``rl_model_<N>_steps.zip`` checkpoint): the folder beside it that holds ``args.yml`` and
    ``config.yml``, the one named after the model's stem first; ``None`` when there is none.
    As rl_zoo3's own ``enjoy``, every model of a run uses the run's one ``vecnormalize.pkl``."""
    path = Path(model_path)
    named = path.parent / path.stem
    if (named / "args.yml").is_file():
        folders = [named]
    elif path.parent.is_dir():
        folders = sorted(d for d in path.parent.iterdir() if (d / "args.yml").is_file())
    else:
        return None
    folders = [d for d in folders if (d / "config.yml").is_file()]
    return ZooRun(folders[0]) if len(folders) == 1 else None

