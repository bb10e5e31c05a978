"""RL recipes run by RL Baselines3 Zoo's trainer: ``sms3d train-policy RECIPE`` on an RL recipe is a
thin front to ``python -m rl_zoo3.train``.

An RL recipe is an RL Zoo hyperparameter file keyed by env id (``sms3d_env/recipes/ppo.yml``),
which RL Zoo reads as it stands: its ``env_kwargs`` reach ``gym.make`` as the file writes them,
and its ``callback:`` names the package's callbacks (:mod:`~sms3d_env.training.curriculum`,
:mod:`~sms3d_env.training.schedules`). :func:`zoo_argv` turns the command's flags into RL Zoo's
command line, :func:`train_zoo` prints that command and runs RL Zoo's own ``train()`` on it, so
the same command typed by hand makes the same run (``args.yml`` and ``config.yml`` record the
same settings). RL Zoo writes the run into ``OUT/ALGO/ENV_N/`` (:mod:`sms3d_env.policies.zoo_runs`
reads it); a rerun makes ``ENV_N+1``.

What the front adds to RL Zoo's defaults, each visible in the printed command: the package's env
ids (``--gym-packages sms3d_env``), seed 0 unless given, one torch thread (the policy's per-step
forward pass is tiny; 2 threads beside the env made it ~50x slower here) on the CPU, and the
periodic evaluation's env (:func:`evaluation_env_kwargs`: fresh beds, every episode from home).
"""

from __future__ import annotations

import contextlib
import shlex
import sys
from pathlib import Path
from typing import Any

from generator.config_file import shipped_or_file
from sms3d_env.policies.files import PolicyFileError
from sms3d_env.policies.zoo_runs import zoo_yaml_or_why

#: The shipped recipes: ``sms3d_env/recipes/<name>.yml``.
RECIPES_DIR = Path(__file__).parents[1] / "recipes"
#: What the front passes RL Zoo unless the command says otherwise (see the module's docstring).
FRONT_DEFAULTS = ("--gym-packages", "sms3d_env", "--num-threads", "1", "--device", "cpu")


class RecipeError(ValueError):
    """A recipe file that ``sms3d train-policy`` cannot follow; the message names the file and key."""


def recipe_path(name_or_path: str | Path) -> Path:
    """A shipped recipe by name (``"ppo"``: ``sms3d_env/recipes/ppo.yml``) or a recipe file's path
    (``FileNotFoundError`` naming it when there is neither)."""
    return shipped_or_file(name_or_path, RECIPES_DIR)


def read_zoo_yaml(path: Path) -> dict[str, Any]:
    """A recipe file as a mapping (safe YAML: RL Zoo's one ``OrderedDict`` tag, no other);
    ``RecipeError`` naming the file when it is not readable YAML of a mapping."""
    data, why = zoo_yaml_or_why(path)
    if data is None:
        raise RecipeError(f"{path}: {why}")
    return data


def recipe_entry(path: Path, env_id: str | None = None) -> tuple[str, dict[str, Any]]:
    """``(env_id, entry)``: the recipe file's hyperparameters for ``env_id`` (``None``: its first
    entry), as RL Zoo picks them; ``RecipeError`` naming the file when there is no such entry."""
    data = read_zoo_yaml(path)
    env_id = next(iter(data), None) if env_id is None else env_id
    if not isinstance(data.get(env_id), dict):
        raise RecipeError(f"{path}: no entry for {env_id} (entries: {sorted(data)})")
    return env_id, data[env_id]


def evaluation_env_kwargs(env_kwargs: dict[str, Any]) -> dict[str, Any]:
    """The periodic evaluation's env arguments for a recipe's ``env_kwargs``: the same, but fresh
    beds instead of a pool (``scene``'s ``config``) and every episode from home (no ``start``)."""
    kwargs = {k: v for k, v in env_kwargs.items() if k != "start"}
    scene = kwargs.get("scene")
    if isinstance(scene, dict) and "pool" in scene:
        kwargs["scene"] = scene.get("config") or {}
    return kwargs


def _store_dict(values: dict[str, Any]) -> list[str]:
    """``{"scene": {...}}`` as RL Zoo's ``KEY:VALUE`` arguments (it evaluates each value as Python)."""
    return [f"{key}:{value!r}" for key, value in values.items()]


