"""The one place for JIT options.

``cache=True`` keeps compiled machine code on disk between processes, so the compile cost
(several seconds per kernel) is paid once per machine. ``fastmath`` is off: the kernels
compare log-densities across labels and a reordered reduction would change argmax ties.
The one exception is :data:`jit_contract` for the neighbour-distance loop: it only allows
fused multiply-add (``contract``), which rounds once instead of twice; the compiled code is
the same for every thread count, so results stay bit-identical across threads (measured
speed-up in docs/performance.md).

:data:`jit_inline` is :data:`jit` for the helpers a parallel loop calls per voxel or site with
arrays: numba inlines them into the caller, where the reference counts of their array
arguments cancel; as separate functions every call took and released a reference to each array
(two atomic operations on memory the threads share), a fifth of the solver's time. The same
operations in the same order, so the same bits.
"""

from __future__ import annotations

import hashlib
import os
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

from .._cache_folders import private_temp_folder, writable_folder
from ..errors import ParameterError


def thread_setting_problem(text: str | None) -> str | None:
    """One line about a ``NUMBA_NUM_THREADS`` value numba cannot start with (0, negative, not a
    number), else None."""
    if text is None or not text.strip():
        return None
    try:
        threads = int(text)
    except ValueError:
        threads = 0
    if threads >= 1:
        return None
    return (f"the environment variable NUMBA_NUM_THREADS must be a positive integer (the threads "
            f"of the compiled loops); got {text!r}: unset it or set it to 1 or more")


#: What is wrong with this process's ``NUMBA_NUM_THREADS`` (None: nothing). numba would fail at
#: import with a traceback, so the value is taken out of the environment before numba is
#: imported, and every run refuses to start with this message (:func:`check_thread_setting`).
THREAD_SETTING_PROBLEM = thread_setting_problem(os.environ.get("NUMBA_NUM_THREADS"))
if THREAD_SETTING_PROBLEM is not None:
    del os.environ["NUMBA_NUM_THREADS"]

import numba  # noqa: E402  (after the check above)
import scipy.linalg.cython_blas  # noqa: E402, F401  (loads the BLAS that np.dot in a kernel calls,

# so that threadpoolctl finds it and limits it: see single_threaded_blas)
from threadpoolctl import threadpool_limits  # noqa: E402


def check_thread_setting() -> None:
    """Raise :class:`~npmrf3d.errors.ParameterError` if ``NUMBA_NUM_THREADS`` was unusable."""
    if THREAD_SETTING_PROBLEM is not None:
        raise ParameterError(THREAD_SETTING_PROBLEM)


def _default_cache_dir() -> str:
    """Per-user folder for numba's compiled-code cache: ``$NUMBA_CACHE_DIR`` if set, else
    ``$XDG_CACHE_HOME/npmrf3d/numba`` (``~/.cache/npmrf3d/numba``).

    Never the installed package: numba's default writes ``__pycache__`` folders beside the
    sources, and a later editable install leaves ``site-packages/npmrf3d/_kernels/__pycache__``
    behind as a namespace package that shadows the real one.
    """
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return str(Path(base) / "npmrf3d" / "numba")


def kernel_sources_digest(folder: Path = Path(__file__).parent) -> str:
    """The first 12 hex digits of the SHA-256 of the compiled kernels' sources (every ``.py``
    file of ``folder``, this package, by name then content).

    numba's disk cache checks only the source file of the kernel it loads, not those of the
    functions compiled into it: a kernel that inlines a helper of another module would keep the
    helper's old machine code after that module changed (an upgrade, or an edited checkout).
    The cache therefore lives in a folder of this digest (:func:`_cache_dir`), and kernels whose
    sources changed in any way are compiled afresh.
    """
    digest = hashlib.sha256()
    for path in sorted(Path(folder).glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:12]


#: The cache's subfolder for these kernel sources (:func:`kernel_sources_digest`).
SOURCES_FOLDER = f"kernels-{kernel_sources_digest()}"


def _cache_dir() -> str | None:
    """The folder for numba's cache: the subfolder :data:`SOURCES_FOLDER` of
    ``$NUMBA_CACHE_DIR`` or :func:`_default_cache_dir` when it can be written, else of a private
    folder in the temporary folder, else None (no cache: numba raises when a kernel is decorated
    if it finds no writable cache folder at all). A ``$NUMBA_CACHE_DIR`` that already names that
    subfolder (a worker process inherits its parent's) is used as it is.
    """
    chosen = os.environ.get("NUMBA_CACHE_DIR") or _default_cache_dir()
    base = chosen if writable_folder(chosen) else private_temp_folder("numba")
    if base is None or Path(base).name == SOURCES_FOLDER:
        return base
    inner = os.path.join(base, SOURCES_FOLDER)
    return inner if writable_folder(inner) else None


