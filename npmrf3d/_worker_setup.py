"""Run by every worker process of :func:`npmrf3d._cluster.local_cluster` as it starts (a Dask
preload: ``dask_setup``), so that Ctrl-C ends a study with one line.

Ctrl-C reaches every process of the terminal's process group, the workers too. The parent
handles it: it stops waiting, cancels the runs and closes the cluster. A worker that handled it
as well would die with a ``KeyboardInterrupt`` traceback on stderr, and a worker closed while a
run goes on logs "Async instruction ... ended with CancelledError"; both describe the
interruption the command already reports. So a worker ignores SIGINT (the parent closes it) and
drops that one warning.
"""

from __future__ import annotations

import logging
import signal
import threading

__all__ = ["dask_setup"]


class _CancelledFilter(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return "ended with CancelledError" not in record.getMessage()


def dask_setup(worker=None) -> None:
    """Ignore SIGINT in this worker process and quiet its cancellation warning."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    logger = logging.getLogger("distributed.worker.state_machine")
    if not any(isinstance(f, _CancelledFilter) for f in logger.filters):
        logger.addFilter(_CancelledFilter())
