"""How many threads a flight's processes' numeric libraries may use, for flights flown side by side."""

from __future__ import annotations

import os

# the variables that size the numeric libraries' thread pools: torch's and OpenMP's, numba's, the BLASes'
THREAD_VARIABLES = ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")


def thread_env(threads: int, environ=None) -> dict[str, str]:
    """The :data:`THREAD_VARIABLES` that hold a process to ``threads`` threads per library; one already set in
    ``environ`` (default: none) is kept as it is.  Flights flown side by side need it: each process's libraries
    size their pools by the machine's cores, and OpenMP's workers spin while they wait, so two flights at once on
    2 cores took 470-620 ms per frame pair of RAFT against 116-136 ms with a thread each (the suite's first four
    scenes, lockstep, the same decisions)."""
    environ = {} if environ is None else environ
    return {name: environ.get(name, str(int(threads))) for name in THREAD_VARIABLES}


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:                    # not on Linux
        return os.cpu_count() or 1


def flight_threads(flights_at_once: int, cpus: int | None = None) -> int:
    """Threads per library for each of ``flights_at_once`` flights sharing ``cpus`` (default: this machine's):
    their share, at least one."""
    cpus = available_cpus() if cpus is None else cpus
    return max(1, cpus // max(1, flights_at_once))
