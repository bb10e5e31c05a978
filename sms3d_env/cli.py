"""The ``sms3d`` command line: scene generation, datasets, pose networks, picking.

It lives in the top package, the one allowed to import the others. ``COMMANDS`` is the one
table of subcommands: each names the module whose ``register(subparsers)`` adds it. Only the
module of the command being run is imported (``sms3d --help`` and a mistyped command import all
of them to list them); every module keeps torch, MuJoCo and the networks out of ``register``, so
building any parser stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

#: Subcommand -> the module that registers it, in the order ``sms3d --help`` lists them.
COMMANDS: dict[str, str] = {
    "preview": "generator.cli",
    "scene": "generator.cli",
    "generate": "generator.dataset.cli",
    "show": "generator.dataset.cli",
    "train-pose": "perception.cli_pose",
    "eval-pose": "perception.cli_pose",
    "train-axis-cnn": "perception.cli_pose",
    "train-segmenter": "perception.cli_detector",
    "train-detector": "perception.cli_detector",
    "eval-detector": "perception.cli_detector",
    "eval-pipeline": "perception.cli_detector",
    "show-estimates": "perception.cli_detector",
    "sweep": "sms3d_env.study.cli",
    "sweep-compare": "sms3d_env.study.cli",
    "record-demos": "sms3d_env.training.cli_demos",
    "train-policy": "sms3d_env.training.cli",
    "eval-policy": "sms3d_env.training.cli",
    "learning-curve": "sms3d_env.training.cli",
    "demo": "sms3d_env.demo",
}


def _command_of(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` runs (its first word that is no option), if it is one of ours."""
    first = next((a for a in argv if not a.startswith("-")), None)
    return first if first in COMMANDS else None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``sms3d`` parser with ``command``'s module registered, or every module (``None``)."""
    parser = argparse.ArgumentParser(prog="sms3d", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    modules = [COMMANDS[command]] if command else list(dict.fromkeys(COMMANDS.values()))
    for module in modules:
        importlib.import_module(module).register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(_command_of(argv)).parse_args(argv)
    from generator.errors import ConfigError, MeshError, SceneFormatError

    try:
        return int(args.func(args) or 0)
    except (ConfigError, MeshError, SceneFormatError, OSError) as exc:
        print(f"sms3d {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
