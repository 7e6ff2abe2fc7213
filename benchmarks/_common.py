"""Shared helpers for the benchmark scripts: hardware line and a float32 matmul reference."""

from __future__ import annotations

import contextlib
import os
import platform
import time

import numpy as np


def hardware() -> str:
    """One line: CPU model, cores, numba threads."""
    import numba

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}; {os.cpu_count()} cores; numba threads {numba.get_num_threads()}"


def matmul_gflops(n: int = 1024, repeats: int = 5, *, clock=time.perf_counter,
                  blas=contextlib.nullcontext) -> float:
    """Best float32 ``n x n`` matrix-multiply rate of this machine, in GFLOP/s, timed with
    ``clock`` (wall time by default; ``time.thread_time`` gives one core's rate per CPU second)
    inside the context ``blas()`` (e.g. ``single_threaded_blas``)."""
    rng = np.random.default_rng(0)
    a = rng.random((n, n), dtype=np.float32)
    b = rng.random((n, n), dtype=np.float32)
    with blas():
        a @ b
        best = np.inf
        for _ in range(repeats):
            t0 = clock()
            a @ b
            best = min(best, clock() - t0)
    return 2.0 * n**3 / best / 1e9
