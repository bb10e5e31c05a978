"""Worker processes that end with the process that started them.

A ``ProcessPoolExecutor`` worker whose parent is killed (``kill -9``, an out-of-memory kill)
otherwise waits on its queue, or finishes its task and writes, forever beside a resumed run.
Pass :func:`die_with_parent` as the pool's ``initializer`` with ``initargs=(os.getpid(),)``, or
take :func:`worker_pool`, a spawn pool that does so. :func:`init_ray` starts a local Ray cluster
whose processes end with this one too (:func:`kill_tree_on_exit`).
"""

from __future__ import annotations

import ctypes
import os
import select
import signal
import sys
import threading
import time
import warnings
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

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


def children(pid: int) -> list[int]:
    """The child processes of ``pid`` (Linux: ``/proc/PID/task/*/children``; none once it ended)."""
    found = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found += [int(c) for c in (task / "children").read_text().split()]
        except OSError:  # the thread or the process ended while we looked
            pass
    return found


def _start_time(pid: int) -> str | None:
    """``pid``'s start time (``/proc/PID/stat`` field 22), which tells it from a later process
    given the same id; None once it ended."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def _watch_tree(roots: list[int], interval: float) -> None:
    """The watchdog of :func:`kill_tree_on_exit`: every ``interval`` seconds note the processes
    of the tree under ``roots``; once stdin reaches its end (the process that started this one
    ended, however), SIGKILL every noted process still running."""
    for sig in (signal.SIGINT, signal.SIGHUP):  # a Ctrl-C or a closed terminal ends the parent, not this
        signal.signal(sig, signal.SIG_IGN)
    noted = {pid: start for pid in roots if (start := _start_time(pid)) is not None}
    while True:
        tree: dict[int, str] = {}
        frontier = list(noted)
        while frontier:  # the tree as it is now; a noted process that ended drops out
            pid = frontier.pop()
            start = _start_time(pid)
            if start is not None and pid not in tree and noted.get(pid, start) == start:
                tree[pid] = start
                frontier += children(pid)
        noted = tree
        if select.select([sys.stdin], [], [], interval)[0]:
            break
    for pid, start in noted.items():
        if _start_time(pid) == start:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:  # ended in between
                pass


def kill_tree_on_exit(roots: Iterable[int], interval: float = 0.5) -> None:
    """Start a watchdog process that SIGKILLs ``roots`` and every process started under them once
    this process ends, even by SIGKILL: for a tree whose members outlive their parent on their own.
    Linux only (it reads ``/proc``); elsewhere nothing is started.

    The watchdog notes the tree every ``interval`` seconds (a process started and orphaned in
    between escapes it) and learns of this process's end from the end of its stdin: a pipe whose
    write end this process never closes (the kernel does, when it ends) and no child inherits."""
    if not sys.platform.startswith("linux"):
        return
    roots = list(roots)
    read_end, _write_end = os.pipe()  # both close-on-exec; the write end is left open on purpose
    pid = os.posix_spawn(sys.executable, [sys.executable, "-m", "generator.processes", str(interval), *map(str, roots)],
                         os.environ, file_actions=[(os.POSIX_SPAWN_DUP2, read_end, 0),
                                                   (os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0),
                                                   (os.POSIX_SPAWN_OPEN, 2, os.devnull, os.O_WRONLY, 0)])
    os.close(read_end)
    time.sleep(0.2)  # a watchdog that cannot start (no importable package) ends at once: say so
    if os.waitpid(pid, os.WNOHANG) != (0, 0):
        warnings.warn(f"the process watchdog ({sys.executable} -m generator.processes) did not start; processes "
                      f"{list(roots)} may outlive this one", RuntimeWarning, stacklevel=2)


def init_ray(num_cpus: int, **init_kwargs: Any) -> None:
    """``ray.init`` a local cluster of ``num_cpus`` CPUs whose processes end with this one.

    Ray's GCS server and raylet die with their parent already, and its workers follow the raylet
    within seconds; the raylet's agents (dashboard and runtime-env agents) do not: after a
    ``kill -9`` of this process they report the raylet's death to the dead GCS server and wait
    60 s for an answer before exiting (Ray 2.60). A :func:`kill_tree_on_exit` watchdog ends the
    whole tree at once."""
    import ray

    before = set(children(os.getpid()))
    ray.init(num_cpus=num_cpus, include_dashboard=False, log_to_driver=False, **init_kwargs)
    kill_tree_on_exit(sorted(set(children(os.getpid())) - before))


if __name__ == "__main__":  # the watchdog of kill_tree_on_exit: INTERVAL PID...
    _watch_tree([int(a) for a in sys.argv[2:]], float(sys.argv[1]))
