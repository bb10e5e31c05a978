"""Fixtures shared across the test tree: rendered beds and small generated datasets, each made
once per session and cached by its arguments (rendering and generation are the slow parts)."""

import os
import signal
import time

os.environ.setdefault("MUJOCO_GL", "egl")

from functools import cache
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def render_bed():
    """``render_bed(num_mushrooms, seed, width=640, height=480) -> (scene, frame)``: a generated
    bed and its clean overhead render (``generator.dataset.render.Frame``, no amodal masks)."""
    from generator import SceneConfig, generate_scene
    from generator.dataset.render import SceneRenderer

    @cache
    def make(num_mushrooms: int, seed: int, width: int = 640, height: int = 480):
        config = SceneConfig().replace(placement__num_mushrooms=num_mushrooms, camera__width=width,
                                       camera__height=height)
        scene = generate_scene(config, seed=seed)
        with SceneRenderer(height, width) as renderer:
            return scene, renderer.render(scene, amodal=False)

    return make


@pytest.fixture(scope="session")
def small_dataset(tmp_path_factory):
    """``small_dataset(num_scenes, num_mushrooms, seed, split_ratios) -> Path``: a ``sms3d
    generate`` folder of 256 x 192 beds seen from 25 cm (small enough to train on in seconds)."""
    from generator import SceneConfig
    from generator.dataset import DatasetOptions, generate_dataset

    @cache
    def make(num_scenes: int, num_mushrooms: int, seed: int, split_ratios: tuple[float, float, float]):
        out = tmp_path_factory.mktemp(f"beds_{num_scenes}x{num_mushrooms}_seed{seed}")
        config = SceneConfig().replace(camera__width=256, camera__height=192, camera__height_above_soil=0.25,
                                       placement__num_mushrooms=num_mushrooms)
        generate_dataset(out, config, num_scenes, seed=seed, options=DatasetOptions(split_ratios=split_ratios),
                         progress=False)
        return out

    return make


class ProcessTable:
    """Processes read from ``/proc``: for tests that kill a command and check its workers."""

    @staticmethod
    def state(pid: int) -> str | None:
        """The state letter in /proc/PID/stat (Z = zombie), None if there is no such process."""
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            return None

    @staticmethod
    def children(pid: int) -> list[int]:
        found = []
        for entry in Path("/proc").iterdir():
            try:
                if entry.name.isdigit() and int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1]) == pid:
                    found.append(int(entry.name))
            except OSError:  # ended while we looked
                pass
        return found

    @staticmethod
    def pool_workers(pid: int) -> list[int]:
        """``pid``'s children started by multiprocessing's spawn."""
        workers = []
        for child in ProcessTable.children(pid):
            try:
                if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
                    workers.append(child)
            except OSError:
                pass
        return workers

    def survivors(self, pids: list[int], wait_s: float = 5.0) -> list[int]:
        """Those of ``pids`` still alive (not zombies) after up to ``wait_s`` seconds; they are
        killed before returning, so that a failing test leaves nothing running."""
        deadline = time.monotonic() + wait_s
        while any(self.state(p) not in (None, "Z") for p in pids) and time.monotonic() < deadline:
            time.sleep(0.05)
        alive = [p for p in pids if self.state(p) not in (None, "Z")]
        for pid in alive:
            os.kill(pid, signal.SIGKILL)
        return alive


@pytest.fixture
def processes():
    """A :class:`ProcessTable` (skips where there is no ``/proc``)."""
    if not Path("/proc/self/stat").exists():
        pytest.skip("reads processes from /proc")
    return ProcessTable()


def _without_root_override() -> None:
    """Drop, in a child of root, the capabilities that let root write a read-only folder
    (CAP_DAC_OVERRIDE, CAP_DAC_READ_SEARCH, CAP_FOWNER), so that such a folder is read-only to it."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    for capability in (1, 2, 3):
        if libc.prctl(24, capability, 0, 0, 0) != 0:  # PR_CAPBSET_DROP
            raise OSError(ctypes.get_errno(), "prctl(PR_CAPBSET_DROP)")


@pytest.fixture
def read_only_child():
    """``subprocess`` keywords that make a read-only folder (mode 0o555) read-only to the child
    even when the tests run as root, which may write any folder."""
    return {"preexec_fn": _without_root_override} if os.geteuid() == 0 else {}
