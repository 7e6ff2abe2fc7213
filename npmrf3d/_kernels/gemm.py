"""Neighbour distances of many sites at once as one matrix product (issue 14, item 1).

Why over 400 lines: the block versions of the ICM and annealing class updates live beside the
product they are built on (the per-site rules they apply are the shared ones of
:mod:`npmrf3d._kernels.relax`).

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
from .relax import (
    HEAT_BATH,
    choose_label,
    cool_site,
    make_buffers,
    metropolis_accept,
    objective_scores,
    penalty_pair,
    sample_index,
)

#: Sites per matrix product (a fixed partition of each class: results do not depend on threads).
BLOCK = 256


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
def gemm_rows(volume, temps, sites, rows, n_rows, offsets, centre, a, s0):
    """The left operand of the product for the sites ``sites[rows[:n_rows]]`` of one view.

    Row ``b`` of ``a`` (B, M*C + M) float32: ``-2 t_m x'_{m,c}`` at ``m*C + c``, ``t_m`` at
    ``M*C + m``; ``s0[b] = sum_m t_m ||x'_m||^2`` (float64).
    """
    n1, n2, n3, nc = volume.shape
    n_m = offsets.shape[0]
    mc = n_m * nc
    for b in range(n_rows):
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
def make_block_scratch(n_rows_max, width, n_max):
    """Scratch of :func:`block_distances` for up to ``n_rows_max`` rows: the packed left operand
    (flat), kept columns, the float64 sum of the fully trusted ``q`` rows, the product."""
    return (np.empty(n_rows_max * width, dtype=np.float32),
            np.empty(width, dtype=np.int64),
            np.empty(n_max, dtype=np.float64),
            np.empty((n_rows_max, n_max), dtype=np.float32))


@jit
def block_distances(a, s0, n_rows, n_m, patches, norms, n_patches, scratch):
    """``D_p`` of rows ``b < n_rows`` into the product buffer ``scratch[3][b, p]`` (float32).

    ``a`` (B, M*C + M) and ``s0`` from :func:`gemm_rows`; ``patches`` (M*C + M, n_max) and
    ``norms`` (n_max,): one view's :class:`GemmOperands`; ``scratch`` from
    :func:`make_block_scratch`. Columns that no row needs are left out of the product: a
    neighbour with trust 0 in every row (a hot voxel) contributes nothing, and the ``q`` column
    of a neighbour with trust 1 in every row adds the same ``q_{p,m}`` to every row, once, in
    float64 (all fully trusted: ``norms``). Columns from ``n_patches`` on are left undefined.
    """
    packed_a, kept, extra, product = scratch
    width = patches.shape[0]
    n_mc = width - n_m
    nc = n_mc // n_m
    n_kept = 0
    n_full = 0
    for m in range(n_m):  # value columns of neighbours someone trusts
        live = False
        for b in range(n_rows):
            if a[b, n_mc + m] != 0.0:
                live = True
                break
        if live:
            for c in range(nc):
                kept[n_kept] = m * nc + c
                n_kept += 1
    n_values = n_kept
    for m in range(n_m):  # q columns of neighbours trusted partly (not 0 or 1 in every row)
        live = False
        full = True
        for b in range(n_rows):
            t = a[b, n_mc + m]
            if t != 0.0:
                live = True
            if t != 1.0:
                full = False
        if full:
            n_full += 1
        elif live:
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
            full = True
            for b in range(n_rows):
                if a[b, n_mc + m] != 1.0:
                    full = False
                    break
            if full:
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
def block_log_lcpdfs(volume, temps, sites, rows, n_rows, models, ops, adapt_eps, min_two_h2,
                     prune, outlier, query, log_l):
    """Per-view log-LCPDFs of the sites ``sites[rows[:n_rows]]`` (at most :data:`BLOCK`).

    ``query`` (S, Q) int64 with Q >= 1 and ``query[q, 0] >= 0``: only the labels
    ``query[rows[b]]`` are evaluated into ``log_l[b, v, :Q]`` (a Metropolis step's current and
    proposed labels); ``query`` of shape (0, 0): every label, into ``log_l[b, v, :K]``.
    ``log_l`` (at least n_rows, V, max(K, Q)) float64. The same LCPDF as
    :func:`npmrf3d._kernels.relax.site_log_lcpdfs`; only ``D_p`` is computed differently.
    """
    n_views, n_m = models.offsets.shape[0], models.offsets.shape[1]
    n_labels = models.labels.shape[0]
    nc = volume.shape[3]
    width = ops.patches.shape[1]
    a = np.empty((n_rows, width), dtype=np.float32)
    s0 = np.empty(n_rows, dtype=np.float64)
    scratch = make_block_scratch(n_rows, width, models.patches_t.shape[2])
    product = scratch[3]
    weights = np.zeros(n_labels, dtype=np.float64)
    nonzero = np.empty(n_labels, dtype=np.int64)
    log_weights = np.empty(n_labels, dtype=np.float64)
    wbuf = np.empty((2, models.patches_t.shape[2]), dtype=np.float32)
    all_labels = query.shape[0] == 0
    for v in range(n_views):
        n = models.n_patches[v]
        gemm_rows(volume, temps, sites, rows, n_rows, models.offsets[v], ops.centre, a, s0)
        block_distances(a, s0, n_rows, n_m, ops.patches[v], ops.norms[v], n, scratch)
        for b in range(n_rows):
            if all_labels:
                log_lcpdf_from_distances(
                    product[b], n, models.label_starts[v], models.labels,
                    models.inv_two_h2[v], models.inv_two_hc2[v], adapt_eps, min_two_h2, prune,
                    models.log_norm_const[v], models.kernel_tables[v], outlier, weights,
                    nonzero, log_weights, wbuf, log_l[b, v])
            else:
                log_lcpdf_at_labels(
                    product[b], n, models.label_starts[v], models.labels,
                    models.inv_two_h2[v], models.inv_two_hc2[v], adapt_eps, min_two_h2, prune,
                    models.log_norm_const[v], outlier, query[rows[b]], weights, nonzero,
                    log_weights, wbuf, log_l[b, v])


@jit
def icm_update_block(
    start, stop, volume, labels_volume, temps, inherited, sites, uniforms, models, ops,
    heuristic, decision, tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier,
    old_labels, new_labels,
):
    """The ICM update of sites ``start .. stop - 1`` (one block) of one class; the same rule
    as :func:`npmrf3d._kernels.relax.icm_update_sites`, with the block's distances from one
    matrix product per view (sites of a class never interact, so gathering every site of the
    block before updating any of them changes nothing)."""
    n_views = models.offsets.shape[0]
    n_labels = models.labels.shape[0]
    nc = volume.shape[3]
    rows = np.empty(BLOCK, dtype=np.int64)
    n_rows = 0
    for q in range(start, stop):
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        if temps[i, j, k] > 0.0 or (resynth and inherited[i, j, k]):
            rows[n_rows] = q
            n_rows += 1
        else:
            old_labels[q] = -2
            new_labels[q] = -2
    if n_rows == 0:
        return
    log_l = np.empty((n_rows, n_views, n_labels), dtype=np.float64)
    block_log_lcpdfs(volume, temps, sites, rows, n_rows, models, ops, adapt_eps, min_two_h2,
                     prune, outlier, np.empty((0, 0), dtype=np.int64), log_l)
    score = np.empty(n_labels, dtype=np.float64)
    value = np.empty(nc, dtype=np.float32)
    for b in range(n_rows):
        q = rows[b]
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        chosen = choose_label(log_l[b], heuristic, decision, tau, uniforms[q], penalty,
                              models.labels, value, score)
        old_labels[q] = labels_volume[i, j, k]
        new_labels[q] = chosen
        labels_volume[i, j, k] = chosen
        for c in range(nc):
            volume[i, j, k, c] = value[c]
        if not inherited[i, j, k]:
            cool_site(temps, i, j, k, models.union_offsets, xi)


@jit_parallel
def icm_update_class_gemm(
    volume, labels_volume, temps, inherited, sites, uniforms, models, ops, heuristic,
    decision, tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier, old_labels,
    new_labels,
):
    """:func:`npmrf3d._kernels.relax.icm_update_class` with the distances of each block of
    :data:`BLOCK` sites from matrix products (blocks in parallel)."""
    n_sites = sites.shape[0]
    for blk in prange((n_sites + BLOCK - 1) // BLOCK):
        icm_update_block(blk * BLOCK, min(n_sites, (blk + 1) * BLOCK), volume, labels_volume,
                         temps, inherited, sites, uniforms, models, ops, heuristic, decision,
                         tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier,
                         old_labels, new_labels)


@jit
def icm_update_class_gemm_serial(
    volume, labels_volume, temps, inherited, sites, uniforms, models, ops, heuristic,
    decision, tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier, old_labels,
    new_labels,
):
    """:func:`icm_update_class_gemm` in the calling thread (small classes; same blocks, same
    result)."""
    n_sites = sites.shape[0]
    for blk in range((n_sites + BLOCK - 1) // BLOCK):
        icm_update_block(blk * BLOCK, min(n_sites, (blk + 1) * BLOCK), volume, labels_volume,
                         temps, inherited, sites, uniforms, models, ops, heuristic, decision,
                         tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier,
                         old_labels, new_labels)


@jit
def anneal_update_block(
    start, stop, volume, labels_volume, temps, inherited, sites, candidates, uniforms, models,
    ops, heuristic, sampler, temperature, resynth, adapt_eps, min_two_h2, prune, penalty,
    outlier, old_labels, new_labels,
):
    """The annealing step of sites ``start .. stop - 1`` (one block) of one class; the same
    rule as :func:`npmrf3d._kernels.relax.anneal_update_sites`, with the block's distances
    from one matrix product per view."""
    n_views = models.offsets.shape[0]
    n_labels = models.labels.shape[0]
    nc = volume.shape[3]
    rows = np.empty(BLOCK, dtype=np.int64)
    n_rows = 0
    heat_bath = sampler == HEAT_BATH
    pairs = np.empty((stop - start, 2), dtype=np.int64)
    for q in range(start, stop):
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        if inherited[i, j, k] and not resynth:
            old_labels[q] = -2
            new_labels[q] = -2
            continue
        current = labels_volume[i, j, k]
        old_labels[q] = current
        new_labels[q] = current
        pairs[q - start, 0] = current
        pairs[q - start, 1] = candidates[q]
        if heat_bath or (current >= 0 and candidates[q] != current):
            rows[n_rows] = q
            n_rows += 1
        elif candidates[q] != current:  # a voxel without a label takes the proposal as it is
            chosen = candidates[q]
            new_labels[q] = chosen
            labels_volume[i, j, k] = chosen
            for c in range(nc):
                volume[i, j, k, c] = models.labels[chosen, c]
    if n_rows == 0:
        return
    width = n_labels if heat_bath else 2
    log_l = np.empty((n_rows, n_views, width), dtype=np.float64)
    # the block's own rows of ``pairs`` are addressed by ``rows[b] - start``: shift them
    local = np.empty(BLOCK, dtype=np.int64)
    for b in range(n_rows):
        local[b] = rows[b] - start
    block_log_lcpdfs(volume, temps, sites[start:stop], local, n_rows, models, ops, adapt_eps,
                     min_two_h2, prune, outlier,
                     np.empty((0, 0), dtype=np.int64) if heat_bath else pairs, log_l)
    score = np.empty(n_labels, dtype=np.float64)
    pen2 = np.empty(2, dtype=np.float64)
    two = np.empty(2, dtype=np.float64)
    for b in range(n_rows):
        q = rows[b]
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        current = labels_volume[i, j, k]
        if heat_bath:
            objective_scores(log_l[b], heuristic, penalty, score)
            chosen = sample_index(score, temperature, uniforms[q])
        else:
            chosen = candidates[q]
            pair = pairs[q - start]
            objective_scores(log_l[b], heuristic, penalty_pair(penalty, pair, pen2), two)
            if not metropolis_accept(two[1] - two[0], temperature, uniforms[q]):
                chosen = current
        new_labels[q] = chosen
        if chosen != current:
            labels_volume[i, j, k] = chosen
            for c in range(nc):
                volume[i, j, k, c] = models.labels[chosen, c]


@jit_parallel
def anneal_update_class_gemm(
    volume, labels_volume, temps, inherited, sites, candidates, uniforms, models, ops,
    heuristic, sampler, temperature, resynth, adapt_eps, min_two_h2, prune, penalty, outlier,
    old_labels, new_labels,
):
    """:func:`npmrf3d._kernels.relax.anneal_update_class` with the distances of each block of
    :data:`BLOCK` sites from matrix products (blocks in parallel)."""
    n_sites = sites.shape[0]
    for blk in prange((n_sites + BLOCK - 1) // BLOCK):
        anneal_update_block(blk * BLOCK, min(n_sites, (blk + 1) * BLOCK), volume, labels_volume,
                            temps, inherited, sites, candidates, uniforms, models, ops,
                            heuristic, sampler, temperature, resynth, adapt_eps, min_two_h2,
                            prune, penalty, outlier, old_labels, new_labels)


@jit
def anneal_update_class_gemm_serial(
    volume, labels_volume, temps, inherited, sites, candidates, uniforms, models, ops,
    heuristic, sampler, temperature, resynth, adapt_eps, min_two_h2, prune, penalty, outlier,
    old_labels, new_labels,
):
    """:func:`anneal_update_class_gemm` in the calling thread (small classes; same result)."""
    n_sites = sites.shape[0]
    for blk in range((n_sites + BLOCK - 1) // BLOCK):
        anneal_update_block(blk * BLOCK, min(n_sites, (blk + 1) * BLOCK), volume, labels_volume,
                            temps, inherited, sites, candidates, uniforms, models, ops,
                            heuristic, sampler, temperature, resynth, adapt_eps, min_two_h2,
                            prune, penalty, outlier, old_labels, new_labels)


@jit
def sites_log_lcpdfs(volume, temps, sites, models, ops, adapt_eps, min_two_h2, prune, outlier,
                     out):
    """Per-view log-LCPDFs of every site of ``sites`` (S, 3) into ``out`` (S, V, K), block by
    block (the public :func:`npmrf3d.model.parzen.log_lcpdf_sites`)."""
    n_sites = sites.shape[0]
    rows = np.arange(BLOCK)
    log_l = np.empty((BLOCK, models.offsets.shape[0], models.labels.shape[0]), dtype=np.float64)
    none = np.empty((0, 0), dtype=np.int64)
    for start in range(0, n_sites, BLOCK):
        n_rows = min(BLOCK, n_sites - start)
        block_log_lcpdfs(volume, temps, sites[start:start + n_rows], rows, n_rows, models, ops,
                         adapt_eps, min_two_h2, prune, outlier, none, log_l)
        out[start:start + n_rows] = log_l[:n_rows]


@jit
def best_distances_block(start, stop, volume, temps, sites, models, ops, out):
    """``out[q, v] = min_p D_p`` of sites ``start .. stop - 1`` (one block) by the product."""
    n_m = models.offsets.shape[1]
    width = ops.patches.shape[1]
    rows = np.arange(BLOCK)
    n_rows = stop - start
    a = np.empty((n_rows, width), dtype=np.float32)
    s0 = np.empty(n_rows, dtype=np.float64)
    scratch = make_block_scratch(n_rows, width, models.patches_t.shape[2])
    for v in range(models.offsets.shape[0]):
        n = models.n_patches[v]
        gemm_rows(volume, temps, sites[start:stop], rows, n_rows, models.offsets[v], ops.centre,
                  a, s0)
        block_distances(a, s0, n_rows, n_m, ops.patches[v], ops.norms[v], n, scratch)
        for b in range(n_rows):
            out[start + b, v] = scratch[3][b, :n].min()


@jit_parallel
def sites_best_distances(volume, temps, sites, models, ops, out):
    """The best-matching patch distance ``min_p D_p`` of every site (S, 3) and view into ``out``
    (S, V) float32, by blocks of matrix products in parallel (the distance stage of the
    relaxations alone: what ``benchmarks/bench_parzen_blas.py`` times)."""
    n_sites = sites.shape[0]
    for blk in prange((n_sites + BLOCK - 1) // BLOCK):
        best_distances_block(blk * BLOCK, min(n_sites, (blk + 1) * BLOCK), volume, temps, sites,
                             models, ops, out)


@jit_parallel
def sites_best_distances_direct(volume, temps, sites, models, out):
    """:func:`sites_best_distances` by the direct per-site sum
    (:func:`npmrf3d._kernels.parzen.neighbour_distances`), for comparison."""
    n_sites = sites.shape[0]
    for blk in prange((n_sites + BLOCK - 1) // BLOCK):
        buffers = make_buffers(models)
        values, trust, dist, _, _, _, rows, _ = buffers
        for q in range(blk * BLOCK, min(n_sites, (blk + 1) * BLOCK)):
            for v in range(models.offsets.shape[0]):
                n = models.n_patches[v]
                gather_neighbours(volume, temps, sites[q, 0], sites[q, 1], sites[q, 2],
                                  models.offsets[v], values, trust)
                neighbour_distances(values, trust, models.patches_t[v], n, dist, rows)
                out[q, v] = dist[:n].min()
