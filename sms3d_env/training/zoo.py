"""RL Baselines3 Zoo (``rl_zoo3``) and this package: the shipped RL recipes are RL Zoo
hyperparameter files (``sms3d_env/recipes/<name>.yml``) that ``sms3d train-policy RECIPE``
reads too (:func:`recipe_fields`), and a model that ``python -m rl_zoo3.train`` saved runs as a
picker (:func:`zoo_run_of`, used by :class:`~sms3d_env.training.actor.PolicyActor`).

A zoo run folder (``logs/ppo/SMS3DPickTrain-v1_1/``) holds the model (``SMS3DPickTrain-v1.zip``,
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
:func:`~sms3d_env.training.actor.load_sb3`). No code from a zoo run's files runs here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from generator.config_file import shipped_or_file
from sms3d_env.env_args import translate_legacy_options
from sms3d_env.policies.zoo_runs import FLATTEN_WRAPPER, zoo_yaml_or_why

#: The shipped recipes: ``sms3d_env/recipes/<name>.yml``.
RECIPES_DIR = Path(__file__).parents[1] / "recipes"
#: Callbacks a recipe may name (RL Zoo's ``callback:``), each for a ``TrainConfig`` setting.
PREGRASP_ANNEALING = "sms3d_env.training.curriculum.pregrasp_annealing"
FALLING_LEARNING_RATE = "sms3d_env.training.schedules.falling_learning_rate"
WALL_CLOCK_LIMIT = "sms3d_env.training.rl.wall_clock_limit"
#: Recipe keys that are ``TrainConfig`` fields of the same name.
SAME_NAME_KEYS = ("n_envs", "n_steps", "batch_size", "gamma", "learning_rate", "target_kl", "buffer_size",
                  "learning_starts")
#: ``env_kwargs`` entries that are ``TrainConfig`` fields of the same name.
SAME_NAME_ENV_KWARGS = ("pose_source", "reward_type")

class RecipeError(ValueError):
    """A recipe file that ``sms3d train-policy`` cannot follow; the message names the file and key."""


def recipe_path(name_or_path: str | Path) -> Path:
    """A shipped recipe by name (``"ppo"``: ``sms3d_env/recipes/ppo.yml``) or a recipe file's path
    (``FileNotFoundError`` naming it when there is neither)."""
    return shipped_or_file(name_or_path, RECIPES_DIR)


def read_zoo_yaml(path: Path) -> dict[str, Any]:
    """An RL Zoo YAML file (a recipe, ``config.yml``, ``args.yml``) as a mapping; ``RecipeError``
    naming the file when it is not readable YAML of a mapping (:func:`~sms3d_env.policies.zoo_runs.zoo_yaml_or_why`)."""
    data, why = zoo_yaml_or_why(path)
    if data is None:
        raise RecipeError(f"{path}: {why}")
    return data


def _callbacks(path: Path, value: Any) -> dict[str, dict[str, Any]]:
    """A recipe's ``callback:`` (one name, or a list of names or ``{name: kwargs}``) by name."""
    items = value if isinstance(value, list) else [value]
    out: dict[str, dict[str, Any]] = {}
    for item in items:
        name, kwargs = (next(iter(item.items())) if isinstance(item, dict) and len(item) == 1 else (item, {}))
        if not isinstance(name, str) or not isinstance(kwargs, dict):
            raise RecipeError(f"{path}: callback: each entry must be a name or {{name: {{keyword: value}}}}, got {item!r}")
        out[name] = kwargs
    return out


def _scene_fields(scene: Any, bad: Any) -> dict[str, Any]:
    """The ``TrainConfig`` fields of a recipe's ``env_kwargs.scene``: ``{"placement":
    {"num_mushrooms": N}}`` (a ``SceneConfig``'s mapping form) or ``{"config": that, "pool": P}``
    (a ``SceneSourceConfig``'s); ``bad(key, why)`` makes the error for anything else."""
    source = scene if isinstance(scene, dict) and set(scene) & {"config", "pool"} else {"config": scene}
    config = source.get("config")
    placement = config.get("placement") if isinstance(config, dict) and set(config) == {"placement"} else None
    if set(source) - {"config", "pool"} or not (isinstance(placement, dict) and set(placement) == {"num_mushrooms"}):
        raise bad("env_kwargs.scene", f"TrainConfig sets config.placement.num_mushrooms and pool only, got {scene!r}")
    return {"num_mushrooms": placement["num_mushrooms"], **({"scene_pool": source["pool"]} if "pool" in source else {})}


