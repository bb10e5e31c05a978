"""The documentation site builds with `mkdocs build --strict`: no broken link, anchor or snippet."""

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="mkdocs is not installed (the dev extra brings it)")
def test_docs_build_strictly_without_warnings(tmp_path):
    command = [sys.executable, "-m", "mkdocs", "build", "--strict",
               "--config-file", str(ROOT / "mkdocs.yml"), "--site-dir", str(tmp_path / "site")]
    # Not -q: quiet mode hides the warnings that --strict counts.
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    result = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    log = result.stdout + result.stderr
    warnings = [line for line in log.splitlines() if line.startswith(("WARNING", "ERROR"))]
    assert result.returncode == 0 and warnings == [], "mkdocs build --strict failed:\n" + "\n".join(warnings or [log])
    assert (tmp_path / "site" / "study" / "index.html").is_file()
