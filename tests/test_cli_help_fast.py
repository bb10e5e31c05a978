"""``sms3d --help`` stays fast: building the parser loads no torch, MuJoCo or trimesh.

Every ``sms3d`` call builds the whole parser, so one eager import of a heavy package in a sub-CLI
module (or a package ``__init__`` it triggers) costs seconds on every command, ``--help`` included.
"""

import json
import subprocess
import sys

HEAVY = ("torch", "torchvision", "mujoco", "mink", "trimesh", "scipy", "stable_baselines3")

# Runs in a fresh interpreter: this test process has long since imported all of them.
_PROBE = """
import contextlib, io, json, sys
from sms3d_env.cli import build_parser, main

parser = build_parser()
commands = [a for a in parser._actions if a.dest == "command"][0].choices
for argv in [["--help"]] + [[name, "--help"] for name in commands]:
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            main(argv)
        except SystemExit as exc:
            assert exc.code == 0, (argv, exc.code)
print(json.dumps({"commands": sorted(commands), "heavy": sorted(set(sys.argv[1:]) & set(sys.modules))}))
"""


def test_help_imports_no_heavy_packages():
    result = subprocess.run([sys.executable, "-c", _PROBE, *HEAVY], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    report = json.loads(result.stdout)
    assert {"generate", "train-pose", "train-detector", "sweep", "train-policy", "demo"} <= set(report["commands"])
    assert report["heavy"] == [], f"`sms3d --help` imported {report['heavy']}; import them inside the commands"


def test_the_command_table_is_exactly_what_the_modules_register():
    from sms3d_env.cli import COMMANDS, build_parser

    def commands(parser):
        return [a for a in parser._actions if a.dest == "command"][0].choices

    assert list(commands(build_parser())) == list(COMMANDS)  # listed in the table's order
    for name, module in COMMANDS.items():  # each command's own module registers it
        assert name in commands(build_parser(name)), (name, module)


_ONE_MODULE_PROBE = """
import contextlib, io, json, sys
from sms3d_env.cli import main
with contextlib.redirect_stdout(io.StringIO()):
    try:
        main(["generate", "--help"])
    except SystemExit:
        pass
print(json.dumps(sorted(m for m in sys.modules if m.startswith(("perception", "sms3d_env.study", "sms3d_env.training")))))
"""


def test_a_command_imports_only_its_own_module():
    result = subprocess.run([sys.executable, "-c", _ONE_MODULE_PROBE], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr[-2000:]
    assert json.loads(result.stdout) == []
