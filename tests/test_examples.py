"""The examples answer --help at once, describe themselves, and write where the repository
ignores their output."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = sorted((ROOT / "examples").glob("*.py"))

#: Run an example up to its argument parsing; print its parser's description, the defaults of
#: its path options and the heavy modules imported by then (what --help would have loaded).
PARSER_PROBE = """
import argparse, json, runpy, sys

def report(parser, args=None, namespace=None):
    defaults = vars(argparse.ArgumentParser.parse_known_args(parser, [])[0])
    print(json.dumps({"description": parser.description,
                      "paths": [v for k, v in defaults.items() if k in ("out", "video") and v],
                      "heavy": sorted(m for m in ("torch", "mujoco") if m in sys.modules)}))
    raise SystemExit(0)

argparse.ArgumentParser.parse_args = report
sys.argv = [sys.argv[1]]
runpy.run_path(sys.argv[0], run_name="__main__")
"""


def _probe(example: Path) -> dict:
    out = subprocess.run([sys.executable, "-c", PARSER_PROBE, str(example)], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_dataset_example_answers_help_without_loading_torch_or_mujoco():
    assert _probe(ROOT / "examples" / "generate_dataset.py")["heavy"] == []


@pytest.mark.parametrize("example", EXAMPLES, ids=lambda p: p.name)
def test_each_example_describes_itself_and_writes_into_an_ignored_folder(example):
    probe = _probe(example)
    assert probe["description"], f"{example.name} --help has no description"
    for path in probe["paths"]:
        ignored = subprocess.run(["git", "check-ignore", "-q", path], cwd=ROOT)
        assert ignored.returncode == 0, f"{example.name} writes {path} by default, which git does not ignore"
