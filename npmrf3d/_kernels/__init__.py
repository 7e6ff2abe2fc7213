"""Compiled kernels: the only numba code in npmrf3d.

Kernels take plain arrays and scalars, never raise user-facing errors, and are private:
the public API in :mod:`npmrf3d.parzen`, :mod:`npmrf3d.relax` and :mod:`npmrf3d.synthesis`
validates inputs and calls them. JIT options live in :mod:`npmrf3d._kernels._jit`.
"""
