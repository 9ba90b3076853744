"""How many threads a run uses, decided in one place for the parts that thread.

A step's work runs one part at a time: the compiled assembly, then the sparse solver, then
NumPy's own work. The assembly therefore gets the whole machine (:func:`run_threads`), and
NumPy's BLAS none of it (:func:`serial_blas`): a run has no dense product large enough to gain
from threads, and OpenBLAS's idle workers spin on a core after each threaded call. Measured on
the ring impact refined 8x (46 530 unknowns, 2 cores, load ~1.5, ``benchmarks/scaling.py
--threads``): with the BLAS threaded outside Newton its workers took 0.37 s of CPU a step,
the whole second core, and neither PARDISO nor the assembly could use it (0.77 s a step
whatever their threads); with the BLAS serial, the assembly on 2 threads took 0.129 against
0.198 s a step. PARDISO's threads are chosen apart (``solvers.linear.pardiso_threads``: one on
2 cores, where a second gains ~5 % and costs bit-for-bit reproducibility).

Environment, as a user of MKL or OpenMP code expects it: ``OMP_NUM_THREADS`` sets the run's
threads; ``MKL_NUM_THREADS`` overrides it for PARDISO alone; ``NUMBA_NUM_THREADS`` caps the
assembly. Dask's workers set ``OMP_NUM_THREADS=1`` and ``MKL_NUM_THREADS=1``, so a sweep's
cases run on one thread each.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache

from threadpoolctl import ThreadpoolController, threadpool_limits

__all__ = ["MAX_THREADS", "available_cores", "run_threads", "serial_blas", "single_threaded",
           "threads_from_environment"]

#: The most threads used without being asked: the nested-dissection tree of a 2D mesh of
#: 10^5 unknowns has too few large separators to keep more PARDISO threads busy.
MAX_THREADS = 8


def threads_from_environment(*names: str) -> int | None:
    """The first of these environment variables set to a positive integer, or None."""
    for name in names:
        value = os.environ.get(name, "").strip()
        if value.isdigit() and int(value) > 0:
            return int(value)
    return None


def available_cores() -> int:
    """The cores this process may run on (its affinity mask where the system has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def run_threads(cores: int | None = None) -> int:
    """Threads of a run's threaded parts: ``OMP_NUM_THREADS`` if set, else every core, at
    most :data:`MAX_THREADS`."""
    requested = threads_from_environment("OMP_NUM_THREADS")
    if requested is not None:
        return requested
    return max(1, min(available_cores() if cores is None else cores, MAX_THREADS))


@lru_cache(maxsize=1)
def _blas() -> ThreadpoolController:
    """threadpoolctl's handle on the BLAS libraries loaded (NumPy's, with NumPy)."""
    return ThreadpoolController().select(user_api="blas")


def serial_blas():
    """A context in which NumPy's BLAS runs on one thread (restored on exit). It limits every
    BLAS threadpoolctl sees, MKL too once pypardiso loaded it; PARDISO sets its own threads
    for each call (``solvers.linear._PardisoBackend._call``)."""
    return _blas().limit(limits=1)


@contextmanager
def single_threaded() -> Iterator[None]:
    """A context in which a run uses one thread in every part: ``OMP_NUM_THREADS`` and
    ``MKL_NUM_THREADS`` set to 1 (so :func:`run_threads` and PARDISO's count give 1) and every
    thread pool threadpoolctl sees limited to 1; all restored on exit. For a sweep's case,
    whose worker shares the machine with one worker a core, also where the worker was not
    started by a Dask nanny (which sets the same variables)."""
    names = ("OMP_NUM_THREADS", "MKL_NUM_THREADS")
    saved = {name: os.environ.get(name) for name in names}
    os.environ.update(dict.fromkeys(names, "1"))
    try:
        with threadpool_limits(1):
            yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
