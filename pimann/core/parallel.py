"""Process-level parallelism for the stages: one spawned process per core.

Small-batch training and per-trajectory work scale better as independent single-threaded
processes than as one process with several BLAS threads (measured: 1.24x for training).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

from pimann.core.errors import PimannError
from pimann.core.logs import logging_levels, worker_logging
from pimann.core.progress import track

# the torch threads of a training, overriding train.threads: e.g. PIMANN_THREADS=1 for each
# of `dvc queue start -j 2` on two cores
THREADS_ENV = "PIMANN_THREADS"


def usable_cores() -> int:
    """The cores this process may run on: its affinity (taskset, a Slurm or container cpuset)."""
    if hasattr(os, "sched_getaffinity"):
        return max(1, len(os.sched_getaffinity(0)))
    return os.cpu_count() or 1


def busy_cores(
    loadavg: Path = Path("/proc/loadavg"), samples: int = 5, interval_s: float = 0.05
) -> int:
    """Other processes running now: the kernel's runnable count less this one, the least of
    a few reads `interval_s` apart (a momentary wake-up is no busy core); 0 where the count
    is not readable. A snapshot: two runs started in the same instant miss each other, which
    PIMANN_THREADS or taskset settles."""
    counts = []
    for k in range(samples):
        if k:
            time.sleep(interval_s)
        try:
            counts.append(int(loadavg.read_text().split()[3].split("/")[0]))
        except (OSError, ValueError, IndexError):
            return 0
    return max(0, min(counts) - 1)


def free_cores(usable: int, busy: int) -> int:
    """The usable cores not taken by the busy ones, at least one."""
    return max(1, usable - busy)


def cpu_workers(requested: int) -> int:
    """`requested` processes, at most one per usable core, at least one."""
    return max(1, min(requested, usable_cores()))


def training_threads(setting: int | str) -> int:
    """Torch threads of a training: PIMANN_THREADS, else `setting` (train.threads), where
    `auto` takes the usable cores that other running processes leave free. Torch's own
    default (every core) makes two trainings started together 8x slower than one thread
    each on two cores."""
    raw = os.environ.get(THREADS_ENV, "").strip()
    if raw:
        if not raw.isdigit() or int(raw) < 1:
            raise PimannError(None, f"{THREADS_ENV} must be a whole number >= 1, not {raw!r}")
        return int(raw)
    if setting == "auto":
        return free_cores(usable_cores(), busy_cores())
    return int(setting)


def pool_map(
    function: Callable, jobs: Sequence, workers: int, desc: str | None, unit: str = "jobs"
) -> list:
    """`function` over `jobs` in order, in `workers` spawned processes (1: in this one).

    `desc`: the progress over the jobs (pimann.core.progress); None: none. The workers log as this
    process does.
    """

    def collect(results: Iterable) -> list:
        return list(results if desc is None else track(results, desc, unit, total=len(jobs)))

    if workers <= 1 or len(jobs) <= 1:
        return collect(map(function, jobs))
    with ProcessPoolExecutor(
        workers,
        mp_context=get_context("spawn"),
        initializer=worker_logging,
        initargs=(logging_levels(),),
    ) as pool:
        return collect(pool.map(function, jobs))
