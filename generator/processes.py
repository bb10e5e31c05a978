"""Worker processes that end with the process that started them.

A ``ProcessPoolExecutor`` worker whose parent is killed (``kill -9``, an out-of-memory kill)
otherwise waits on its queue, or finishes its task and writes, forever beside a resumed run.
Pass :func:`die_with_parent` as the pool's ``initializer`` with ``initargs=(os.getpid(),)``, or
take :func:`worker_pool`, a spawn pool that does so.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor

_PR_SET_PDEATHSIG = 1  # from <linux/prctl.h>


def die_with_parent(parent_pid: int) -> None:
    """End this process when ``parent_pid`` dies, even by SIGKILL.

    On Linux the kernel kills it (``PR_SET_PDEATHSIG``), even in the middle of a render that
    holds the GIL; the parent may have died before that took effect, hence the ``getppid`` check
    after it. Elsewhere a daemon thread polls for the parent's death (:func:`exit_when_orphaned`)."""
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent_pid:
            os._exit(1)
    else:
        threading.Thread(target=exit_when_orphaned, args=(parent_pid,), daemon=True).start()


def exit_when_orphaned(parent_pid: int, interval: float = 0.2) -> None:
    """Poll every ``interval`` seconds; exit this process once ``parent_pid`` is no longer its
    parent (an orphan is re-parented to init or a subreaper)."""
    while os.getppid() == parent_pid:
        time.sleep(interval)
    os._exit(1)


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """A pool of ``workers`` spawned processes that die with this one (:func:`die_with_parent`)."""
    import multiprocessing

    return ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"),
                               initializer=die_with_parent, initargs=(os.getpid(),))
