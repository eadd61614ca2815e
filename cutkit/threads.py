"""How many numba threads cutkit runs.

numba starts one thread per core by default.  On a machine whose cores
are already busy (other users, other runs, the workers of a sweep) the
extra threads only wait on each other: on a loaded 2-core machine a
relaxation ran ten times slower with two threads than with one, with the
same result.  :func:`configure_threads` therefore picks at most the cores
that are free, and never more than the cores this process may run on.

The command line calls it for every command, with ``--threads N`` or the
environment variable ``CUTKIT_THREADS``.
"""

from __future__ import annotations

import contextlib
import os

from cutkit.errors import InputError

#: Environment variable read when no thread count is given.
ENV_VAR = "CUTKIT_THREADS"


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the system has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - macOS, Windows
        return max(1, os.cpu_count() or 1)


#: How long :func:`busy_cores_now` watches the processor, seconds.  Long
#: enough to see a running job (a few scheduler ticks), short enough not to
#: be felt at a command's start; it is only paid when the load average
#: says the cores are busy.
BUSY_SAMPLE_S = 0.2

#: The kernel's aggregate processor counters (Linux).
PROC_STAT = "/proc/stat"


def _cpu_times(path=PROC_STAT):
    """(busy, total) jiffies of all processors since boot, or None where the file is not there."""
    try:
        with open(path) as f:
            fields = f.readline().split()
    except OSError:
        return None
    if not fields or fields[0] != "cpu" or len(fields) < 5:
        return None
    ticks = [int(v) for v in fields[1:]]
    idle = ticks[3] + (ticks[4] if len(ticks) > 4 else 0)  # idle + iowait
    return sum(ticks) - idle, sum(ticks)


def busy_cores_now(interval=BUSY_SAMPLE_S, path=PROC_STAT):
    """Cores busy over the next ``interval`` seconds (processor counters sampled twice), or None.

    Unlike the load average, which remembers the last minute, this sees
    only what runs now: a run that has just ended (ours, the previous
    command) no longer counts.

    Parameters
    ----------
    interval : float
        Seconds between the two samples.
    path : str
        The counters file (Linux ``/proc/stat``); None is returned where it
        cannot be read.

    Returns
    -------
    busy : float or None
        Busy cores of the whole machine (0 .. its processor count).
    """
    import time

    first = _cpu_times(path)
    if first is None:
        return None
    time.sleep(interval)
    second = _cpu_times(path)
    if second is None or second[1] <= first[1]:
        return None
    share = (second[0] - first[0]) / (second[1] - first[1])
    return share * (os.cpu_count() or 1)


def free_cores(cores: int | None = None) -> int:
    """Cores not busy with other work, at least 1.

    ``cores`` minus the 1-minute load average; where that says some cores
    are busy, the processor is watched for :data:`BUSY_SAMPLE_S` and the
    cores busy *now* are taken instead (the load average still counts a run
    that ended seconds ago: a second command started right after a first
    would otherwise get one thread on an idle 2-core machine).

    Parameters
    ----------
    cores : int, optional
        Cores to start from; default :func:`available_cores`.
    """
    cores = available_cores() if cores is None else int(cores)
    try:
        load = os.getloadavg()[0]
    except (AttributeError, OSError):  # pragma: no cover - Windows
        return cores
    if int(round(load)) > 0:
        busy = busy_cores_now()
        if busy is not None:
            load = min(load, busy)
    return int(min(cores, max(1, cores - int(round(load)))))


def default_threads() -> int:
    """The thread count used when none is asked for: the free cores, never more than the cores."""
    return free_cores(available_cores())


def parse_threads(value) -> int | None:
    """A thread count from the command line or the environment; None for "choose".

    Raises
    ------
    InputError
        When ``value`` is not a whole number >= 1.
    """
    if value is None or (isinstance(value, str) and value.strip() == ""):
        return None
    try:
        n = int(str(value).strip())
    except ValueError:
        raise InputError(f"threads must be a whole number >= 1, got {value!r}") from None
    if n < 1:
        raise InputError(f"threads must be a whole number >= 1, got {value!r}")
    return n


#: The threads :func:`configure_threads` chose (None: not called).  numba's thread count is
#: thread-local: a thread started later runs its parallel kernels on all of numba's threads
#: unless it sets its own (:func:`use_threads_in_this_thread`).
_configured: int | None = None
_blas = None  # the process's BLAS libraries (threadpoolctl), looked up at the first one_blas_thread


def configured_threads() -> int:
    """The threads :func:`configure_threads` chose, or numba's count on this thread if it was not called."""
    if _configured is not None:
        return _configured
    return numba_threads_here()


