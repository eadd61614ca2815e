"""Stop requests (Ctrl-C, SIGTERM) delivered at a loop's safe points.

A signal handler runs between two bytecodes of the main thread, wherever that
is: an exception raised there can leave a half-made update behind (a force
row counted but not stored, a cut mesh between two of its arrays), and the
recording written on the way out then reads it.  The run loops
(``simulate``'s replay, the live session) therefore declare
:func:`safe_points`: while one is active, a handler calls
:func:`request_stop` instead of raising, and the loop raises the stop at its
next :func:`check_stop`, between two ticks, where every array is whole.

Outside such a loop (a model build, a settle before the first tick) there
is nothing half-written that a recording would read, and the handler raises
at once, as before.  A second request while one waits is raised at once too:
a user who presses Ctrl-C twice does not wait for a slow safe point.

The library never installs a signal handler; the command line does.
"""

from __future__ import annotations

from contextlib import contextmanager

__all__ = ["Terminated", "safe_points", "request_stop", "check_stop"]


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised on the main thread: it takes every path Ctrl-C takes (recordings are closed)."""


#: Signal handlers and the loops both run on the main thread, one at a time: no lock is needed
#: (and a handler must never wait for one the interrupted code holds).
_state = {"depth": 0, "pending": None}


@contextmanager
def safe_points():
    """Within this context a stop request waits for :func:`check_stop`.

    A stop still waiting when the context ends (the loop ended on its own
    between the request and its next check) is raised on leaving it.
    """
    _state["depth"] += 1
    try:
        yield
    except BaseException:
        _leave()
        raise
    pending = _leave()
    if pending is not None:
        raise pending()


def _leave():
    """Leave one level of :func:`safe_points`; the request still waiting when the last one ends."""
    _state["depth"] -= 1
    if _state["depth"]:
        return None
    pending, _state["pending"] = _state["pending"], None
    return pending


def request_stop(exc_type: type[KeyboardInterrupt]) -> bool:
    """Ask the running loop to stop with ``exc_type`` at its next safe point.

    Returns
    -------
    deferred : bool
        True when a loop with safe points will raise it; False when the caller
        (a signal handler) should raise it itself: no such loop runs, or a
        request already waits.
    """
    if _state["depth"] == 0 or _state["pending"] is not None:
        return False
    _state["pending"] = exc_type
    return True


def check_stop() -> None:
    """A safe point: raise the stop request that waits, if any."""
    pending = _state["pending"]
    if pending is not None:
        _state["pending"] = None
        raise pending()
