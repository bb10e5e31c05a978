"""``render_mode="human"``: MuJoCo's passive viewer opens on reset, follows the steps and closes
with the env, under a virtual X server (Xvfb) beside EGL off-screen rendering; without a display
the env says what is missing."""

import os
import shutil
import subprocess
import sys
import textwrap

import pytest

from sms3d_env.viewer import DisplayUnavailableError

# Run in a child process: a viewer that crashed at exit must fail this test, not end pytest.
SCRIPT = textwrap.dedent("""
    import time
    import gymnasium as gym
    import numpy as np
    import sms3d_env
    from generator import SceneConfig

    def make():
        return gym.make("SMS3DPick-v1", scene=SceneConfig().replace(placement__num_mushrooms=4),
                        render_mode="human")

    env = make()
    assert env.unwrapped.viewer is not None and not env.unwrapped.viewer.is_running
    env.reset(seed=0)
    assert env.unwrapped.viewer.is_running
    start = time.monotonic()
    for _ in range(5):
        assert env.step(np.zeros(7, np.float32))[0] is not None
    paced = time.monotonic() - start  # synced at the simulation's pace: 0.04 s per step
    env.reset(seed=1)  # a new world: the window opens on it
    assert env.unwrapped.viewer.is_running
    env.close()
    assert not env.unwrapped.viewer.is_running
    left_open = make()  # not closed: the process must still exit cleanly
    left_open.reset(seed=0)
    print(f"paced {paced:.3f}")
""")


@pytest.fixture
def virtual_display():
    """A fresh Xvfb server on a free display number (Xvfb picks it: -displayfd)."""
    if shutil.which("Xvfb") is None:
        pytest.skip("no Xvfb binary (apt-get install xvfb) to run an X server for the viewer")
    server = subprocess.Popen(["Xvfb", "-displayfd", "1", "-screen", "0", "1024x768x24", "-nolisten", "tcp"],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    number = server.stdout.readline().strip()
    if not number.isdigit():
        server.kill()
        pytest.skip("Xvfb did not start an X server")
    yield f":{number}"
    server.terminate()
    server.wait(timeout=10)


def test_the_viewer_opens_follows_the_steps_and_closes(virtual_display):
    env = {**os.environ, "DISPLAY": virtual_display, "MUJOCO_GL": "egl"}
    env.pop("WAYLAND_DISPLAY", None)
    run = subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    paced = float(run.stdout.split("paced ")[1])
    assert paced >= 4 * 0.04  # five steps shown at no more than real time


@pytest.mark.skipif(sys.platform == "darwin", reason="macOS opens windows through mjpython, not DISPLAY")
def test_human_mode_without_a_display_names_what_is_missing(monkeypatch):
    import gymnasium as gym

    import sms3d_env  # noqa: F401

    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(DisplayUnavailableError, match="neither DISPLAY nor WAYLAND_DISPLAY is set.*MUJOCO_GL"):
        gym.make("SMS3DPick-v1", render_mode="human")
