"""Neighbour distances and per-view log-LCPDFs of a chunk of sites: one matrix product per view
for a block of sites, or the direct sum site by site.

The class updates (:mod:`npmrf3d._kernels.relax`) and the public LCPDF functions work on a chunk
of sites at a time; ``ops`` chooses how its distances ``D_p`` are computed: a
:class:`GemmOperands` for the product (blocks of :data:`BLOCK` sites), ``None`` for the direct
sum of :func:`npmrf3d._kernels.parzen.neighbour_distances` (chunks of :data:`CHUNK` sites).
Numba compiles each choice as its own specialisation (``ops is None`` is decided when compiling),
so a run compiles only the path it takes.

For one view, sites ``s`` of a block and exemplar patches ``p``, with trust ``t_m = (1 - T_m)^2``
of neighbour ``m``, values centred on the exemplar's channel means ``mu`` (``x' = x - mu``,
``y' = y - mu``, which leaves every difference unchanged and keeps the norms small)::

    D_p(s) = sum_m t_m ||x'_m - y'_{p,m}||^2
           = sum_m t_m ||x'_m||^2  +  sum_{m,c} (-2 t_m x'_{m,c}) y'_{p,m,c}  +  sum_m t_m q_{p,m}

with ``q_{p,m} = ||y'_{p,m}||^2``. The first term is one float64 number per site; the other two
are one float32 matrix product ``A (B, M*C + M) @ Y (M*C + M, n)`` for the whole block, done by
BLAS (``np.dot``: scipy's ``sgemm`` when compiled). When every neighbour of every site of a block
is fully trusted (``t_m = 1``: annealing, cooled regions) the last ``M`` columns are dropped and
``sum_m q_{p,m}`` is added from a float64 table instead; more generally the columns of
neighbours that no site of the block trusts (hot voxels) are left out, and so are the ``q``
columns of neighbours every site trusts fully (:func:`block_distances`). ``D_p`` is clamped at
0 (the expansion can round a little below it). Its rounding error is at most
``(M*C + M + 4) * eps32`` times the
sum of the absolute values of the terms added (tests/test_gemm.py checks it against the direct
float64 sum); the direct kernel's error is relative to ``D_p`` itself, so the two paths agree
to float32 rounding, not bit for bit.

Determinism: a block is a fixed range of a class's sites (``BLOCK``, independent of the thread
count) and BLAS runs single-threaded inside each block (:func:`npmrf3d._kernels._jit.
single_threaded_blas`), so each block's product is the same sgemm call whatever the number of
threads: the volume depends on the seed only. (Measured with OpenBLAS 0.3.30/0.3.31: a threaded
sgemm of a (4096, 96) by (96, 3364) product differs in the last bits between 1 and 2 BLAS
threads, and rows of a 64-row product differ from the same rows inside a 4096-row one; so
neither BLAS's own threads nor blocks that depend on the thread count would do.)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._jit import jit, jit_parallel, prange
from .parzen import (
    gather_neighbours,
    log_lcpdf_at_labels,
    log_lcpdf_from_distances,
    neighbour_distances,
)

#: Sites per matrix product (a fixed partition of each class: results do not depend on threads).
BLOCK = 256
#: Sites per chunk of the direct sum (few: the threads' loads stay balanced).
CHUNK = 8


@jit
def chunk_sites(ops):
    """Sites per chunk: :data:`BLOCK` with matrix products, :data:`CHUNK` with direct sums."""
    return CHUNK if ops is None else BLOCK


@jit
def chunk_count(n_sites, ops):
    """Number of chunks of ``n_sites`` sites (the last one may be shorter); chunk ``c`` starts
    at site ``c * chunk_sites(ops)``, an int64 whether ``c`` is ``range``'s or ``prange``'s
    (unsigned) index, so the callees compile once for both."""
    size = chunk_sites(ops)
    return (n_sites + size - 1) // size


class GemmOperands(NamedTuple):
    """The exemplar side of the product, per view (from :func:`make_gemm_operands`).

    patches : (V, M*C + M, n_max) float32, rows ``m*C + c``: ``y'_{p,m,c}``; rows ``M*C + m``:
        ``q_{p,m} = ||y'_{p,m}||^2``
    norms : (V, n_max) float64, ``sum_m q_{p,m}`` (the fully trusted case)
    centre : (C,) float32, the channel means ``mu`` subtracted from both sides
    """

    patches: np.ndarray
    norms: np.ndarray
    centre: np.ndarray


@jit
def make_gemm_operands(patches_t, n_patches, n_channels):
    """:class:`GemmOperands` from the transposed patch matrices ``patches_t`` (V, M*C, n_max).

    ``mu`` is the mean over every view's valid patch entries, per channel (any constant would
    give the same distances; the mean keeps the products' rounding small).
    """
    n_views, n_rows, n_max = patches_t.shape
    n_m = n_rows // n_channels
    centre64 = np.zeros(n_channels, dtype=np.float64)
    count = 0
    for v in range(n_views):
        for r in range(n_rows):
            c = r % n_channels
            for p in range(n_patches[v]):
                centre64[c] += patches_t[v, r, p]
        count += n_patches[v] * n_m
    centre = np.empty(n_channels, dtype=np.float32)
    for c in range(n_channels):
        centre[c] = centre64[c] / max(count, 1)
    patches = np.zeros((n_views, n_rows + n_m, n_max), dtype=np.float32)
    norms = np.zeros((n_views, n_max), dtype=np.float64)
    for v in range(n_views):
        for m in range(n_m):
            for c in range(n_channels):
                r = m * n_channels + c
                for p in range(n_patches[v]):
                    y = patches_t[v, r, p] - centre[c]
                    patches[v, r, p] = y
                    q = np.float64(y) * np.float64(y)
                    patches[v, n_rows + m, p] += q
                    norms[v, p] += q
    return GemmOperands(patches, norms, centre)


@jit
def gemm_rows(volume, temps, sites, rows, offsets, centre, a, s0):
    """The left operand of the product for the sites ``sites[rows]`` of one view.

    Row ``b`` of ``a`` (B, M*C + M) float32: ``-2 t_m x'_{m,c}`` at ``m*C + c``, ``t_m`` at
    ``M*C + m``; ``s0[b] = sum_m t_m ||x'_m||^2`` (float64).
    """
    n1, n2, n3, nc = volume.shape
    n_m = offsets.shape[0]
    mc = n_m * nc
    for b in range(rows.shape[0]):
        q = rows[b]
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        acc = 0.0
        for m in range(n_m):
            ii = (i + offsets[m, 0]) % n1
            jj = (j + offsets[m, 1]) % n2
            kk = (k + offsets[m, 2]) % n3
            u = np.float32(1.0) - temps[ii, jj, kk]
            t = u * u
            a[b, mc + m] = t
            sq = 0.0
            for c in range(nc):
                x = volume[ii, jj, kk, c] - centre[c]
                a[b, m * nc + c] = np.float32(-2.0) * t * x
                sq += np.float64(x) * np.float64(x)
            acc += np.float64(t) * sq
        s0[b] = acc


#: Columns are packed into a smaller product only when at most this share of them is kept
#: (packing copies the kept rows of the exemplar matrix, which costs as much as a few sites).
PACK_BELOW = 0.75


@jit
def block_distances(a, s0, n_rows, n_m, patches, norms, n_patches, product):
    """``D_p`` of rows ``b < n_rows`` into ``product[b, p]`` (float32, (>= n_rows, n_max)).

    ``a`` (B, M*C + M) and ``s0`` from :func:`gemm_rows`; ``patches`` (M*C + M, n_max) and
    ``norms`` (n_max,): one view's :class:`GemmOperands`. Columns that no row needs are left
    out of the product: a neighbour with trust 0 in every row (a hot voxel) contributes nothing,
    and the ``q`` column of a neighbour with trust 1 in every row adds the same ``q_{p,m}`` to
    every row, once, in float64 (all fully trusted: ``norms``). Columns from ``n_patches`` on
    are left undefined.
    """
    width = patches.shape[0]
    packed_a = np.empty(n_rows * width, dtype=np.float32)  # the packed left operand (flat)
    kept = np.empty(width, dtype=np.int64)  # the columns kept
    extra = np.empty(patches.shape[1], dtype=np.float64)  # sum of the fully trusted q rows
    n_mc = width - n_m
    nc = n_mc // n_m
    live = np.zeros(n_m, dtype=np.bool_)  # neighbour m is trusted by some row
    full = np.ones(n_m, dtype=np.bool_)  # ... fully (t_m = 1) by every row
    for b in range(n_rows):
        for m in range(n_m):
            t = a[b, n_mc + m]
            if t != 0.0:
                live[m] = True
            if t != 1.0:
                full[m] = False
    n_kept = 0
    n_full = 0
    for m in range(n_m):  # value columns of neighbours someone trusts
        if live[m]:
            for c in range(nc):
                kept[n_kept] = m * nc + c
                n_kept += 1
    n_values = n_kept
    for m in range(n_m):  # q columns of neighbours trusted partly (not 0 or 1 in every row)
        if full[m]:
            n_full += 1
        elif live[m]:
            kept[n_kept] = n_mc + m
            n_kept += 1
    pack = n_kept < PACK_BELOW * width
    if not pack:  # the whole product: every q column inside it, nothing extra
        n_full = 0
        np.dot(a[:n_rows], patches, product[:n_rows])
    elif n_kept == n_values and n_values == n_mc:  # a prefix of the rows: no copy of patches
        for b in range(n_rows):
            for r in range(n_mc):
                packed_a[b * n_mc + r] = a[b, r]
        np.dot(packed_a[: n_rows * n_mc].reshape((n_rows, n_mc)), patches[:n_mc],
               product[:n_rows])
    elif n_kept > 0:
        packed_y = np.zeros((n_kept, patches.shape[1]), dtype=np.float32)
        for b in range(n_rows):
            for r in range(n_kept):
                packed_a[b * n_kept + r] = a[b, kept[r]]
        for r in range(n_kept):
            src = patches[kept[r]]
            dst = packed_y[r]
            for p in range(n_patches):
                dst[p] = src[p]
        np.dot(packed_a[: n_rows * n_kept].reshape((n_rows, n_kept)), packed_y, product[:n_rows])
    else:
        for b in range(n_rows):
            for p in range(n_patches):
                product[b, p] = 0.0
    if n_full == n_m:
        for p in range(n_patches):
            extra[p] = norms[p]
    elif n_full > 0:
        for p in range(n_patches):
            extra[p] = 0.0
        for m in range(n_m):
            if full[m]:
                row = patches[n_mc + m]
                for p in range(n_patches):
                    extra[p] += row[p]
    for b in range(n_rows):
        base = s0[b]
        row = product[b]
        if n_full > 0:
            for p in range(n_patches):
                d = base + extra[p] + row[p]
                row[p] = d if d > 0.0 else 0.0
        else:
            for p in range(n_patches):
                d = base + row[p]
                row[p] = d if d > 0.0 else 0.0



@jit
def view_distances(volume, temps, sites, rows, models, ops, v, out):
    """``D_p`` of the sites ``sites[rows]`` in view ``v`` into ``out[b, :n]`` (float32, (>= B,
    n_max) for B rows; ``n = models.n_patches[v]``): one matrix product for them all (``ops``:
    :class:`GemmOperands`) or the direct sum site by site (``ops`` None)."""
    n = models.n_patches[v]
    n_rows = rows.shape[0]
    if ops is None:
        values = np.empty(models.patches_t.shape[1], dtype=np.float32)
        trust = np.empty(models.offsets.shape[1], dtype=np.float32)
        kept = np.empty(models.patches_t.shape[1], dtype=np.int64)
        for b in range(n_rows):
            q = rows[b]
            gather_neighbours(volume, temps, sites[q, 0], sites[q, 1], sites[q, 2],
                              models.offsets[v], values, trust)
            neighbour_distances(values, trust, models.patches_t[v], n, out[b], kept)
    else:
        a = np.empty((n_rows, ops.patches.shape[1]), dtype=np.float32)
        s0 = np.empty(n_rows, dtype=np.float64)
        gemm_rows(volume, temps, sites, rows, models.offsets[v], ops.centre, a, s0)
        block_distances(a, s0, n_rows, models.offsets.shape[1], ops.patches[v], ops.norms[v], n,
                        out)


@jit
def rows_log_lcpdfs(volume, temps, sites, rows, models, ops, lcpdf, query, log_l):
    """Per-view log-LCPDFs of the sites ``sites[rows]`` (B rows, at most one chunk).

    ``lcpdf``: :class:`npmrf3d._kernels.parzen.LcpdfOptions`. ``query`` None: every label,
    into ``log_l[b, v, :K]``; ``query`` (B, Q) int64 with Q >= 1 and ``query[b, 0] >= 0``: only
    the labels ``query[b]``, into ``log_l[b, v, :Q]`` (a Metropolis step's current and proposed
    labels). ``log_l`` (>= B, V, K or Q) float64.
    """
    n_rows = rows.shape[0]
    n_labels = models.labels.shape[0]
    n_max = models.patches_t.shape[2]
    dist = np.empty((n_rows, n_max), dtype=np.float32)
    weights = np.zeros(n_labels, dtype=np.float64)
    nonzero = np.empty(n_labels, dtype=np.int64)
    log_weights = np.empty(n_labels, dtype=np.float64)
    wbuf = np.empty((2, n_max), dtype=np.float32)
    for v in range(models.offsets.shape[0]):
        n = models.n_patches[v]
        view_distances(volume, temps, sites, rows, models, ops, v, dist)
        for b in range(n_rows):
            if query is None:
                log_lcpdf_from_distances(
                    dist[b], n, models.label_starts[v], models.labels, models.inv_two_h2[v],
                    models.inv_two_hc2[v], lcpdf.adapt_eps, lcpdf.min_two_h2, lcpdf.prune,
                    models.log_norm_const[v], models.kernel_tables[v], lcpdf.outlier, weights,
                    nonzero, log_weights, wbuf, log_l[b, v])
            else:
                log_lcpdf_at_labels(
                    dist[b], n, models.label_starts[v], models.labels, models.inv_two_h2[v],
                    models.inv_two_hc2[v], lcpdf.adapt_eps, lcpdf.min_two_h2, lcpdf.prune,
                    models.log_norm_const[v], lcpdf.outlier, query[b], weights, nonzero,
                    log_weights, wbuf, log_l[b, v])


@jit
def sites_log_lcpdfs(volume, temps, sites, models, ops, lcpdf, out):
    """Per-view log-LCPDFs of every site of ``sites`` (S, 3) into ``out`` (S, V, K), chunk by
    chunk (the public :func:`npmrf3d.model.parzen.log_lcpdf` and ``log_lcpdf_sites``)."""
    n_sites = sites.shape[0]
    log_l = np.empty((chunk_sites(ops), models.offsets.shape[0], models.labels.shape[0]),
                     dtype=np.float64)
    for start in range(0, n_sites, chunk_sites(ops)):
        stop = min(n_sites, start + chunk_sites(ops))
        rows_log_lcpdfs(volume, temps, sites, np.arange(start, stop), models, ops, lcpdf, None,
                        log_l)
        out[start:stop] = log_l[: stop - start]


@jit_parallel
def sites_best_distances(volume, temps, sites, models, ops, out):
    """The best-matching patch distance ``min_p D_p`` of every site (S, 3) and view into ``out``
    (S, V) float32, by chunks in parallel: the distance stage of the relaxations alone (what
    ``benchmarks/bench_parzen_blas.py`` times; ``ops`` as for :func:`view_distances`)."""
    n_sites = sites.shape[0]
    for chunk in prange(chunk_count(n_sites, ops)):
        start = chunk * chunk_sites(ops)
        stop = min(n_sites, start + chunk_sites(ops))
        dist = np.empty((stop - start, models.patches_t.shape[2]), dtype=np.float32)
        for v in range(models.offsets.shape[0]):
            view_distances(volume, temps, sites, np.arange(start, stop), models, ops, v, dist)
            for b in range(stop - start):
                out[start + b, v] = dist[b, : models.n_patches[v]].min()
