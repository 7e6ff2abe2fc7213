"""Compiled kernels: the only numba code in npmrf3d.

Kernels take plain arrays and scalars, never raise user-facing errors, and are private:
the public API in :mod:`npmrf3d.parzen`, :mod:`npmrf3d.relax`, :mod:`npmrf3d.synthesis` and
:mod:`npmrf3d.baselines.kopf` validates inputs and calls them. Modules: ``parzen`` and ``relax``
(the NP-MRF sampler), ``kopf`` (NP_K). Their naive twins are in ``tests/naive.py``. JIT options live in :mod:`npmrf3d._kernels._jit`.
"""
