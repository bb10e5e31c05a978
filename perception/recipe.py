"""A shipped network's recipe as data: the datasets it is trained on and its training steps, in
one YAML file that ``sms3d train-segmenter RECIPE`` or ``sms3d train-axis-cnn RECIPE`` runs.

The shipped recipes are ``perception/recipes/<name>.yml``, run by name: ``segmenter`` (the
shipped RGB-D segmenter) and ``axis_cnn`` (the shipped axis CNN). A recipe stands for ``sms3d``
commands, which ``--dry-run`` prints and a run executes in order, in this process:

1. ``sms3d generate`` of each dataset into ``DATA_ROOT/NAME``, by generate's own rule: a
   complete dataset renders nothing again, a partial one resumes, one made with other settings
   is refused;
2. the recipe's training command for each step, on the step's datasets, into ``OUT`` (a recipe
   of one step) or ``OUT/STEP`` (several); a step that ``continues`` starts from the previous
   step's ``best.pt`` (``--init``). Run again, each step resumes its run folder or says it is
   complete (:mod:`generator.run_folder`).

================  ===============================================================================
key               what it holds
================  ===============================================================================
``command``       the training command: ``train-segmenter`` or ``train-axis-cnn``
``out``           ``OUT`` unless the run gives ``--out``
``data_root``     ``DATA_ROOT`` unless the run gives ``--data-root``
``split_ratios``  ``[train, val, test]`` shares of every dataset's beds (train and val > 0)
``workers``       ``sms3d generate --workers`` (default 1; the beds do not depend on it)
``options``       options of every step (default none); ``--threads``, ``--cache`` replace theirs
``datasets``      a list of ``{name, beds, mushrooms, seed, realism}``: ``beds`` beds of
                  ``mushrooms`` mushrooms each, seeded by ``seed``, through the camera model
                  when ``realism`` (``sms3d generate --realism``; default false)
``steps``         a list of ``{name, datasets, options, continues}`` (``options`` default none,
                  ``continues`` default false); every dataset is trained on by some step
================  ===============================================================================

Options are the training command's flags by their names (``val_every: 4`` is ``--val-every 4``,
``true`` gives a switch), each checked as the command checks it; the folders, the datasets and a
continuing step's ``--init`` come from the recipe's own keys instead. Files are read by
:func:`generator.config_file.read_config_file` (safe YAML: no code runs from a file, a key given
twice is refused, ``1e-4`` is a number). Every error is a
:class:`~perception.errors.PerceptionConfigError` naming the file and the key
(``steps[2].options.lr``).
"""

from __future__ import annotations

import argparse
import re
import shlex
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from generator.config_file import read_config_file, shipped_or_file
from generator.errors import ConfigError
from perception.errors import PerceptionConfigError

#: The shipped recipes, ``<name>.yml``.
RECIPES_DIR = Path(__file__).resolve().with_name("recipes")
#: The training commands a recipe can name, each with the flag that takes its dataset folders.
DATASET_FLAGS = {"train-segmenter": "--data", "train-axis-cnn": "--scenes"}
#: Step options that a run's own flag replaces: where files go and how many threads train, not
#: what is learnt.
RUN_OPTIONS = ("threads", "cache")
#: Flags of a training command that run a recipe rather than being one of its options.
RECIPE_FLAGS = ("recipe", "out", "data_root", "dry_run", "overwrite", *RUN_OPTIONS)
#: Flags that no recipe option may set: the recipe's own keys set them (the folders and datasets),
#: or they are the run's choice.
RESERVED_OPTIONS = ("recipe", "out", "data_root", "dry_run", "overwrite", "resume", "help")

_TOP_KEYS = ("command", "out", "data_root", "split_ratios", "workers", "options", "datasets", "steps")
_TOP_REQUIRED = ("command", "out", "data_root", "split_ratios", "datasets", "steps")
_FOLDER_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")

#: What adds training commands to an ``sms3d`` sub-parser group (a CLI module's ``register``).
Register = Callable[[argparse._SubParsersAction], None]
#: Checks a parsed training command's settings as the command will, raising
#: ``PerceptionConfigError`` naming the option (e.g. a config class built from them).
CheckOptions = Callable[[argparse.Namespace], object]


@dataclass(frozen=True)
class RecipeDataset:
    """One ``sms3d generate`` dataset: ``beds`` beds of ``mushrooms`` mushrooms, seeded by
    ``seed``, rendered clean or through the camera model (``realism``)."""

    name: str
    beds: int
    mushrooms: int
    seed: int
    realism: bool = False


