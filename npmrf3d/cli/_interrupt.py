"""Ctrl-C and SIGTERM that a run cannot lose.

Python turns SIGINT into ``KeyboardInterrupt`` at the next bytecode of the main thread. When
that bytecode runs inside a callback from C -- numba compiling (llvmlite's ctypes callbacks),
numba loading cached code -- the exception is printed as "Exception ignored on calling ctypes
callback function" and dropped: the run went on and, seen once in CI, exited 0 after its
SIGINT (or 1 with a cold cache). Here the handler also *latches* the signal: every progress
tick (:class:`npmrf3d.cli._common.LevelProgress`) and the end of every run call :func:`check`,
which raises ``KeyboardInterrupt`` again while the latch is set, so a swallowed interrupt still
ends the run at its next step with exit 130 and nothing written.
"""

from __future__ import annotations

import signal
import threading

__all__ = ["check", "install", "interrupt", "pending", "restore"]

#: The signals a run treats as Ctrl-C.
SIGNALS = (signal.SIGINT, signal.SIGTERM)

_latched = threading.Event()


def interrupt(signum=None, frame=None):
    """The signal handler: latch the interrupt, then raise ``KeyboardInterrupt``."""
    _latched.set()
    raise KeyboardInterrupt


def pending() -> bool:
    """Whether an interrupt arrived since :func:`install`."""
    return _latched.is_set()


def check() -> None:
    """Raise ``KeyboardInterrupt`` if an interrupt arrived (even one that was swallowed)."""
    if _latched.is_set():
        raise KeyboardInterrupt


def install() -> dict | None:
    """Clear the latch and handle :data:`SIGNALS` with :func:`interrupt`; return the previous
    handlers for :func:`restore` (None off the main thread, where signals cannot be handled)."""
    _latched.clear()
    if threading.current_thread() is not threading.main_thread():
        return None
    return {s: signal.signal(s, interrupt) for s in SIGNALS}


def restore(previous: dict | None) -> None:
    """Put back the handlers :func:`install` replaced and clear the latch."""
    _latched.clear()
    for s, handler in (previous or {}).items():
        signal.signal(s, handler)