def recipe_fields(path: Path, env_id: str | None = None) -> tuple[str, dict[str, Any]]:
    """``(env_id, fields)``: the ``TrainConfig`` fields that the recipe file's entry for ``env_id``
    (``None``: its only entry) sets. Every key must be one that maps onto a field, read the same
    way RL Zoo reads it (``n_timesteps`` is ``total_steps``, ``normalize`` a mapping of
    ``norm_obs``/``norm_reward``, ``env_kwargs.scene`` is ``num_mushrooms`` (its
    ``config.placement.num_mushrooms``) and ``scene_pool`` (its ``pool``), ``env_kwargs.start.share``
    is ``pregrasp_start``, ``env_kwargs.controller.posture_target`` is ``posture_target``,
    ``env_kwargs.pose_error_deg`` a (low, high) pair is ``pose_error_range_deg``, the three
    callbacks of this package are ``pregrasp_anneal``, ``learning_rate_final`` (+
    ``learning_rate_by_wall``) and ``max_wall_s``); anything else is a ``RecipeError`` naming the
    file and the key. Env arguments of earlier versions (``scene_config``, ``scene_pool``,
    ``pregrasp_start``, ...) are read as :func:`~sms3d_env.env_args.translate_legacy_options`
    reads them."""
    data = read_zoo_yaml(path)
    if env_id is None:
        if len(data) != 1:
            raise RecipeError(f"{path}: holds entries for {sorted(data)}; name one with --env-id")
        env_id = next(iter(data))
    if env_id not in data or not isinstance(data[env_id], dict):
        raise RecipeError(f"{path}: no entry for {env_id} (entries: {sorted(data)})")
    entry = dict(data[env_id])
    out: dict[str, Any] = {"env_id": env_id}

    def bad(key: str, why: str) -> RecipeError:
        return RecipeError(f"{path}: {env_id}.{key}: {why}")

    for key in SAME_NAME_KEYS:
        if key in entry:
            value = entry.pop(key)
            if key == "learning_rate" and not isinstance(value, (int, float)):
                raise bad(key, f"must be a number, got {value!r} (RL Zoo's lin_ rates fall to 0; a rate that "
                               f"falls to another value is the callback {FALLING_LEARNING_RATE})")
            out[key] = value
    if "n_timesteps" in entry:
        out["total_steps"] = int(float(entry.pop("n_timesteps")))
    wrappers = entry.pop("env_wrapper", None)
    wrappers = [] if wrappers is None else wrappers if isinstance(wrappers, list) else [wrappers]
    if any(w != FLATTEN_WRAPPER for w in wrappers):
        raise bad("env_wrapper", f"the one wrapper supported is {FLATTEN_WRAPPER}, got {wrappers}")
    out["flat_observation"] = bool(wrappers)
    policy = entry.pop("policy", "MlpPolicy" if wrappers else "MultiInputPolicy")
    if policy != ("MlpPolicy" if wrappers else "MultiInputPolicy"):
        raise bad("policy", f"must be MlpPolicy with {FLATTEN_WRAPPER}, MultiInputPolicy without, got {policy!r}")
    if "normalize" in entry:
        norm = entry.pop("normalize")
        if isinstance(norm, bool):
            norm = {"norm_obs": norm, "norm_reward": norm}
        if not isinstance(norm, dict) or set(norm) - {"norm_obs", "norm_reward", "gamma"} \
                or not norm.get("norm_obs", True):
            raise bad("normalize", f"must be a bool or a mapping of norm_obs (true) and norm_reward, got {norm!r} "
                                   "(a string would be evaluated as Python)")
        out["normalize"], out["normalize_reward"] = True, bool(norm.get("norm_reward", True))
    kwargs = entry.pop("policy_kwargs", {})
    if not isinstance(kwargs, dict) or set(kwargs) - {"net_arch", "log_std_init"}:
        raise bad("policy_kwargs", f"must be a mapping of net_arch and log_std_init, got {kwargs!r} "
                                   "(a string would be evaluated as Python)")
    if "net_arch" in kwargs:
        out["net_arch"] = tuple(kwargs["net_arch"])
    if "log_std_init" in kwargs:
        out["log_std_init"] = kwargs["log_std_init"]
    try:
        env_kwargs = translate_legacy_options(dict(entry.pop("env_kwargs", None) or {}))
    except ValueError as exc:
        raise bad("env_kwargs", str(exc)) from None
    if "scene" in env_kwargs:
        out.update(_scene_fields(env_kwargs.pop("scene"), bad))
    for key, field in (("start", "share"), ("controller", "posture_target")):
        if key in env_kwargs:
            value = env_kwargs.pop(key)
            if not (isinstance(value, dict) and set(value) == {field}):
                raise bad(f"env_kwargs.{key}", f"TrainConfig sets {key}.{field} only, got {value!r}")
            out["pregrasp_start" if key == "start" else field] = value[field]
    for key in SAME_NAME_ENV_KWARGS:
        if key in env_kwargs:
            out[key] = env_kwargs.pop(key)
    if "pose_error_deg" in env_kwargs:
        error = env_kwargs.pop("pose_error_deg")
        out["pose_error_range_deg" if isinstance(error, list) else "pose_error_deg"] = (
            tuple(error) if isinstance(error, list) else error)
    if env_kwargs:
        raise bad("env_kwargs", f"no TrainConfig field for {sorted(env_kwargs)}")
    callbacks = _callbacks(path, entry.pop("callback", []))
    if PREGRASP_ANNEALING in callbacks:
        initial = callbacks.pop(PREGRASP_ANNEALING).get("initial")
        if initial != out.get("pregrasp_start"):
            raise bad("callback", f"{PREGRASP_ANNEALING} anneals from env_kwargs.start.share "
                                  f"({out.get('pregrasp_start')}); its initial must be the same, got {initial!r}")
        out["pregrasp_anneal"] = True
    walls = {}
    if FALLING_LEARNING_RATE in callbacks:
        rate = callbacks.pop(FALLING_LEARNING_RATE)
        out["learning_rate_final"] = rate.get("final")
        if rate.get("max_wall_s") is not None:
            out["learning_rate_by_wall"], walls["rate"] = True, rate["max_wall_s"]
    if WALL_CLOCK_LIMIT in callbacks:
        out["max_wall_s"] = walls["stop"] = callbacks.pop(WALL_CLOCK_LIMIT).get("max_wall_s")
    if len(set(walls.values())) > 1 or ("rate" in walls and "stop" not in walls):
        raise bad("callback", f"the falling rate's max_wall_s must be {WALL_CLOCK_LIMIT}'s, got {walls}")
    if callbacks:
        raise bad("callback", f"no TrainConfig setting for {sorted(callbacks)} (supported: {PREGRASP_ANNEALING}, "
                              f"{FALLING_LEARNING_RATE}, {WALL_CLOCK_LIMIT})")
    if entry:
        raise bad(", ".join(sorted(entry)), "no TrainConfig field for these keys")
    return env_id, out