@dataclass(frozen=True)
class TrainingStep:
    """One run of the training command: on ``datasets`` (names), with ``options`` (the command's
    flags by name), from the previous step's ``best.pt`` when it ``continues``."""

    name: str
    datasets: tuple[str, ...]
    options: dict[str, Any] = field(default_factory=dict)
    continues: bool = False


@dataclass(frozen=True)
class NetworkRecipe:
    """A recipe file read and checked (the keys of the module docstring); ``source`` is its path."""

    source: str
    command: str
    out: str
    data_root: str
    split_ratios: tuple[float, float, float]
    workers: int
    options: dict[str, Any]
    datasets: tuple[RecipeDataset, ...]
    steps: tuple[TrainingStep, ...]

    def step_folder(self, index: int, out: str | None = None) -> str:
        """The run folder of step ``index`` under ``out`` (default the recipe's)."""
        out = self.out if out is None else out
        return out if len(self.steps) == 1 else str(Path(out) / self.steps[index].name)


def _error(source: str, key: str, message: str) -> PerceptionConfigError:
    return PerceptionConfigError(f"{source}: {key}", message)


def _mapping(value: Any, source: str, key: str, keys: Sequence[str], required: Sequence[str]) -> dict[str, Any]:
    """``value`` as a mapping of only ``keys``, holding every ``required`` one."""
    if not isinstance(value, Mapping):
        raise _error(source, key, f"must be a mapping of keys, got {type(value).__name__}")
    prefix = f"{key}." if key != "recipe" else ""
    for name in value:
        if name not in keys:
            raise _error(source, f"{prefix}{name}", f"no such key (the keys: {', '.join(keys)})")
    for name in required:
        if name not in value:
            raise _error(source, f"{prefix}{name}", "missing")
    return dict(value)


