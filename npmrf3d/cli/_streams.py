"""Standard output and standard error that a command outlives.

A command's words are never its work: a run whose stderr is closed (``2>&-``) or full
(``2>/dev/full``) still writes its output folder, and a run whose stdout went away still exits 0.
While :func:`guard_streams` is active, ``sys.stdout`` and ``sys.stderr`` are
:class:`TolerantStream` wrappers: a write that fails (closed, full, a reader that hung up) is
dropped, the stream's descriptor is pointed at the null device (so the interpreter's last flush
at exit fails no more), and the loss is remembered. A stream closed before the command started
gets the null device too, and its descriptor is filled, so that no file the command opens later
takes the number 1 or 2 and receives what was meant for the terminal.

Only the commands whose whole purpose is to print (``info``, ``--dry-run``) end with a non-zero
exit code when their output was lost (:func:`stdout_lost`).
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys
from collections.abc import Iterator

__all__ = ["TolerantStream", "guard_streams", "lost_reason"]

#: The standard streams by name and descriptor.
_STREAMS = (("stdout", 1), ("stderr", 2))


class TolerantStream:
    """A text stream whose failed writes are dropped and remembered (``lost``: the error, or
    None while every write went through); ``fd``: the descriptor it writes to (pointed at the
    null device after a failure; None: none). Everything else is the wrapped stream's."""

    def __init__(self, stream, fd: int | None, lost: OSError | None = None):
        self._stream, self._fd, self.lost = stream, fd, lost

    def write(self, text: str) -> int:
        if self.lost is None:
            try:
                self._stream.write(text)
            except (OSError, ValueError) as exc:
                self._lose(exc)
        return len(text)

    def flush(self) -> None:
        if self.lost is None:
            try:
                self._stream.flush()
            except (OSError, ValueError) as exc:
                self._lose(exc)

    def _lose(self, exc: Exception) -> None:
        """Remember the failure and point the descriptor at the null device, where whatever is
        still buffered (or written by a library that holds the old stream) goes quietly."""
        self.lost = exc if isinstance(exc, OSError) else OSError(errno.EBADF, "the stream is closed")
        if self._fd is not None:
            _fill_with_null(self._fd, replace=True)

    def isatty(self) -> bool:
        try:
            return self.lost is None and self._stream.isatty()
        except (OSError, ValueError):
            return False

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _fill_with_null(fd: int, *, replace: bool = False) -> None:
    """Open the null device as descriptor ``fd`` if that number is free (``replace``: even if
    it is taken)."""
    if not replace:
        try:
            os.fstat(fd)
            return  # taken: by the stream, or by a file opened before this check
        except OSError:
            pass
    try:
        null = os.open(os.devnull, os.O_WRONLY)
    except OSError:
        return
    if null != fd:
        try:
            os.dup2(null, fd)
        except OSError:
            pass
        os.close(null)


def _descriptor(stream) -> int | None:
    """The descriptor a stream writes to (None for one in memory, e.g. a test's capture)."""
    try:
        return stream.fileno()
    except (AttributeError, OSError, ValueError):
        return None


def _null_stream():
    return open(os.devnull, "w", encoding="utf-8")  # noqa: SIM115 (lives as long as the process)


@contextlib.contextmanager
def guard_streams() -> Iterator[dict[str, TolerantStream]]:
    """Wrap ``sys.stdout`` and ``sys.stderr`` in :class:`TolerantStream` for the block (the
    previous objects come back afterwards); yields them by name. A stream that was closed when
    the process started (``None``) is the null device, lost from the start."""
    previous = {name: getattr(sys, name) for name, _ in _STREAMS}
    guarded = {}
    for name, fd in _STREAMS:
        stream = previous[name]
        if isinstance(stream, TolerantStream):  # nested (a command run by a command)
            guarded[name] = stream
            continue
        if stream is None:
            _fill_with_null(fd)
            guarded[name] = TolerantStream(_null_stream(), fd,
                                           lost=OSError(errno.EBADF, "Bad file descriptor"))
        else:
            guarded[name] = TolerantStream(stream, _descriptor(stream))
        setattr(sys, name, guarded[name])
    try:
        yield guarded
    finally:
        for stream in guarded.values():
            stream.flush()
        for name, _ in _STREAMS:
            setattr(sys, name, previous[name])


def lost_reason(stream: TolerantStream) -> str | None:
    """Why ``stream``'s output was lost, in a few words (None: it was not; ``""``: the reader
    hung up, which tools do not report)."""
    if stream.lost is None:
        return None
    if stream.lost.errno == errno.EPIPE or isinstance(stream.lost, BrokenPipeError):
        return ""
    return stream.lost.strerror or str(stream.lost)