# Read by numba when each decorated function is created (its cache locator), so setting it here,
# before any kernel module decorates a function, is enough even if numba was imported earlier;
# the environment variable carries the choice to worker processes (dask) too.
CACHE_DIR = _cache_dir()
if CACHE_DIR is not None and CACHE_DIR != os.environ.get("NUMBA_CACHE_DIR"):
    os.environ["NUMBA_CACHE_DIR"] = CACHE_DIR
    numba.config.CACHE_DIR = CACHE_DIR

JIT_OPTIONS = {"cache": CACHE_DIR is not None, "fastmath": False, "nogil": True}

jit = numba.njit(**JIT_OPTIONS)
jit_parallel = numba.njit(parallel=True, **JIT_OPTIONS)
jit_inline = numba.njit(inline="always", **JIT_OPTIONS)
jit_contract = numba.njit(**{**JIT_OPTIONS, "fastmath": {"contract"}})
prange = numba.prange


class SerialParallel(NamedTuple):
    """One kernel in two compiled forms from one definition (:func:`serial_and_parallel`):
    ``serial`` runs in the calling thread, ``parallel`` on numba's threads; same result."""

    serial: Callable
    parallel: Callable


def serial_and_parallel(define: Callable[[Callable], Callable]) -> SerialParallel:
    """Compile the kernel ``define(loop)`` twice: with ``loop = range`` by :data:`jit` and with
    ``loop = prange`` by :data:`jit_parallel` (``define`` returns a function whose parallel loop
    is ``for x in loop(n)``).

    Each form is its own entry in numba's disk cache: the cache key of a closure includes the
    contents of its cells (``range`` or ``prange``), not the ``parallel`` flag.
    """
    return SerialParallel(jit(define(range)), jit_parallel(define(prange)))


def use_threads(threads: int | None) -> int:
    """Let numba's parallel loops use ``threads`` threads (capped at the pool size; None: keep
    the current setting); return the number in use."""
    if threads is not None:
        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    return thread_count()


def thread_count() -> int:
    """Number of threads numba's parallel loops use in this process."""
    check_thread_setting()
    return int(numba.get_num_threads())


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run BLAS (numpy's and scipy's OpenBLAS, which ``np.dot`` in a kernel calls) on one thread
    inside the block; the previous limits come back afterwards.

    The batched-distance kernels (:mod:`npmrf3d._kernels.gemm`) call ``sgemm`` once per block of
    sites from numba's parallel threads: the parallelism is theirs, a fixed partition of the
    sites, and each call must be the same single-threaded product whatever the thread count
    (OpenBLAS's own threads would also oversubscribe the cores).
    """
    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _package_kernel(dispatcher) -> bool:
    """Whether a dispatcher numba compiles is one of this package's kernels (not one of numba's
    own helpers, compiled as part of a kernel)."""
    module = getattr(getattr(dispatcher, "py_func", None), "__module__", None) or ""
    return module.split(".", 1)[0] == __name__.split(".", 1)[0]


class CompileClock:
    """Seconds spent compiling the package's kernels while it is installed
    (:func:`timing_compiles`), the compilation under way included; a kernel compiled inside
    another counts once."""

    def __init__(self):
        self._done, self._since, self._depth = 0.0, None, 0

    @property
    def seconds(self) -> float:
        since = self._since
        return self._done + (time.perf_counter() - since if since is not None else 0.0)

    def on_start(self, ev) -> None:
        if _package_kernel(ev.data.get("dispatcher")):
            self._depth += 1
            if self._depth == 1:
                self._since = time.perf_counter()

    def on_end(self, ev) -> None:
        if _package_kernel(ev.data.get("dispatcher")) and self._depth > 0:
            self._depth -= 1
            if self._depth == 0 and self._since is not None:
                self._done += time.perf_counter() - self._since
                self._since = None


@contextmanager
def timing_compiles() -> Iterator[CompileClock]:
    """A :class:`CompileClock` over the block (nothing is compiled on a warm cache: it stays 0)."""
    from numba.core import event

    clock = CompileClock()
    listener = type("CompileListener", (event.Listener,),
                    {"on_start": lambda self, ev: clock.on_start(ev),
                     "on_end": lambda self, ev: clock.on_end(ev)})()
    with event.install_listener("numba:compile", listener):
        yield clock


@contextmanager
def on_first_compile(callback: Callable[[], None]) -> Iterator[None]:
    """Call ``callback()`` once, when the first of the package's kernels is compiled inside the
    block: a kernel that numba's disk cache (:data:`CACHE_DIR`) does not hold yet (the first run
    on a machine or after an upgrade, about a minute for a run of the default).

    numba announces a compilation (its ``numba:compile`` event) and not a kernel loaded from
    the cache, so a warm run calls nothing and pays nothing but one listener in a list.
    """
    from numba.core import event

    fired = threading.Event()

    class FirstCompile(event.Listener):
        def on_start(self, ev):
            if not fired.is_set() and _package_kernel(ev.data.get("dispatcher")):
                fired.set()
                callback()

        def on_end(self, ev):
            pass

    with event.install_listener("numba:compile", FirstCompile()):
        yield
