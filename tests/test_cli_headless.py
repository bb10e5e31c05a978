"""The command line renders without a display and without MUJOCO_GL set by the user."""

import os
import subprocess
import sys


def test_preview_renders_headless_with_mujoco_gl_unset(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM", "DISPLAY")}
    out = tmp_path / "scene.png"
    result = subprocess.run([sys.executable, "-m", "sms3d_env.cli", "preview", "--num-mushrooms", "3", "--out", str(out)],
                            env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-2000:]
    assert out.stat().st_size > 10_000