def _text(value: Any, source: str, key: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise _error(source, key, f"must be a non-empty string, got {value!r}")
    return value


def _folder_name(value: Any, source: str, key: str) -> str:
    if not isinstance(value, str) or not _FOLDER_NAME.fullmatch(value):
        raise _error(source, key, f"must be a folder name (letters, digits, '_', '.', '-'), got {value!r}")
    return value


def _integer(value: Any, source: str, key: str, lo: int, hi: int | None = None) -> int:
    from generator.config import require_int

    try:
        return require_int(key, value, lo, hi)
    except ConfigError as exc:
        raise _error(source, key, exc.message) from None


def _switch(value: Any, source: str, key: str) -> bool:
    if not isinstance(value, bool):
        raise _error(source, key, f"must be true or false, got {value!r}")
    return value


def _options(value: Any, source: str, key: str) -> dict[str, Any]:
    """A mapping of options; which exist is the command's to say (:func:`recipe_commands`)."""
    if not isinstance(value, Mapping):
        raise _error(source, key, f"must be a mapping of option names to values, got {value!r}")
    options = dict(value)
    for name in options:
        if name in RESERVED_OPTIONS:
            raise _error(source, f"{key}.{name}", "is no recipe option (the recipe's out, data_root, datasets and "
                                                  "continues keys and the run's flags set the folders)")
    return options


def _split_ratios(value: Any, source: str) -> tuple[float, float, float]:
    from generator.dataset.options import DatasetOptions

    numbers = isinstance(value, list) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    try:
        ratios = DatasetOptions(split_ratios=tuple(value) if numbers else ()).split_ratios
    except ConfigError as exc:
        raise _error(source, "split_ratios", exc.message) from None
    if not (ratios[0] > 0 and ratios[1] > 0):
        raise _error(source, "split_ratios", f"the training steps read each dataset's train and val beds: both shares "
                                             f"must be > 0, got {value!r}")
    return ratios


def _dataset(value: Any, source: str, key: str) -> RecipeDataset:
    from generator.config import SceneConfig
    from generator.dataset.writer import MAX_SCENES

    entry = _mapping(value, source, key, ("name", "beds", "mushrooms", "seed", "realism"),
                     ("name", "beds", "mushrooms", "seed"))
    mushrooms = _integer(entry["mushrooms"], source, f"{key}.mushrooms", 1)
    try:  # as `sms3d generate --num-mushrooms` will: within range, and room for them on the bed
        SceneConfig().replace(placement__num_mushrooms=mushrooms)
    except ConfigError as exc:
        raise _error(source, f"{key}.mushrooms", exc.message) from None
    return RecipeDataset(name=_folder_name(entry["name"], source, f"{key}.name"),
                         beds=_integer(entry["beds"], source, f"{key}.beds", 1, MAX_SCENES), mushrooms=mushrooms,
                         seed=_integer(entry["seed"], source, f"{key}.seed", 0),
                         realism=_switch(entry.get("realism", False), source, f"{key}.realism"))


def _step(value: Any, source: str, key: str, defined: Mapping[str, RecipeDataset]) -> TrainingStep:
    entry = _mapping(value, source, key, ("name", "datasets", "options", "continues"), ("name", "datasets"))
    names = entry["datasets"]
    if not isinstance(names, list) or not names:
        raise _error(source, f"{key}.datasets", f"must be a list of one or more dataset names, got {names!r}")
    for name in names:
        if name not in defined:
            raise _error(source, f"{key}.datasets", f"no dataset {name!r} in datasets (they are {', '.join(defined)})")
        if names.count(name) > 1:
            raise _error(source, f"{key}.datasets", f"{name} is named twice (its beds would count twice)")
    return TrainingStep(name=_folder_name(entry["name"], source, f"{key}.name"), datasets=tuple(names),
                        options=_options(entry.get("options", {}), source, f"{key}.options"),
                        continues=_switch(entry.get("continues", False), source, f"{key}.continues"))


def _entries(value: Any, source: str, key: str) -> list[Any]:
    if not isinstance(value, list) or not value:
        raise _error(source, key, f"must be a list of one or more entries, got {value!r}")
    return value


def _unique_names(items: Sequence[RecipeDataset | TrainingStep], source: str, key: str) -> None:
    seen: set[str] = set()
    for index, item in enumerate(items):
        if item.name in seen:
            raise _error(source, f"{key}[{index}].name", f"{item.name} names an earlier entry too")
        seen.add(item.name)


def recipe_path(name_or_path: str | Path) -> Path:
    """A shipped recipe by name (``"axis_cnn"``: ``perception/recipes/axis_cnn.yml``) or a recipe
    file's path; ``FileNotFoundError`` naming it when there is neither."""
    return shipped_or_file(name_or_path, RECIPES_DIR)


def read_recipe(name_or_path: str | Path) -> NetworkRecipe:
    """The recipe shipped under that name, or in that file, checked.

    Raises:
        FileNotFoundError: neither a shipped recipe nor a file.
        PerceptionConfigError: naming the file and the key, for a file that cannot be read or
            parsed, a key that is no recipe key, or a value that cannot be followed. The steps'
            options are checked against the command by :func:`recipe_commands`.
    """
    path = recipe_path(name_or_path)
    source = str(path)
    try:
        raw = read_config_file(path)
    except ConfigError as exc:
        raise PerceptionConfigError(exc.field, exc.message) from None
    top = _mapping(raw, source, "recipe", _TOP_KEYS, _TOP_REQUIRED)
    command = top["command"]
    if command not in DATASET_FLAGS:
        raise _error(source, "command", f"must be one of {', '.join(DATASET_FLAGS)}, got {command!r}")
    datasets = tuple(_dataset(entry, source, f"datasets[{i}]")
                     for i, entry in enumerate(_entries(top["datasets"], source, "datasets")))
    _unique_names(datasets, source, "datasets")
    defined = {dataset.name: dataset for dataset in datasets}
    steps = tuple(_step(entry, source, f"steps[{i}]", defined)
                  for i, entry in enumerate(_entries(top["steps"], source, "steps")))
    _unique_names(steps, source, "steps")
    if steps[0].continues:
        raise _error(source, "steps[0].continues", "the first step has no step before it to continue from")
    trained = {name for step in steps for name in step.datasets}
    for index, dataset in enumerate(datasets):
        if dataset.name not in trained:
            raise _error(source, f"datasets[{index}]", f"no step trains on {dataset.name}")
    return NetworkRecipe(source=source, command=command, out=_text(top["out"], source, "out"),
                         data_root=_text(top["data_root"], source, "data_root"),
                         split_ratios=_split_ratios(top["split_ratios"], source),
                         workers=_integer(top.get("workers", 1), source, "workers", 1),
                         options=_options(top.get("options", {}), source, "options"), datasets=datasets, steps=steps)


class _RaisingParser(argparse.ArgumentParser):
    """A parser whose errors raise instead of exiting: a recipe's commands are all parsed before
    the first one runs."""

    def error(self, message: str) -> Any:
        raise PerceptionConfigError(self.prog, message)


def command_parsers(register: Register) -> dict[str, argparse.ArgumentParser]:
    """``sms3d generate`` and the commands ``register`` adds, by name, as parsers that raise
    ``PerceptionConfigError`` instead of exiting."""
    from generator.dataset.cli import register as register_generate

    top = argparse.ArgumentParser(prog="sms3d")
    group = top.add_subparsers(dest="command", parser_class=_RaisingParser)
    register_generate(group)
    register(group)
    return dict(group.choices)


def parse_command(parsers: Mapping[str, argparse.ArgumentParser], argv: Sequence[str]) -> argparse.Namespace:
    """``argv`` (a command's name, then its flags) parsed as ``sms3d`` would parse it."""
    return parsers[argv[0]].parse_args(argv[1:], namespace=argparse.Namespace(command=argv[0]))


def _flags(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """A parser's optional arguments by their ``dest`` (argparse keeps them in ``_actions`` and
    gives them no public accessor)."""
    return {action.dest: action for action in parser._actions if action.option_strings}


def _option_tokens(action: argparse.Action, value: Any, source: str, key: str) -> list[str]:
    """The flag and values that give option ``key`` its ``value``, checked by the flag's own type
    and choices."""
    flag = next(s for s in action.option_strings if s.startswith("--"))
    if action.nargs == 0:
        if not isinstance(value, bool):
            raise _error(source, key, f"{flag} is a switch: true or false, got {value!r}")
        return [flag] if value else []
    several = action.nargs in ("+", "*") or isinstance(action.nargs, int)
    values = value if several and isinstance(value, list) else [value]
    if (several and not isinstance(value, list)) or any(isinstance(v, (bool, list, dict)) or v is None
                                                          for v in values):
        raise _error(source, key, f"expected {'a list of values' if several else 'one value'} for {flag}, got {value!r}")
    tokens = [str(v) for v in values]
    for token in tokens:
        try:
            parsed = token if action.type is None else action.type(token)
        except argparse.ArgumentTypeError as exc:
            raise _error(source, key, f"{flag} {token}: {exc}") from None
        except (TypeError, ValueError):
            kind = getattr(action.type, "__name__", "value")
            raise _error(source, key, f"{flag} takes {'an' if kind == 'int' else 'a'} {kind}, got {value!r}") from None
        if action.choices is not None and parsed not in action.choices:
            raise _error(source, key, f"must be one of {', '.join(map(str, action.choices))}, got {value!r}")
    return [flag, *tokens]


def _tokens(options: Mapping[str, Any], flags: Mapping[str, argparse.Action], source: str, key: str,
            reserved: Sequence[str]) -> list[str]:
    tokens: list[str] = []
    for name, value in options.items():
        if name in reserved:
            raise _error(source, f"{key}.{name}", "is no recipe option (the recipe's datasets and continues keys set it)")
        if name not in flags:
            known = [dest for dest in flags if dest not in (*RESERVED_OPTIONS, *reserved)]
            raise _error(source, f"{key}.{name}", f"no such option (the options: {', '.join(known)})")
        tokens += _option_tokens(flags[name], value, source, f"{key}.{name}")
    return tokens


def _generate_command(recipe: NetworkRecipe, dataset: RecipeDataset, data_root: str) -> list[str]:
    # repr: the shortest text that reads back as the same float ("0.95"); whole numbers bare
    ratios = ",".join(str(int(r)) if r.is_integer() else repr(r) for r in recipe.split_ratios)
    return ["generate", "--out", str(Path(data_root) / dataset.name), "--num-scenes", str(dataset.beds),
            "--num-mushrooms", str(dataset.mushrooms), "--seed", str(dataset.seed), "--split-ratios", ratios,
            "--workers", str(recipe.workers), *(["--realism"] if dataset.realism else [])]


def recipe_commands(recipe: NetworkRecipe, parsers: Mapping[str, argparse.ArgumentParser],
                    check_options: CheckOptions, *, out: str | None = None, data_root: str | None = None,
                    run_options: Mapping[str, Any] | None = None, overwrite: bool = False) -> list[list[str]]:
    """The ``sms3d`` commands (each without ``sms3d``) that run ``recipe``: one ``generate`` per
    dataset, then the training command per step. ``out`` and ``data_root`` replace the recipe's,
    ``run_options`` (:data:`RUN_OPTIONS`) its options of those names, and ``overwrite`` starts
    every step anew.

    Every command is parsed by ``parsers`` (:func:`command_parsers`) and each training step's
    settings checked by ``check_options`` before this returns, so that a bad option of the last
    step is reported before the first runs: ``PerceptionConfigError`` naming the file and key.
    """
    source = recipe.source
    data_root = recipe.data_root if data_root is None else data_root
    commands = [_generate_command(recipe, dataset, data_root) for dataset in recipe.datasets]
    flags = _flags(parsers[recipe.command])
    dataset_flag = DATASET_FLAGS[recipe.command]
    run_options = dict(run_options or {})
    for index, step in enumerate(recipe.steps):
        key = f"steps[{index}]"
        reserved = [dataset_flag.removeprefix("--"), *(["init"] if step.continues else [])]
        argv = [recipe.command, "--out", recipe.step_folder(index, out), dataset_flag,
                *(str(Path(data_root) / name) for name in step.datasets)]
        # the recipe's shared options, less those the step sets; the run's own flags over both
        own = {name: value for name, value in step.options.items() if name not in run_options}
        shared = {**{name: value for name, value in recipe.options.items() if name not in own}, **run_options}
        argv += _tokens(shared, flags, source, "options", reserved)
        if step.continues:
            if "init" not in flags:
                raise _error(source, f"{key}.continues", f"sms3d {recipe.command} cannot start from a network (no --init)")
            argv += ["--init", str(Path(recipe.step_folder(index - 1, out)) / "best.pt")]
        argv += _tokens(own, flags, source, f"{key}.options", reserved)
        argv += ["--overwrite"] if overwrite else []
        try:
            check_options(parse_command(parsers, argv))
        except PerceptionConfigError as exc:
            option = exc.field.removeprefix("--").replace("-", "_")
            where = (f"{key}.options.{option}" if option in step.options
                     else f"options.{option}" if option in recipe.options else key)
            raise _error(source, where, str(exc).removeprefix(f"{exc.field}: ")) from None
        commands.append(argv)
    return commands


def command_line(argv: Sequence[str]) -> str:
    """``argv`` as the ``sms3d`` line a shell runs."""
    return shlex.join(["sms3d", *argv])


def _refuse_recipe_set_flags(args: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """With a RECIPE, the flags that set what the recipe sets are errors, not silently ignored."""
    flags = _flags(parser)
    for dest, action in flags.items():
        if dest not in RECIPE_FLAGS and getattr(args, dest, action.default) != action.default:
            usable = ", ".join(flags[d].option_strings[0] for d in RECIPE_FLAGS if d in flags)
            raise PerceptionConfigError(action.option_strings[0], f"the recipe sets it; with a RECIPE the flags are "
                                                                  f"{usable} (copy the recipe to change the rest)")


def run_recipe(args: argparse.Namespace, register: Register, check_options: CheckOptions) -> int:
    """``sms3d COMMAND RECIPE``: the recipe ``args.recipe`` names, for the training command
    ``args.command`` that ``register`` adds, run (or with ``--dry-run`` printed) as the module
    docstring says. Returns the exit code: 2 for a recipe or flag that cannot be followed (the
    file and key or the flag named), a failed command's own code (the commands after it are not
    run), else 0."""
    from generator.run_folder import RunFolderError, check_out_path

    try:
        recipe = read_recipe(args.recipe)
        if recipe.command != args.command:
            raise _error(recipe.source, "command", f"a {recipe.command} recipe; run it with sms3d {recipe.command} "
                                                   f"{args.recipe}")
        check_out_path(recipe.out if args.out is None else args.out)
        check_out_path(recipe.data_root if args.data_root is None else args.data_root, "--data-root")
        parsers = command_parsers(register)
        _refuse_recipe_set_flags(args, parsers[args.command])
        run_options = {name: getattr(args, name) for name in RUN_OPTIONS if getattr(args, name, None) is not None}
        commands = recipe_commands(recipe, parsers, check_options, out=args.out, data_root=args.data_root,
                                   run_options=run_options, overwrite=args.overwrite)
    except (PerceptionConfigError, RunFolderError, FileNotFoundError) as exc:
        print(f"sms3d {args.command}: error: {exc}", file=sys.stderr)
        return 2
    if args.dry_run:
        print("\n".join(command_line(argv) for argv in commands))
        return 0
    for argv in commands:
        print(f"$ {command_line(argv)}", flush=True)
        command = parse_command(parsers, argv)
        code = int(command.func(command) or 0)
        if code:
            print(f"sms3d {args.command}: {recipe.source}: stopped, `sms3d {argv[0]}` exited with {code}; run the "
                  "recipe again to resume", file=sys.stderr)
            return code
    print(f"{recipe.source}: done; the network is {Path(recipe.step_folder(len(recipe.steps) - 1, args.out)) / 'best.pt'}")
    return 0
