"""The README's set-up commands are what CI runs."""

from __future__ import annotations

import re
from pathlib import Path

import tomllib

ROOT = Path(__file__).resolve().parents[1]


def _readme_commands() -> list[str]:
    blocks = re.findall(r"```bash\n(.*?)```", (ROOT / "README.md").read_text(encoding="utf-8"), re.S)
    return [line.strip() for block in blocks for line in block.splitlines() if line.startswith("pip install")]


def test_ci_runs_the_readme_test_command_verbatim():
    test_commands = [c for c in _readme_commands() if "pytest" in c]
    assert len(test_commands) == 1, test_commands
    ci_lines = [line.strip() for line in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()]
    assert test_commands[0] in ci_lines


def test_the_demo_and_test_commands_pin_one_torch():
    """In one venv the test command keeps the demo's torch: both name the same release."""
    commands = _readme_commands()
    pins = {re.search(r'"torch==([^"]+)"', c).group(1) for c in commands if "sms3d demo" in c or "pytest" in c}
    assert len(pins) == 1, pins


def test_the_test_extra_asks_for_no_other_torch():
    """torchvision from PyPI requires the newest torch, so a dev extra holding it would replace
    the pinned torch (with the CUDA build); it lives only in the baselines extra."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    dev = project["optional-dependencies"]["dev"]
    assert not [r for r in dev if re.match(r"(torch|torchvision)\b", r)], dev
    assert any(r.startswith("mkdocs") for r in dev), "the suite builds the docs, so the dev extra brings MkDocs"
