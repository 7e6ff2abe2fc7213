"""Compiled kernels: the only numba code in npmrf3d.

Kernels take plain arrays and scalars, never raise user-facing errors, and are private:
the public API in :mod:`npmrf3d.model.parzen`, :mod:`npmrf3d.model.relax`, :mod:`npmrf3d.methods.npmrf` and
:mod:`npmrf3d.methods.kopf` validates inputs and calls them. Modules: ``parzen`` and ``relax``
(the NP-MRF sampler), ``kopf`` (NP_K). Their naive twins are in ``tests/naive.py``. JIT options live in :mod:`npmrf3d._kernels._jit`.
"""
