"""Local Dask clusters: the studies' (:mod:`npmrf3d.studies.runner`) and the neural Zarr
writer's (:mod:`npmrf3d.methods.neural.zarr_volume`), started the same way.

Why a module of its own: both start worker processes whose memory allocator needs one setting
before the process exists. Dask's Nanny sets ``MALLOC_TRIM_THRESHOLD_`` in every worker's
environment before spawning it (``distributed.nanny.pre-spawn-environ``); setting any of glibc's
``MALLOC_*_THRESHOLD_`` variables turns off glibc's dynamic mmap threshold, so every allocation
above 128 KiB is then a fresh ``mmap`` whose pages the kernel zeroes on first touch, and freed at
once. Measured on the neural generator (a 128^3 block, one thread, AMD EPYC): 6.9 s per block
with 2.9 s of it in the kernel under Dask's setting, 4.3 s (0.4 s kernel) with the mmap
threshold raised as here, 4.5 s (0.7 s) with glibc's defaults; a 1024^3 Zarr volume spent 41 %
of its CPU time in the kernel. So the workers get glibc's largest mmap threshold (32 MiB):
blocks below it come from the heap and are reused.
"""

from __future__ import annotations

import logging

#: glibc's largest ``M_MMAP_THRESHOLD`` on 64-bit Linux (``DEFAULT_MMAP_THRESHOLD_MAX``), bytes.
MMAP_THRESHOLD = 32 * 2 ** 20

#: BLAS and OpenMP thread counts in every worker (each run or task sets its own threads).
_SINGLE_THREADED = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def local_cluster(workers: int, *, dashboard_address=":0", silence_logs=logging.WARNING):
    """A ``distributed.LocalCluster`` of ``workers`` processes with one Dask thread each, BLAS
    single-threaded and the allocator setting above in every worker's environment."""
    import dask
    from distributed import LocalCluster

    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_MMAP_THRESHOLD_": MMAP_THRESHOLD}):
        return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                            dashboard_address=dashboard_address, silence_logs=silence_logs,
                            env=dict(_SINGLE_THREADED))
