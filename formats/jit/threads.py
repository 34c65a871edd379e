"""How many threads one job may use: the one setting every thread pool of imutool follows.

A single command uses the usable cores. ``imutool batch`` runs N jobs at once and gives each
``usable cores ÷ N`` (:func:`limit_threads` in each worker), so N workers never oversubscribe the machine: the CSV
parser and writer threads (``formats/csv.py``), pyarrow's pool (``formats/parquet.py``), numba's and the BLAS/OpenMP
pools (through their environment variables, for the libraries a worker loads after the limit, and threadpoolctl
where it is installed, for those already loaded).
"""

from __future__ import annotations

import os
import sys

ENV = "IMUTOOL_THREADS"  # the budget of this process (set by batch in its workers; a user may set it too)
# the thread pools of numerical libraries, read when each library loads
LIBRARY_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity; all cores where that is unknown)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def thread_budget() -> int:
    """Threads this process may use: ``IMUTOOL_THREADS`` when set to a positive integer, else the usable cores."""
    text = os.environ.get(ENV, "").strip()
    if text.isdigit() and int(text) > 0:
        return min(int(text), usable_cores())
    return usable_cores()


def limit_threads(n: int) -> int:
    """Cap this process (a batch worker) at ``n`` threads in every pool imutool uses; returns ``n`` (at least 1).

    Sets ``IMUTOOL_THREADS`` and the numerical libraries' variables (for what loads later), numba's thread count
    and pyarrow's CPU count where they are loaded, and the BLAS/OpenMP pools through threadpoolctl where it is
    installed (optional: numpy's BLAS is loaded before a forked worker starts)."""
    n = max(1, int(n))
    os.environ[ENV] = str(n)
    for name in LIBRARY_ENV:
        os.environ[name] = str(n)
    numba = sys.modules.get("numba")
    if numba is None:
        os.environ.setdefault("NUMBA_NUM_THREADS", str(n))
    else:
        # numba is loaded (a forked worker): its pool may already run, and numba re-reads NUMBA_NUM_THREADS at each
        # compile and refuses a change once its threads are launched ("Cannot set NUMBA_NUM_THREADS ..." on a cold
        # cache only), so the environment is left alone and the running pool is narrowed instead
        try:
            numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
        except (ValueError, AttributeError):
            pass
    pyarrow = sys.modules.get("pyarrow")
    if pyarrow is not None:
        pyarrow.set_cpu_count(n)
        pyarrow.set_io_thread_count(max(1, n))
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        pass
    else:
        threadpool_limits(n)
    return n
