"""The one place for JIT options (STYLE.md practice 8).

``cache=True`` keeps compiled machine code on disk between processes, so the compile cost
(several seconds per kernel) is paid once per machine. ``fastmath`` is off: the kernels
compare log-densities across labels and a reordered reduction would change argmax ties.
The one exception is :data:`jit_contract` for the neighbour-distance loop: it only allows
fused multiply-add (``contract``), which rounds once instead of twice; the compiled code is
the same for every thread count, so results stay bit-identical across threads (measured
speed-up in docs/quality.md).
"""

from __future__ import annotations

import numba

JIT_OPTIONS = {"cache": True, "fastmath": False, "nogil": True}

jit = numba.njit(**JIT_OPTIONS)
jit_parallel = numba.njit(parallel=True, **JIT_OPTIONS)
jit_contract = numba.njit(**{**JIT_OPTIONS, "fastmath": {"contract"}})
prange = numba.prange


def use_threads(threads: int | None) -> int:
    """Let numba's parallel loops use ``threads`` threads (capped at the pool size; None: keep
    the current setting); return the number in use."""
    if threads is not None:
        numba.set_num_threads(max(1, min(int(threads), numba.config.NUMBA_NUM_THREADS)))
    return thread_count()


def thread_count() -> int:
    """Number of threads numba's parallel loops use in this process."""
    return int(numba.get_num_threads())
