"""``render_mode="human"``: MuJoCo's passive viewer (``mujoco.viewer.launch_passive``) on the
env's world, synced after every reset and step at the simulation's pace.

The viewer is a GLFW window whatever ``MUJOCO_GL`` says: ``MUJOCO_GL`` picks the backend of
MuJoCo's off-screen ``mujoco.Renderer`` only (``sms3d_env`` sets EGL unless it is already set,
for headless machines), so the window and off-screen renders (``rgb_array``, image
observations) live side by side in one process. The window needs a display: ``DISPLAY`` (X11,
also a virtual one, ``xvfb-run``) or ``WAYLAND_DISPLAY`` on Linux; on macOS the script must run
under ``mjpython``, MuJoCo's launcher.
"""

from __future__ import annotations

import atexit
import os
import sys
import threading
import time
import warnings
import weakref
from collections.abc import Iterable
from typing import Any

import mujoco
import numpy as np

#: Seconds ``close`` waits for the viewer's threads to tear the window down (it took about 0.2 s
#: under Xvfb); a process that exits before they have done so crashes (segmentation fault).
_TEARDOWN_TIMEOUT_S = 10.0


class DisplayUnavailableError(RuntimeError):
    """``render_mode="human"`` without a display the viewer's window could open on."""


def check_display() -> None:
    """``DisplayUnavailableError`` unless GLFW can open windows here (``DISPLAY`` or
    ``WAYLAND_DISPLAY`` set and reachable; macOS: left to ``mjpython``'s own check)."""
    if sys.platform == "darwin":
        return
    advice = ("render_mode='human' opens a window; without a display use render_mode='rgb_array' "
              "(off-screen, MUJOCO_GL selects its backend) or run under a virtual display, e.g. "
              "`xvfb-run -a python script.py`")
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise DisplayUnavailableError(f"neither DISPLAY nor WAYLAND_DISPLAY is set: {advice}. "
                                      f"(MUJOCO_GL={os.environ.get('MUJOCO_GL')!r} does not give the "
                                      "viewer a display: it sets off-screen rendering only.)")
    import glfw

    # A hidden 1 x 1 window proves the display and its OpenGL: were either missing, the viewer's
    # own thread would fail to open its window, and launch_passive would wait for it forever.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ok = glfw.init()  # idempotent; the viewer's thread calls it again
        if ok:
            glfw.window_hint(glfw.VISIBLE, glfw.FALSE)
            probe = glfw.create_window(1, 1, "display check", None, None)
            ok = bool(probe)
            if ok:
                glfw.destroy_window(probe)
            glfw.default_window_hints()
    if not ok:
        reasons = "; ".join(str(w.message) for w in caught) or "GLFW failed"
        raise DisplayUnavailableError(f"GLFW cannot open an OpenGL window on DISPLAY={os.environ.get('DISPLAY')!r} "
                                      f"WAYLAND_DISPLAY={os.environ.get('WAYLAND_DISPLAY')!r} ({reasons}): {advice}")


def _shut(handle: Any, threads: Iterable[threading.Thread]) -> None:
    """Close the viewer and wait for its threads to finish tearing the window down."""
    handle.close()
    for thread in threads:
        thread.join(_TEARDOWN_TIMEOUT_S)


class PassiveViewer:
    """The window of one env: opened on the first world shown, opened again when a reset brings a
    new model (every reset builds one), synced no faster than one ``period_s`` (s) per step, so
    that an episode plays at the simulation's speed or slower.

    Args:
        period_s: simulated seconds per step (the env's ``control_dt``).
    """

    def __init__(self, period_s: float) -> None:
        check_display()
        self.period_s = float(period_s)
        self._model: mujoco.MjModel | None = None
        self._handle: Any = None
        self._shutdown: weakref.finalize | None = None
        self._last_sync = 0.0

    @property
    def is_running(self) -> bool:
        """Whether the window is open (a person may have closed it)."""
        return self._handle is not None and self._handle.is_running()

    def show(self, model: mujoco.MjModel, data: mujoco.MjData, eye: np.ndarray, lookat: np.ndarray) -> None:
        """Show ``data``; on a new ``model`` open the window with its free camera at ``eye``
        looking at ``lookat`` (m, world frame), where the user can turn and zoom it."""
        if model is not self._model:
            self.close()
            self._open(model, data, eye, lookat)
            return
        wait = self._last_sync + self.period_s - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        self._handle.sync()
        self._last_sync = time.monotonic()

    def _open(self, model: mujoco.MjModel, data: mujoco.MjData, eye: np.ndarray, lookat: np.ndarray) -> None:
        import mujoco.viewer

        before = set(threading.enumerate())
        handle = mujoco.viewer.launch_passive(model, data)
        # launch_passive keeps no reference to its thread; the threads it started are the ones to
        # join before the process may exit.
        threads = [t for t in threading.enumerate() if t not in before]
        offset = np.asarray(lookat, float) - np.asarray(eye, float)
        with handle.lock():
            handle.cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            handle.cam.lookat[:] = lookat
            handle.cam.distance = float(np.linalg.norm(offset))
            handle.cam.azimuth = float(np.degrees(np.arctan2(offset[1], offset[0])))
            handle.cam.elevation = float(np.degrees(np.arcsin(offset[2] / np.linalg.norm(offset))))
        handle.sync()
        self._model, self._handle = model, handle
        # Also when the viewer is dropped, and at interpreter exit: an env left open must not take
        # the process down with it. Registered after the viewer's own exit handlers (GLFW's
        # terminate among them), so that it runs before them.
        self._shutdown = weakref.finalize(self, _shut, handle, threads)
        atexit.register(self._shutdown)
        self._last_sync = time.monotonic()

    def close(self) -> None:
        """Close the window (if open) and wait until it is gone."""
        if self._shutdown is not None:
            atexit.unregister(self._shutdown)
            self._shutdown()
        self._model = self._handle = self._shutdown = None