def numba_threads_here() -> int:
    """numba's thread count on the calling thread now (thread-local: a live session's relaxation
    sets its own, :func:`use_threads_in_this_thread`)."""
    import numba

    return int(numba.get_num_threads())


def worker_threads() -> int:
    """Threads for the numba kernels of a live session's workers (relaxation, rebase): one core
    fewer than :func:`configured_threads` (at least one), so that the threads that draw, serve
    OpenIGTLink and read poses keep a core.  On the 2-core machine, the hybrid knee session with
    the relaxation on two threads drew 26-27 fps with a pose-to-picture p95 of 234-478 ms, on one
    28.5-28.8 fps and 63-86 ms (``benchmarks/live.py --json --session knee.h5 --strokes one``)."""
    return max(1, configured_threads() - 1)


#: The nice value a live session's worker threads (relaxation, rebase) run at: where the machine's
#: cores are all busy, the threads that draw, send and feel get the processor first.
WORKER_NICE = 10


def yield_cpu_in_this_thread() -> bool:
    """Lower this thread's scheduling priority to :data:`WORKER_NICE` (Linux: per thread); returns
    whether it was set (other systems, or a priority already lower: left as it is).  Only on
    Linux, where a thread's id is in the process ids' space: elsewhere the same call would name
    another process, or none."""
    import sys
    import threading

    if not sys.platform.startswith("linux"):
        return False
    try:
        tid = threading.get_native_id()
        if os.getpriority(os.PRIO_PROCESS, tid) < WORKER_NICE:
            os.setpriority(os.PRIO_PROCESS, tid, WORKER_NICE)
            return True
    except (AttributeError, OSError):
        pass
    return False


def use_threads_in_this_thread(n: int) -> int:
    """Run this thread's numba kernels on ``n`` threads (at most numba's pool); returns the count."""
    import numba

    threads = max(1, min(int(n), int(numba.config.NUMBA_NUM_THREADS)))
    numba.set_num_threads(threads)
    return threads


def become_live_worker() -> int:
    """Make this thread one of a live session's workers (the relaxation, a rebase): its kernels on
    :func:`worker_threads` threads (numba's count is per thread) and its priority lowered
    (:func:`yield_cpu_in_this_thread`).  Returns the thread count."""
    threads = use_threads_in_this_thread(worker_threads())
    yield_cpu_in_this_thread()
    return threads


@contextlib.contextmanager
def threads_in_this_thread(n: int):
    """Run this thread's numba kernels on ``n`` threads for the block (:func:`use_threads_in_this_thread`),
    then on as many as before."""
    import numba

    before = int(numba.get_num_threads())
    use_threads_in_this_thread(n)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def configure_threads(n: int | None = None) -> int:
    """Set the number of numba threads for this process and return it.

    Parameters
    ----------
    n : int, optional
        Threads to use.  Without it, ``CUTKIT_THREADS`` when set, else
        :func:`default_threads`.  Never more than numba's thread pool
        (``NUMBA_NUM_THREADS``, by default the machine's cores).

    Returns
    -------
    threads : int
        The threads numba now uses.

    Raises
    ------
    InputError
        When ``n`` or ``CUTKIT_THREADS`` is not a whole number >= 1.
    """
    asked = parse_threads(n)
    if asked is None:
        asked = parse_threads(os.environ.get(ENV_VAR))
    if asked is None:
        asked = default_threads()
    global _configured
    threads = use_threads_in_this_thread(asked)
    _configured = threads
    return threads


@contextlib.contextmanager
def one_blas_thread():
    """Run the block with BLAS (OpenBLAS, MKL) on one thread.

    A threaded BLAS splits a dot product or a norm over its threads and adds
    the parts in an order that depends on how many there are, so the same
    solve gives different last bits on machines with different core counts,
    and a convergence test on those sums can then take another iteration.
    The solvers whose steps depend on such sums (projected Newton's
    conjugate gradients and residual norms) run inside this, so what they
    compute does not depend on the machine's cores (``tests/test_threads.py``).

    The BLAS libraries are looked up once per process (a lookup walks every
    loaded library: about 1 ms, several in a live session with the window's
    libraries loaded, on the thread a cut waits for); setting the limit then
    costs about 20 us.
    """
    global _blas
    if _blas is None:
        import scipy.linalg  # noqa: F401  scipy's own BLAS, loaded now so that the limit reaches it too
        from threadpoolctl import ThreadpoolController

        _blas = ThreadpoolController()
    with _blas.limit(limits=1, user_api="blas"):
        yield
