"""Ctrl-C and SIGTERM that a run cannot lose.

Python turns SIGINT into ``KeyboardInterrupt`` at the next bytecode of the main thread. When
that bytecode runs inside a callback from C -- numba compiling (llvmlite's ctypes callbacks),
numba loading cached code -- the exception is printed as "Exception ignored on calling ctypes
callback function" and dropped: the run went on and, seen once in CI, exited 0 after its
SIGINT (or 1 with a cold cache). Here the handler also *latches* the signal: every progress
tick (:class:`npmrf3d.cli._progress.LevelProgress`) and the end of every run call :func:`check`,
which raises ``KeyboardInterrupt`` again while the latch is set, so a swallowed interrupt still
ends the run at its next step with exit 130 and nothing written. Python reports such a dropped
exception through :func:`sys.unraisablehook` ("Exception ignored in ..." and a traceback on
stderr); while the latch is set, :func:`install`'s hook keeps those quiet, since the interrupt
is not lost (the one line of the interruption follows). An interrupt that lands inside the
compiler can also leave one of llvmlite's objects half-built, whose finalizer then fails when
the process exits ("Exception ignored in: ObjectRef.__del__ ... AttributeError"); while the
latch is set the hook keeps those quiet too, and once a run was interrupted, :func:`restore`
collects the garbage and leaves a hook that keeps those quiet, and only those.

The command line installs this handling first thing (:func:`npmrf3d.cli.main.main`) and the
``npmrf3d`` process before it imports the command line (:mod:`npmrf3d.__main__`), so that a
Ctrl-C at any moment is one line and exit code 130.
"""

from __future__ import annotations

import gc
import signal
import sys
import threading

__all__ = ["check", "install", "interrupt", "pending", "restore"]

#: The signals a run treats as Ctrl-C.
SIGNALS = (signal.SIGINT, signal.SIGTERM)

_latched = threading.Event()
#: Packages whose objects' finalizers may fail after an interrupt cut their construction short.
COMPILER_PACKAGES = ("llvmlite", "numba")


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


def _quiet_dropped_interrupts(unraisable, *, fallback=None):
    """``sys.unraisablehook``: while the latch is set, say nothing of a dropped
    ``KeyboardInterrupt`` (it will be raised again) nor of the compiler's failing finalizers
    (an object the interrupt left half-built, freed with the interrupt's traceback before
    :func:`restore` runs); pass everything else to ``fallback``."""
    if _latched.is_set() and (issubclass(unraisable.exc_type, KeyboardInterrupt) or _from_compiler(unraisable)):
        return
    (fallback or sys.__unraisablehook__)(unraisable)


def _from_compiler(unraisable) -> bool:
    """Whether an unraisable exception comes from a function or object of the compiler."""
    module = getattr(unraisable.object, "__module__", None) or type(unraisable.object).__module__
    return isinstance(module, str) and module.split(".", 1)[0] in COMPILER_PACKAGES


def _quiet_compiler_finalizers(unraisable, *, fallback=None):
    """``sys.unraisablehook`` after an interrupted run: say nothing of the compiler's failing
    finalizers; pass everything else to ``fallback``."""
    if _from_compiler(unraisable):
        return
    (fallback or sys.__unraisablehook__)(unraisable)


def install() -> dict | None:
    """Clear the latch, handle :data:`SIGNALS` with :func:`interrupt` and keep dropped
    interrupts quiet; return what was replaced, for :func:`restore` (None off the main thread,
    where signals cannot be handled)."""
    _latched.clear()
    if threading.current_thread() is not threading.main_thread():
        return None
    previous = {s: signal.signal(s, interrupt) for s in SIGNALS}
    hook = sys.unraisablehook
    previous["unraisablehook"] = hook
    sys.unraisablehook = lambda unraisable: _quiet_dropped_interrupts(unraisable, fallback=hook)
    return previous


def restore(previous: dict | None) -> None:
    """Put back what :func:`install` replaced and clear the latch; after an interrupt, the
    garbage is collected first (objects the interrupt left half-built, in cycles, are freed now,
    quietly, not at exit; a second signal meanwhile is ignored: the run is already ending) and
    the hook put back keeps the compiler's failing finalizers quiet
    (:func:`_quiet_compiler_finalizers`)."""
    previous = dict(previous or {})
    interrupted = _latched.is_set()
    if interrupted:
        for s in SIGNALS:
            if s in previous:
                signal.signal(s, signal.SIG_IGN)
        gc.collect()
    _latched.clear()
    if "unraisablehook" in previous:
        hook = previous.pop("unraisablehook")
        sys.unraisablehook = (hook if not interrupted else
                              lambda unraisable: _quiet_compiler_finalizers(unraisable, fallback=hook))
    for s, handler in previous.items():
        signal.signal(s, handler)