def with_recipe(cfg: Any, recipe: str | Path) -> Any:
    """Deprecated (2026-12-06), removed after 2027-06-06: use ``read_recipe(recipe).config``.

    ``cfg`` (a ``TrainConfig``) with the fields that ``recipe`` (a file, or a shipped recipe's
    name) sets; its entry is ``cfg.env_id``'s when the file has one, else its only one. A field
    that ``cfg`` sets to neither its default nor the recipe's value is a ``RecipeError`` (a flag
    given beside the file); the result is validated as any ``TrainConfig``."""
    import warnings
    from dataclasses import replace

    warnings.warn("sms3d_env.training.with_recipe is deprecated on 2026-12-06 and removed after 2027-06-06: use "
                  "sms3d_env.training.read_recipe(recipe).config, whose fields replace one another by "
                  "Recipe.with_fields", DeprecationWarning, stacklevel=2)
    path = recipe_path(recipe)
    defaults = type(cfg)()
    env_ids = read_zoo_yaml(path)
    env_id, values = recipe_fields(path, cfg.env_id if cfg.env_id in env_ids else None)
    clash = sorted(k for k, v in values.items() if getattr(cfg, k) not in (getattr(defaults, k), v))
    if clash:
        raise RecipeError(f"{path} sets {clash}; leave out the flags that set them too")
    return replace(cfg, **values)
