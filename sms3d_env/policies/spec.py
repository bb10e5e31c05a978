"""``PolicySpec``: what building a saved PPO/SAC model's policy needs, as plain data.

An SB3 ``model.zip`` stores its policy class, observation and action spaces, schedules and any
class named in ``policy_kwargs`` as cloudpickled entries of its ``data`` JSON; unpickling them
runs whatever code the file carries. :func:`~sms3d_env.policies.loader.load_sb3` unpickles none:
it hands SB3 these objects instead, rebuilt from a ``PolicySpec``, which names the algorithm and
the policy from fixed lists, gives the spaces as numbers, and names the classes of
``policy_kwargs`` by qualified name, mapped back through :func:`policy_kwarg_classes` only.
:func:`~sms3d_env.policies.files.save_model` writes it into every model zip it saves.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sms3d_env.policies.quoting import clipped

#: The algorithms a saved policy may be of.
ALGOS = ("ppo", "sac")

#: The SB3 policies a saved model may use (SB3's names, for PPO and for SAC alike): the dict
#: observation's and the flattened observation's.
POLICIES = ("MultiInputPolicy", "MlpPolicy")
#: ``policy_kwargs`` entries whose value is a class (stored by qualified name).
CLASS_KWARGS = ("features_extractor_class", "activation_fn", "optimizer_class")
#: Format of :meth:`PolicySpec.to_json`.
SPEC_FORMAT = 1


def qualified_name(cls: type) -> str:
    """``"package.module.Class"``: how a class is named in a spec."""
    return f"{cls.__module__}.{cls.__qualname__}"


def policy_kwarg_classes() -> dict[str, type]:
    """The classes a saved model's ``policy_kwargs`` may name, by qualified name: the ones this
    package's training passes (the shipped policies' features extractor, also by the name that
    models saved before it moved record). Any other name is refused, so loading imports nothing
    that a file names."""
    from sms3d_env.policies.features import NormalizedFlatten

    return {qualified_name(NormalizedFlatten): NormalizedFlatten,
            "sms3d_env.training.policy_features.NormalizedFlatten": NormalizedFlatten}


def package_env_ids() -> tuple[str, ...]:
    """The env ids this package registers (``sms3d_env/__init__.py``): the only ones a saved
    policy may name. An id read from a file goes nowhere else, since ``gym.make`` reads
    ``"module:Env"`` as "import module first": the file would choose what is imported."""
    from gymnasium.envs.registration import registry

    import sms3d_env  # noqa: F401  (registers the ids)

    return tuple(env_id for env_id, spec in registry.items()
                 if isinstance(spec.entry_point, str) and spec.entry_point.startswith("sms3d_env.pick_env:"))


#: SB3's ``data`` entry of a pickled space: ``:type:`` as SB3 writes it, by the kind of space.
PICKLED_SPACE_TYPES = {"<class 'gymnasium.spaces.dict.Dict'>": "Dict", "<class 'gymnasium.spaces.box.Box'>": "Box"}
#: The module of the policy class of a PPO and of a SAC model (``data["policy_class"]["__module__"]``).
POLICY_MODULES = {"stable_baselines3.common.policies": "ppo", "stable_baselines3.sac.policies": "sac"}


def space_signature(space: Any) -> tuple[Any, ...] | None:
    """What SB3's ``data`` says in readable text of a ``Box`` or a ``Dict`` of them beside its
    pickle (:func:`described_space_signature`), as the space itself gives it; ``None`` for others."""
    import gymnasium as gym

    if isinstance(space, gym.spaces.Dict):
        return ("Dict", str(space.spaces))
    if isinstance(space, gym.spaces.Box):
        return ("Box", str(space.dtype), tuple(space.shape), str(space.low), str(space.high))
    return None


def described_space_signature(entry: Any) -> tuple[Any, ...] | None:
    """The :func:`space_signature` of the space pickled in an SB3 ``data`` entry, from the text
    SB3 writes beside the pickle (a ``Dict``'s ``spaces`` as ``str``; a ``Box``'s dtype, shape and
    bounds), nothing unpickled; ``None`` when the entry is no such description."""
    if not isinstance(entry, dict):
        return None
    kind = PICKLED_SPACE_TYPES.get(entry.get(":type:"))
    if kind == "Dict" and isinstance(entry.get("spaces"), str):
        return ("Dict", entry["spaces"])
    shape = entry.get("_shape")
    if kind == "Box" and isinstance(shape, list) and all(isinstance(n, int) for n in shape):
        return ("Box", entry.get("dtype"), tuple(shape), entry.get("low"), entry.get("high"))
    return None


def described_algo(data: dict[str, Any]) -> str | None:
    """``"ppo"``/``"sac"`` as SB3's ``data`` names the module of its pickled policy class; ``None``
    when it names another."""
    entry = data.get("policy_class")
    return POLICY_MODULES.get(entry.get("__module__")) if isinstance(entry, dict) else None


def space_to_json(space: Any) -> dict[str, Any]:
    """A gymnasium ``Box`` or ``Dict`` of them as JSON data (keys in the space's order; bounds
    flattened in C order, infinities as JSON's ``Infinity``); ``ValueError`` for other spaces."""
    import gymnasium as gym

    if isinstance(space, gym.spaces.Dict):
        return {"type": "Dict", "spaces": [[k, space_to_json(s)] for k, s in space.spaces.items()]}
    if isinstance(space, gym.spaces.Box):
        return {"type": "Box", "shape": list(space.shape), "dtype": space.dtype.name,
                "low": space.low.ravel().tolist(), "high": space.high.ravel().tolist()}
    raise ValueError(f"{type(space).__name__} spaces are not supported (a Box, or a Dict of Boxes)")


def space_from_json(data: Any, field: str) -> Any:
    """The space :func:`space_to_json` described; ``ValueError`` naming ``field`` (and the entry
    within it) when ``data`` is not such a description."""
    import gymnasium as gym

    if not isinstance(data, dict):
        raise ValueError(f"{field}: not a space description")
    if data.get("type") == "Dict":
        pairs = data.get("spaces")
        if not isinstance(pairs, list) or not all(isinstance(p, list) and len(p) == 2 and isinstance(p[0], str)
                                                  for p in pairs):
            raise ValueError(f"{field}.spaces: must be a list of [key, space] pairs")
        if len({k for k, _ in pairs}) != len(pairs):
            raise ValueError(f"{field}.spaces: a key given twice")
        return gym.spaces.Dict([(k, space_from_json(s, f"{field}.spaces[{k!r}]")) for k, s in pairs])
    if data.get("type") != "Box":
        raise ValueError(f"{field}.type: must be 'Box' or 'Dict', got {data.get('type')!r}")
    shape = data.get("shape")
    if not isinstance(shape, list) or not all(isinstance(n, int) and n >= 0 for n in shape):
        raise ValueError(f"{field}.shape: must be a list of sizes, got {shape!r}")
    try:
        dtype = np.dtype(data["dtype"]) if isinstance(data.get("dtype"), str) else None
    except TypeError:
        dtype = None
    if dtype is None or dtype.kind not in "fiu":
        raise ValueError(f"{field}.dtype: must name a numeric dtype, got {data.get('dtype')!r}")
    bounds = {}
    for side in ("low", "high"):
        values = data.get(side)
        if not isinstance(values, list) or len(values) != int(np.prod(shape)) \
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
            raise ValueError(f"{field}.{side}: must be {int(np.prod(shape))} numbers")
        bounds[side] = np.array(values, dtype=dtype).reshape(shape)
    return gym.spaces.Box(bounds["low"], bounds["high"], dtype=dtype)


def policy_kwargs_to_json(kwargs: dict[str, Any]) -> dict[str, Any]:
    """``policy_kwargs`` as JSON data: the classes of :data:`CLASS_KWARGS` by qualified name;
    ``ValueError`` naming an entry that is neither."""
    import json

    out: dict[str, Any] = {}
    for key, value in kwargs.items():
        if key in CLASS_KWARGS:
            if not isinstance(value, type):
                raise ValueError(f"policy_kwargs[{key!r}] must be a class, got {value!r}")
            out[key] = qualified_name(value)
            continue
        try:
            json.dumps(value, allow_nan=False)
        except (TypeError, ValueError):
            raise ValueError(f"policy_kwargs[{key!r}] is not JSON data ({type(value).__name__}); only the classes "
                             f"of {CLASS_KWARGS} are stored by name") from None
        out[key] = value
    return out


def policy_kwargs_from_json(kwargs: Any) -> dict[str, Any]:
    """``policy_kwargs`` for SB3 from their JSON form: each class of :data:`CLASS_KWARGS` taken
    from :func:`policy_kwarg_classes` by name; ``ValueError`` naming an entry with another."""
    if not isinstance(kwargs, dict):
        raise ValueError(f"policy_kwargs: must be a mapping, got {type(kwargs).__name__}")
    allowed = policy_kwarg_classes()
    out = dict(kwargs)
    for key in CLASS_KWARGS:
        if key in out:
            if out[key] not in allowed:
                raise ValueError(f"policy_kwargs[{key!r}]: {out[key]!r} is none of the classes a saved policy may "
                                 f"name ({', '.join(sorted(allowed))})")
            out[key] = allowed[out[key]]
    return out


def algorithm_class(algo: str) -> Any:
    """SB3's ``PPO`` or ``SAC`` for ``"ppo"``/``"sac"``."""
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


def _trained_env_id(model: Any) -> str | None:
    """The package env id of the envs ``model`` trains in (``None`` without envs, or for another env)."""
    venv = model.get_env()
    try:
        env_id = getattr(venv.get_attr("spec", [0])[0], "id", None) if venv is not None else None
    except AttributeError:  # a VecEnv or env without a spec
        return None
    return env_id if env_id in package_env_ids() else None


@dataclass(frozen=True)
class PolicySpec:
    """What a saved model's policy is built from, instead of the entries SB3 pickled.

    Args:
        algo: ``"ppo"`` or ``"sac"``.
        policy: one of :data:`POLICIES`.
        observation_space: the observation the policy takes (a ``Dict`` of ``Box`` for
            ``MultiInputPolicy``, a ``Box`` for ``MlpPolicy``).
        action_space: a ``Box``.
        policy_kwargs: the policy's keyword arguments in JSON form (classes by qualified name);
            ``None``: the model file's own, which must then be plain JSON in its ``data``.
        env_id: the env it was trained on, one of :func:`package_env_ids`; ``None`` when not known.
    """

    algo: str
    policy: str
    observation_space: Any
    action_space: Any
    policy_kwargs: dict[str, Any] | None = None
    env_id: str | None = None

    def __post_init__(self) -> None:
        import gymnasium as gym

        if self.algo not in ALGOS:
            raise ValueError(f"algo: must be one of {ALGOS}, got {self.algo!r}")
        if self.policy not in POLICIES:
            raise ValueError(f"policy: must be one of {POLICIES}, got {self.policy!r}")
        wanted = gym.spaces.Dict if self.policy == "MultiInputPolicy" else gym.spaces.Box
        if not isinstance(self.observation_space, wanted):
            raise ValueError(f"observation_space: {self.policy} takes a {wanted.__name__} observation, got "
                             f"{type(self.observation_space).__name__}")
        if not isinstance(self.action_space, gym.spaces.Box):
            raise ValueError(f"action_space: must be a Box, got {type(self.action_space).__name__}")
        if self.env_id is not None and self.env_id not in package_env_ids():
            raise ValueError(f"env_id: {clipped(repr(self.env_id))} is none of this package's env ids ({', '.join(package_env_ids())})")

    @classmethod
    def of(cls, model: Any) -> PolicySpec:
        """The spec of an SB3 PPO/SAC model (``ValueError`` naming what it cannot describe)."""
        algo = next((a for a in ALGOS if isinstance(model, algorithm_class(a))), None)
        if algo is None:
            raise ValueError(f"a {type(model).__name__} model: only {', '.join(a.upper() for a in ALGOS)} are saved")
        aliases = type(model).policy_aliases
        policy = next((p for p in POLICIES if aliases.get(p) is model.policy_class), None)
        if policy is None:
            raise ValueError(f"policy class {qualified_name(model.policy_class)}: a saved policy is one of {POLICIES}")
        return cls(algo, policy, model.observation_space, model.action_space,
                   policy_kwargs_to_json(model.policy_kwargs), _trained_env_id(model))

    def to_json(self) -> dict[str, Any]:
        """The spec as JSON data (what :data:`~sms3d_env.policies.files.POLICY_SPEC_MEMBER` holds)."""
        if self.policy_kwargs is None:
            raise ValueError("policy_kwargs: a spec written to a file must hold them")
        return {"format": SPEC_FORMAT, "algo": self.algo, "policy": self.policy,
                "observation_space": space_to_json(self.observation_space),
                "action_space": space_to_json(self.action_space), "policy_kwargs": self.policy_kwargs,
                **({} if self.env_id is None else {"env_id": self.env_id})}

    @classmethod
    def from_json(cls, data: Any) -> PolicySpec:
        """What :meth:`to_json` wrote; ``ValueError`` naming the field that is not."""
        if not isinstance(data, dict) or data.get("format") != SPEC_FORMAT:
            raise ValueError(f"format: expected {SPEC_FORMAT}, got "
                             f"{data.get('format') if isinstance(data, dict) else type(data).__name__!r}")
        kwargs = data.get("policy_kwargs")
        if not isinstance(kwargs, dict):
            raise ValueError(f"policy_kwargs: must be a mapping, got {type(kwargs).__name__}")
        return cls(data.get("algo"), data.get("policy"),
                   space_from_json(data.get("observation_space"), "observation_space"),
                   space_from_json(data.get("action_space"), "action_space"), kwargs, data.get("env_id"))

    def policy_class(self) -> type:
        """SB3's class of :attr:`policy` for :attr:`algo`."""
        return algorithm_class(self.algo).policy_aliases[self.policy]
