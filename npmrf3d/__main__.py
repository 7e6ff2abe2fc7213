"""The ``npmrf3d`` process: ``python -m npmrf3d`` and the ``npmrf3d`` console script.

Ctrl-C (or SIGTERM) at any moment of the process is one line and exit code 130, also during
the first second, while numpy, numba, scipy and matplotlib are imported: :func:`main` handles
both signals before it imports the command line. That is why this module imports the command
line inside :func:`main` (through ``importlib``, like the package's other deferred imports) and
nothing heavy at its top; ``import npmrf3d`` imports no public name until it is used. Once the
command line runs, its own handling takes over (:mod:`npmrf3d.cli._interrupt`); once the
command has returned, the process only exits, and a late signal no longer interrupts that exit
(its cleanup included).
"""

from __future__ import annotations

import importlib
import os
import signal
import sys

__all__ = ["main"]

#: The signals a run treats as Ctrl-C (those of :mod:`npmrf3d.cli._interrupt`).
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: The exit code of an interrupted command.
INTERRUPTED = 130

_latched: list[int] = []


def _interrupt(signum=None, frame=None):
    """The signal handler until the command line installs its own: remember, then raise."""
    _latched.append(signum)
    raise KeyboardInterrupt


def _quiet_while_interrupted(unraisable, *, fallback) -> None:
    """``sys.unraisablehook``: once interrupted, the exceptions Python cannot raise (an interrupt
    dropped inside a callback from C, a finalizer of a module whose import it cut short) are
    the interruption's, which its one line reports; before, as ``fallback`` shows them."""
    if not _latched:
        fallback(unraisable)


def _interrupted(what: str) -> int:
    """Say ``what`` (unless standard error is closed); the exit code of an interruption."""
    try:
        sys.stderr.write(f"npmrf3d: {what}\n")
        sys.stderr.flush()
    except (AttributeError, OSError, ValueError):
        pass
    return INTERRUPTED


def _interrupted_while_importing() -> None:
    """End the process at once, exit code 130: an interrupt inside an extension module's import
    can leave it half-initialised, and the interpreter's finalisation then aborts ("Fatal Python
    error: PyThreadState_Get") or reports the interrupt as unhandled (the process killed by
    SIGINT, not exit code 130). Nothing of the command exists yet, so nothing is left behind."""
    _interrupted("interrupted before the command started; nothing was written")
    try:
        sys.stdout.flush()
    except (AttributeError, OSError, ValueError):
        pass
    os._exit(INTERRUPTED)


def main(argv: list[str] | None = None) -> int:
    """Run the command line with the signals handled from its first moment; return the exit code."""
    previous = sys.unraisablehook
    sys.unraisablehook = lambda unraisable: _quiet_while_interrupted(unraisable, fallback=previous)
    started = False
    try:
        for signum in SIGNALS:
            signal.signal(signum, _interrupt)
        command_line = importlib.import_module("npmrf3d.cli.main").main

        if _latched:  # an interrupt that the import swallowed
            raise KeyboardInterrupt
        started = True
        return command_line(argv)
    except BaseException as exc:
        # an interrupt inside an extension's import (numpy's) comes back as that import's error
        if not isinstance(exc, KeyboardInterrupt) and not (_latched and isinstance(exc, Exception)):
            raise
        if not started:
            _interrupted_while_importing()
        return _interrupted("interrupted")  # in the few steps around the command line's own handling
    finally:
        for signum in SIGNALS:  # what remains is the exit and its cleanup
            signal.signal(signum, signal.SIG_IGN)


if __name__ == "__main__":
    raise SystemExit(main())
