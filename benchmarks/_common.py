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


class StepClock:
    """Exclusive wall and CPU seconds per ``(group, label)``, taken by wrapping callables
    (:meth:`patch`): a wrapped call's own time, without the time of the wrapped calls inside it.
    ``group`` is whatever :attr:`group` holds when the call starts (a level, say); the wrappers
    only time the calls, so results stay what they are without them."""

    def __init__(self):
        self.group = None
        self.wall: dict = {}
        self.cpu: dict = {}
        self.calls: dict = {}
        self._stack: list = []

    def wrap(self, label: str, func, on_call=None):
        """``func`` timed under ``label``; ``on_call(*args)``, if given, runs first, untimed."""

        def timed(*args, **kwargs):
            if on_call is not None:
                on_call(*args)
            key = (self.group, label)
            frame = [0.0, 0.0]  # the wall and CPU seconds of the timed calls inside this one
            self._stack.append(frame)
            w0, c0 = time.perf_counter(), time.process_time()
            try:
                return func(*args, **kwargs)
            finally:
                wall, cpu = time.perf_counter() - w0, time.process_time() - c0
                self._stack.pop()
                self.wall[key] = self.wall.get(key, 0.0) + wall - frame[0]
                self.cpu[key] = self.cpu.get(key, 0.0) + cpu - frame[1]
                self.calls[key] = self.calls.get(key, 0) + 1
                if self._stack:
                    self._stack[-1][0] += wall
                    self._stack[-1][1] += cpu

        return timed

    @contextlib.contextmanager
    def patch(self, targets):
        """Within the block, each ``(owner, attribute, label[, on_call])`` of ``targets`` -- a
        module's function or a class's method, looked up as an attribute at call time -- is
        timed under ``label``; the originals are put back after."""
        saved = []
        try:
            for owner, name, label, *hook in targets:
                original = owner.__dict__[name]
                func = original.__func__ if isinstance(original, (classmethod, staticmethod)) else original
                timed = self.wrap(label, func, *hook)
                if isinstance(original, (classmethod, staticmethod)):
                    timed = type(original)(timed)
                saved.append((owner, name, original))
                setattr(owner, name, timed)
            yield self
        finally:
            for owner, name, original in reversed(saved):
                setattr(owner, name, original)
