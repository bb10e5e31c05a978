"""Headless rendering by default: ``MUJOCO_GL`` is set in one place (``generator/__init__.py``),
before any of the packages imports mujoco, whichever package is imported first."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]


def test_mujoco_gl_is_set_in_one_place():
    setters = [f"{path.relative_to(ROOT)}:{n}" for package in ("generator", "perception", "sms3d_env")
               for path in sorted((ROOT / package).rglob("*.py"))
               for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
               if re.search(r"environ(\.setdefault\(|\[)\s*[\"']MUJOCO_GL", line)]
    assert setters == ["generator/__init__.py:9"], setters


#: Run in a fresh interpreter: records MUJOCO_GL at the moment mujoco is first imported.
PROBE = """
import os, sys
seen = []
class Probe:
    def find_spec(self, name, path=None, target=None):
        if name == "mujoco" and not seen:
            seen.append(os.environ.get("MUJOCO_GL"))
        return None
sys.meta_path.insert(0, Probe())
import {module}
import mujoco
print(seen[0])
"""


@pytest.mark.parametrize("module", ["sms3d_env", "perception.pipeline", "generator.dataset.render", "sms3d_env.cli"])
def test_each_package_renders_headless_when_imported_first(module):
    env = {k: v for k, v in os.environ.items() if k != "MUJOCO_GL"}
    out = subprocess.run([sys.executable, "-c", PROBE.format(module=module)], env=env, capture_output=True,
                         text=True, check=True).stdout
    assert out.split() == ["egl"]  # set before mujoco picked its GL backend
