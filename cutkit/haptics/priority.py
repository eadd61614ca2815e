"""Scheduling priority of the haptic loop (the paper's "priority queue" control)."""

from __future__ import annotations

import logging
import os

from cutkit.errors import InputError

log = logging.getLogger("cutkit.haptics")

#: Nice value asked for by priority "high".
HIGH_NICE = -10
#: SCHED_FIFO priority asked for by priority "realtime" (1-99).
REALTIME_PRIORITY = 20
PRIORITIES = ("normal", "high", "realtime")
# mlockall flags (Linux)
MCL_CURRENT = 1
MCL_FUTURE = 2


def raise_priority(mode: str) -> str:
    """Raise this process's scheduling priority, as the paper's haptic server does.

    ``"high"`` lowers the nice value to ``HIGH_NICE``; ``"realtime"`` asks for
    SCHED_FIFO at ``REALTIME_PRIORITY`` (the loop sleeps most of each period,
    so it leaves the CPU to others) and locks the process's memory so that
    reclaimed pages cannot stall a tick.  Where the system refuses, the process
    keeps a lower priority.

    Returns
    -------
    str
        What was obtained: ``"realtime"``, ``"high"`` or ``"normal"``.
    """
    if mode not in PRIORITIES:
        raise InputError(f"unknown priority {mode!r} ({', '.join(PRIORITIES)})")
    if mode == "realtime" and hasattr(os, "sched_setscheduler"):
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(REALTIME_PRIORITY))
            _lock_memory()
            return "realtime"
        except (OSError, PermissionError):
            log.warning("SCHED_FIFO refused; trying a high nice priority instead")
            mode = "high"
    if mode == "high":
        try:
            current = os.nice(0)
            if current > HIGH_NICE:
                os.nice(HIGH_NICE - current)
            return "high"
        except (OSError, PermissionError):
            log.warning("a higher priority was refused; running at normal priority")
    return "normal"


def drop_priority() -> None:
    """Back to normal scheduling: SCHED_OTHER, nice 0 where it was lowered, memory unlocked.

    A process calls it when it leaves its 1 kHz loop: what it does next (a
    report, the interpreter's exit, 100 ms and more of work) would otherwise
    run at real-time priority and take a core from the processes beside it
    (a live session's frames stopped for 100-120 ms when the reference
    device's process exited at SCHED_FIFO).  Lowering a priority is always
    allowed; nothing is raised.
    """
    if hasattr(os, "sched_setscheduler"):
        try:
            if os.sched_getscheduler(0) != os.SCHED_OTHER:
                os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except (OSError, PermissionError):
            log.warning("could not leave real-time scheduling")
    try:
        current = os.nice(0)
        if current < 0:
            os.nice(-current)
    except (OSError, PermissionError):
        pass
    _unlock_memory()


def _libc_call(name: str, *args) -> bool:
    """libc's ``name(*args) == 0``; False where there is no such libc or function."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        return getattr(libc, name)(*args) == 0
    except (OSError, AttributeError):
        return False


def _unlock_memory() -> bool:
    """munlockall(): undo :func:`_lock_memory`."""
    return _libc_call("munlockall")


def _lock_memory() -> bool:
    """mlockall(): keep the process's pages in RAM so that no page fault stalls a tick."""
    return _libc_call("mlockall", MCL_CURRENT | MCL_FUTURE)
