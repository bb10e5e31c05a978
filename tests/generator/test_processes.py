"""Processes that must end with the command that started them (generator.processes)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from generator.processes import kill_tree_on_exit

PARENT = """
import subprocess, sys, time
from generator.processes import kill_tree_on_exit
sleeper = subprocess.Popen(["sleep", "60"], start_new_session=True)  # would outlive this process
kill_tree_on_exit([sleeper.pid], interval=0.2)
print(sleeper.pid, flush=True)
time.sleep(60)
"""


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the watchdog reads /proc (Linux only)")
def test_a_watched_process_dies_with_its_killed_parent():
    parent = subprocess.Popen([sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True)
    sleeper = int(parent.stdout.readline())
    time.sleep(0.5)  # two of the watchdog's rounds
    assert _alive(sleeper)
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10
    while _alive(sleeper) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(sleeper)


def test_a_watchdog_that_cannot_start_is_reported(monkeypatch):
    if not sys.platform.startswith("linux"):
        pytest.skip("the watchdog reads /proc (Linux only)")
    monkeypatch.setattr(sys, "executable", "/bin/false")
    with pytest.warns(RuntimeWarning, match="did not start"):
        kill_tree_on_exit([os.getpid()])
