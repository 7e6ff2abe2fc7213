"""Dask for the studies (:mod:`npmrf3d.studies.runner`) and the executor of Zarr volumes made in
blocks (:func:`npmrf3d.io.zarr_blocks.write_volume`): the one place that starts local clusters, sizes them
(:func:`plan_workers`), checks a scheduler address (:func:`check_scheduler`,
:func:`probe_scheduler`) and connects to one (:func:`dask_client`). Dask is imported only when a
cluster starts or a client connects.

Why the workers' allocator is set here: both users start worker processes whose memory allocator
needs one setting before the process exists. Dask's Nanny sets ``MALLOC_TRIM_THRESHOLD_`` in
every worker's environment before spawning it (``distributed.nanny.pre-spawn-environ``); setting
any of glibc's ``MALLOC_*_THRESHOLD_`` variables turns off glibc's dynamic mmap threshold, so
every allocation above 128 KiB is then a fresh ``mmap`` whose pages the kernel zeroes on first
touch, and freed at once. Measured on the neural generator (a 128^3 block, one thread, AMD
EPYC): 6.9 s per block with 2.9 s of it in the kernel under Dask's setting, 4.3 s (0.4 s kernel)
with the mmap threshold raised as here, 4.5 s (0.7 s) with glibc's defaults; a 1024^3 Zarr
volume spent 41 % of its CPU time in the kernel. So the workers get glibc's largest mmap
threshold (32 MiB): blocks below it come from the heap and are reused.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import threading
from collections.abc import Iterator

from .errors import ParameterError

__all__ = ["CONNECT_TIMEOUT", "ClusterStart", "MMAP_THRESHOLD", "check_scheduler", "dashboard_link", "dask_client",
           "local_cluster", "plan_workers", "probe_scheduler"]

#: glibc's largest ``M_MMAP_THRESHOLD`` on 64-bit Linux (``DEFAULT_MMAP_THRESHOLD_MAX``), bytes.
MMAP_THRESHOLD = 32 * 2 ** 20

#: BLAS and OpenMP thread counts in every worker (each run or task sets its own threads).
_SINGLE_THREADED = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

#: Seconds to wait for an existing Dask scheduler before giving up.
CONNECT_TIMEOUT = 5
#: What every worker of :func:`local_cluster` runs as it starts (:mod:`npmrf3d._worker_setup`:
#: Ctrl-C is the parent's to handle, and an interruption is said in one line).
WORKER_PRELOAD = "npmrf3d._worker_setup"
#: Address schemes of dask.distributed's communication back-ends.
_SCHEMES = ("tcp", "tls", "ucx", "inproc", "ws", "wss")


def local_cluster(workers: int, *, dashboard_address=":0", silence_logs=logging.WARNING):
    """A ``distributed.LocalCluster`` of ``workers`` processes with one Dask thread each, BLAS
    single-threaded, the allocator setting above in every worker's environment and
    :data:`WORKER_PRELOAD` run in every worker.

    The numba thread count is not put in the workers' environment as ``NUMBA_NUM_THREADS``: a
    spawned worker imports the parent's main module (a study script imports numba) before the
    Nanny's environment is applied, so numba's pool would be sized already and the first
    compilation in the worker (a fresh install, an empty cache) would fail with "Cannot set
    NUMBA_NUM_THREADS to a different value once the threads have been launched". Each task sets
    its numba threads itself (a study's run calls ``use_threads``) and BLAS runs single-threaded
    inside the kernels (``single_threaded_blas``).
    """
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": MMAP_THRESHOLD}):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            dashboard_address=dashboard_address, silence_logs=silence_logs,
                            env=dict(_SINGLE_THREADED), preload=[WORKER_PRELOAD])


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int = 1) -> Iterator:
    """A ``distributed.Client`` of a new :func:`local_cluster` of ``workers`` processes
    (``scheduler`` None) or of the scheduler at the address ``scheduler`` (ParameterError when
    it does not answer within :data:`CONNECT_TIMEOUT`); the client, and the cluster it started,
    are closed on leaving."""
    from distributed import Client

    cluster = client = None
    stopped = True
    try:
        if scheduler is None:
            cluster = local_cluster(workers)
            client = Client(cluster)
        else:
            try:
                client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT}s")
            except (OSError, TimeoutError) as exc:
                raise ParameterError(f"cannot connect to the Dask scheduler {scheduler}: "
                                     f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        yield client
        stopped = False
    finally:
        # After Ctrl-C (or an error) the runs still going are cancelled and their workers
        # killed: that is the interruption itself, which the caller says in one line, so the
        # cluster's warnings and errors about it ("... still alive after 4.0 seconds, killing",
        # a CancelledError traceback) stay quiet.
        with _quiet(stopped):
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()


class ClusterStart:
    """:func:`dask_client` entered in a background thread, so that a local cluster's workers
    start while this process goes on working (a Zarr run's first block, which makes what every
    other block reads): :meth:`client` waits for the client (raising what its start raised), and
    leaving the ``with`` block closes it as :func:`dask_client` does, started or not."""

    def __init__(self, scheduler: str | None, workers: int = 1):
        self._context = dask_client(scheduler, workers)
        self._client = self._error = None
        self._thread = threading.Thread(target=self._enter, name="npmrf3d-cluster-start", daemon=True)
        self._thread.start()

    def _enter(self) -> None:
        try:
            self._client = self._context.__enter__()
        except BaseException as exc:  # noqa: BLE001 -- raised again in the caller's thread
            self._error = exc

    def client(self):
        """The client, once the cluster is up."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._client

    def __enter__(self) -> "ClusterStart":
        return self

    def __exit__(self, exc_type, exc, tb) -> bool:
        self._thread.join()
        if self._client is None:
            return False
        return bool(self._context.__exit__(exc_type, exc, tb))


@contextlib.contextmanager
def _quiet(quiet: bool = True) -> Iterator[None]:
    """Nothing of the ``distributed`` loggers in this process for a while (``quiet``)."""
    logger = logging.getLogger("distributed")
    previous = logger.level
    if quiet:
        logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(previous)


def dashboard_link(client) -> str:
    """The client's dashboard address, saying so when it is not served (bokeh missing)."""
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return f"{client.dashboard_link} (not served: install bokeh to see it)"
    return str(client.dashboard_link)


def plan_workers(workers: int | None, threads: int | None, cores: int | None = None) -> tuple[int, int]:
    """(workers, numba threads per worker) with ``workers * threads <= cores``.

    >>> plan_workers(None, None, 8)
    (8, 1)
    >>> plan_workers(2, None, 8)
    (2, 4)
    >>> plan_workers(None, 3, 8)
    (2, 3)
    """
    cores = max(1, int(cores or os.cpu_count() or 1))
    if workers is not None and workers < 1:
        raise ParameterError(f"--workers must be a positive integer; got {workers}")
    if threads is not None and threads < 1:
        raise ParameterError(f"--threads must be a positive integer; got {threads}")
    if workers is None:
        threads = 1 if threads is None else threads
        workers = max(1, cores // threads)
    elif threads is None:
        threads = max(1, cores // workers)
    if workers * threads > cores:
        raise ParameterError(f"{workers} workers x {threads} numba threads exceed the {cores} "
                             f"cores of this machine; use fewer --workers or --threads")
    return workers, threads


def check_scheduler(scheduler):
    """None, ``local``, ``serial`` or ``SCHEME://HOST:PORT`` (ParameterError otherwise)."""
    if scheduler is None or scheduler in ("local", "serial"):
        return scheduler
    text = str(scheduler)
    scheme, sep, rest = text.partition("://")
    host, colon, port = rest.rpartition(":")
    if not sep or scheme not in _SCHEMES or not host or not colon or not port.isdigit() \
            or not 0 < int(port) < 65536:
        raise ParameterError(f"--scheduler must be 'local', 'serial' or a Dask scheduler address "
                             f"such as tcp://HOST:8786; got {text!r}")
    return text


def probe_scheduler(address: str, timeout: float | None = None) -> None:
    """Fail fast (ParameterError) when nothing listens at a ``tcp://`` or ``tls://`` address."""
    scheme, _, rest = address.partition("://")
    if scheme not in ("tcp", "tls"):
        return
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout or CONNECT_TIMEOUT):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise ParameterError(f"cannot reach the Dask scheduler {address}: {reason}; start one "
                             f"with 'dask scheduler' or use --scheduler local") from None