def zoo_argv(recipe: str | Path, *, out: str = "logs", seed: int = 0, algo: str | None = None,
             env_id: str | None = None, steps: int | None = None, n_envs: int | None = None,
             vec_env: str | None = None, eval_freq: int | None = None, eval_episodes: int | None = None,
             checkpoint_freq: int | None = None, init_model: str | None = None,
             hyperparams: dict[str, Any] | None = None) -> list[str]:
    """The ``python -m rl_zoo3.train`` arguments of ``sms3d train-policy RECIPE`` with these flags:
    ``--algo`` the recipe file's name where it names an algorithm (RL Zoo's own files are
    ``ppo.yml``, ``sac.yml``), ``--env`` its first entry's id, ``--hyperparams`` ``hyperparams``
    (values as Python literals) and ``n_envs``; the rest as RL Zoo's flags of those names."""
    from rl_zoo3.utils import ALGOS

    path = recipe_path(recipe)
    if (algo or path.stem) not in ALGOS:
        known = ", ".join(sorted(ALGOS))
        raise RecipeError(f"--algo {algo}: not an RL Zoo algorithm ({known})" if algo else
                          f"{path}: its name is no RL Zoo algorithm ({known}); give --algo")
    algo = algo or path.stem
    env_id, entry = recipe_entry(path, env_id)
    params = {**({"n_envs": n_envs} if n_envs is not None else {}), **(hyperparams or {})}
    argv = ["--algo", algo, "--env", env_id, "--conf-file", str(path), *FRONT_DEFAULTS, "--seed", str(seed),
            "--log-folder", str(out)]
    for flag, value in (("-n", steps), ("--vec-env", vec_env), ("--eval-freq", eval_freq),
                        ("--eval-episodes", eval_episodes), ("--save-freq", checkpoint_freq),
                        ("--trained-agent", init_model)):
        if value is not None:
            argv += [flag, str(value)]
    if params:
        argv += ["--hyperparams", *_store_dict(params)]
    # RL Zoo's evaluation builds the registered env as it stands unless given its arguments.
    evaluation = evaluation_env_kwargs(params.get("env_kwargs", entry.get("env_kwargs")) or {})
    if evaluation:
        argv += ["--eval-env-kwargs", *_store_dict(evaluation)]
    return argv


def zoo_command(argv: list[str]) -> str:
    """``argv`` as the shell command that runs it (a Python literal in double quotes where that
    quotes it, else as ``shlex`` quotes it)."""
    def quoted(arg: str) -> str:
        return arg if shlex.quote(arg) == arg else f'"{arg}"' if not set(arg) & set('"$`\\!') else shlex.quote(arg)

    return " ".join(["python", "-m", "rl_zoo3.train", *map(quoted, argv)])


def _value(argv: list[str], flag: str) -> str:
    return argv[argv.index(flag) + 1]


def _run_folder(argv: list[str]) -> Path:
    """The folder RL Zoo saves the run of ``argv`` in next: ``LOG_FOLDER/ALGO/ENV_<N+1>``."""
    from rl_zoo3.utils import get_latest_run_id

    folder, env_id = Path(_value(argv, "--log-folder")) / _value(argv, "--algo"), _value(argv, "--env")
    return folder / f"{env_id}_{get_latest_run_id(str(folder), env_id) + 1}"


def train_zoo(argv: list[str]) -> dict[str, Any]:
    """Print the RL Zoo command of ``argv`` and run RL Zoo's ``train()`` on it in this process;
    returns ``{"command", "run", "model"}``. A ``--trained-agent`` that is no file is refused
    first (``PolicyFileError``), as RL Zoo would only assert it; RL Zoo loads one with SB3's own
    loader, which unpickles it (and its run's ``vecnormalize.pkl``): a file to trust."""
    from rl_zoo3.train import train

    if "--trained-agent" in argv:
        agent = Path(_value(argv, "--trained-agent"))
        if not agent.is_file() or agent.suffix != ".zip":
            raise PolicyFileError(agent, "no saved model (.zip) to start from")
    command, run = zoo_command(argv), _run_folder(argv)
    print(command, flush=True)
    with contextlib.ExitStack() as stack:
        stack.callback(setattr, sys, "argv", sys.argv)
        sys.argv = ["rl_zoo3.train", *argv]
        train()
    return {"command": command, "run": str(run), "model": str(run / f"{_value(argv, '--env')}.zip")}
