"""Parzen-window LCPDF of one site in one view (docs/model.md, section 2).

Notation (docs/model.md, section 2): for a site ``s`` of the volume, a view ``v`` with ``M = w*w - 1``
neighbour offsets, exemplar patches ``p = 0..n-1`` with neighbour vectors ``y_p`` and centre
labels ``lab[p]``, and labels ``lam_k`` (rows of ``labels``)::

    D_p      = sum_r (1 - t_r)^2 * ||x_r - y_{p,r}||^2           (neighbour term)
    log w_p  = -(D_p - D_min) / (2 h^2)                          (relative weight, max 0)
    W_j      = sum_{p : lab[p] = j} w_p                          (weighted label histogram)
    log f(k) = log sum_j W_j exp(-||lam_j - lam_k||^2 / (2 h_c^2))
    log Z    = log sum_j W_j c_j,   c_j = sum_k exp(-||lam_j - lam_k||^2 / (2 h_c^2))
    log L(k) = log f(k) - log Z

With ``h_c = h`` this is exactly the LCPDF ``L_v`` of docs/model.md, section 2 (the common factor
``exp(-D_min / 2h^2)`` cancels between numerator and normaliser). Patches whose log weight is
more than ``prune`` below the best one are skipped (``prune = inf`` keeps all). With
``adapt_eps > 0`` the neighbour bandwidth is chosen per site: ``2 h^2 = max(adapt_eps * D_min,
min_two_h2)`` (a relative, Efros-Leung-like tolerance around the best match).

Why one module of over 400 lines: the distances, the patch weights (the full pass and the one
that visits only the chunks of patches the pruning keeps, the same float32 operations in the
same order), the label smoothing and the normaliser are the stages of one site's evaluation,
and :mod:`npmrf3d._kernels.relax` inlines them into its sweeps.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._jit import jit, jit_contract, jit_inline
from .vecmath import WEIGHT_LOG_MIN, relative_weight, relative_weights


class LcpdfOptions(NamedTuple):
    """How a site's per-view log-LCPDF is computed (:func:`log_lcpdf_from_distances`).

    adapt_eps, min_two_h2 : the per-site bandwidth ``2 h^2 = max(adapt_eps * D_min,
        min_two_h2)`` when ``adapt_eps > 0`` (else the view's ``h``)
    prune : patches whose log weight is more than this below the best one are skipped
    outlier : weight of the uniform term in each view's LCPDF (0: off)
    """

    adapt_eps: float
    min_two_h2: float
    prune: float
    outlier: float


@jit
def label_sq_distance(labels, jl, kl):
    """``||lam_j - lam_k||^2`` accumulated in float64."""
    d2 = 0.0
    for c in range(labels.shape[1]):
        d = labels[jl, c] - labels[kl, c]
        d2 += d * d
    return d2


@jit
def gather_neighbours(volume, temps, i, j, k, offsets, values, trust):
    """Copy the neighbour values and trust weights of site (i, j, k) into the buffers.

    ``values[m * C + c] = volume[s + offsets[m], c]`` (toroidal) and
    ``trust[m] = (1 - temps[s + offsets[m]])**2``.
    """
    n1, n2, n3, nc = volume.shape
    for m in range(offsets.shape[0]):
        ii = (i + offsets[m, 0]) % n1
        jj = (j + offsets[m, 1]) % n2
        kk = (k + offsets[m, 2]) % n3
        t = 1.0 - temps[ii, jj, kk]
        trust[m] = t * t
        for c in range(nc):
            values[m * nc + c] = volume[ii, jj, kk, c]


@jit_contract
def neighbour_distances(values, trust, patches_t, n_patches, dist, rows):
    """``dist[p] = sum_m trust[m] * sum_c (values[m*C+c] - patches_t[m*C+c, p])**2``.

    ``patches_t`` is the transposed patch matrix (M*C, n_max), so the inner loop runs over
    contiguous patches and vectorises; four rows are folded into each pass over ``dist`` to
    halve its loads and stores. Rows of neighbours with zero trust are skipped; ``rows``
    (M*C,) int64 is scratch for the indices of the rows kept.
    """
    n_m = trust.shape[0]
    nc = values.shape[0] // n_m
    n_rows = 0
    for m in range(n_m):
        if trust[m] != 0.0:
            for c in range(nc):
                rows[n_rows] = m * nc + c
                n_rows += 1
    for p in range(n_patches):
        dist[p] = 0.0
    q = 0
    while q + 4 <= n_rows:
        q0, q1, q2, q3 = rows[q], rows[q + 1], rows[q + 2], rows[q + 3]
        x0, x1, x2, x3 = values[q0], values[q1], values[q2], values[q3]
        a0, a1, a2, a3 = trust[q0 // nc], trust[q1 // nc], trust[q2 // nc], trust[q3 // nc]
        r0, r1, r2, r3 = patches_t[q0], patches_t[q1], patches_t[q2], patches_t[q3]
        for p in range(n_patches):
            d0 = x0 - r0[p]
            d1 = x1 - r1[p]
            d2 = x2 - r2[p]
            d3 = x3 - r3[p]
            dist[p] += (a0 * d0 * d0 + a1 * d1 * d1) + (a2 * d2 * d2 + a3 * d3 * d3)
        q += 4
    while q < n_rows:
        x0 = values[rows[q]]
        a0 = trust[rows[q] // nc]
        r0 = patches_t[rows[q]]
        for p in range(n_patches):
            d0 = x0 - r0[p]
            dist[p] += a0 * d0 * d0
        q += 1


@jit
def smoothed_log_weight(labels, kl, nonzero, log_weights, n_nz, inv_two_hc2):
    """``log sum_j W_j exp(-||lam_k - lam_j||^2 / (2 h_c^2))`` over the weighted labels j, in
    the log domain (log-sum-exp: exact where the linear sum would underflow)."""
    best = -np.inf
    for a in range(n_nz):
        v = log_weights[a] - label_sq_distance(labels, nonzero[a], kl) * inv_two_hc2
        if v > best:
            best = v
    acc = 0.0
    for a in range(n_nz):
        v = log_weights[a] - label_sq_distance(labels, nonzero[a], kl) * inv_two_hc2
        acc += math.exp(v - best)
    return best + math.log(acc)


@jit
def smallest_distance(dist, n, cell):
    """``min(dist[:n])`` (as float64) of non-negative float32 distances, n >= 1.

    Non-negative float32 numbers order as their bit patterns do (as int32), and an integer
    minimum vectorises where a float one (without fastmath) does not: about 3x faster.
    ``cell`` (>= 1,) float32 is scratch, for turning the bits back into the number.
    """
    bits = dist[:n].view(np.int32)
    low = bits[0]
    for p in range(1, n):
        low = min(low, bits[p])
    cell[:1].view(np.int32)[0] = low
    return np.float64(cell[0])


#: Distances per chunk of :func:`kept_label_weights`' scan: a chunk whose smallest distance lies
#: beyond the pruning bound is passed over whole.
SCAN = 32
#: :func:`kept_label_weights` hands over to :func:`all_label_weights` when more than this share
#: of the chunks may hold a kept patch (one by one, a kept patch costs several times what it
#: costs in the vectorised pass over all patches; measured on the Figure-4 job's distances).
KEPT_CHUNKS_MAX = 0.125


@jit
def neighbour_bandwidth(d_min, inv_two_h2, adapt_eps, min_two_h2):
    """``1 / (2 h^2)`` of a site: the view's, or ``1 / max(adapt_eps * D_min, min_two_h2)``."""
    if adapt_eps > 0.0:
        return 1.0 / max(adapt_eps * d_min, min_two_h2)
    return inv_two_h2


@jit_inline
def _listed(weights, nonzero, n_nz, j, w):
    """Label ``j``'s sum ``w`` into ``weights[j]`` and ``j`` into the list ``nonzero`` when it is
    not 0; the list's new length."""
    if w == 0.0:
        return n_nz
    weights[j] = w
    nonzero[n_nz] = j
    return n_nz + 1


@jit
def all_label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps, min_two_h2, prune,
                      weights, nonzero, wbuf):
    """:func:`label_weights`' sums ``W_j`` over every patch (any ``prune``): writes ``weights[j]``
    and lists the labels in ``nonzero``; returns their number."""
    d_min = smallest_distance(dist, n_patches, wbuf[1])
    inv = neighbour_bandwidth(d_min, inv_two_h2, adapt_eps, min_two_h2)
    relative_weights(dist, n_patches, d_min, inv, -prune, wbuf[0], wbuf[1])
    w32 = wbuf[0]
    beyond = prune > -WEIGHT_LOG_MIN  # pruning (nearly) off: weights below float32's range
    n_nz = 0
    for j in range(label_starts.shape[0] - 1):
        lo, hi = label_starts[j], label_starts[j + 1]
        s0 = s1 = s2 = s3 = 0.0
        p = lo
        while p + 4 <= hi:
            s0 += w32[p]
            s1 += w32[p + 1]
            s2 += w32[p + 2]
            s3 += w32[p + 3]
            p += 4
        while p < hi:
            s0 += w32[p]
            p += 1
        w = (s0 + s1) + (s2 + s3)
        if beyond:
            for p in range(lo, hi):
                if w32[p] == 0.0:  # not kept above: inside the prune range, from math.exp
                    lw = -(dist[p] - d_min) * inv
                    if lw >= -prune:
                        w += math.exp(lw)  # may underflow to 0: then it adds nothing
        n_nz = _listed(weights, nonzero, n_nz, j, w)
    return n_nz


@jit
def kept_label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps, min_two_h2, prune,
                       weights, nonzero, wbuf):
    """:func:`all_label_weights` for ``prune <= -WEIGHT_LOG_MIN``, bit for bit, at the cost of
    two passes of integer minima over the distances and the chunks that may hold a patch the
    pruning keeps (a handful of 3,364 patches once a level has cooled).

    Every weight that pruning keeps lies at most ``prune / inv`` above ``D_min``: a chunk of
    :data:`SCAN` distances whose smallest lies beyond that (with a margin for float32 rounding)
    holds none. Each distance of the other chunks gets the test and the float32 ``exp`` of
    :func:`npmrf3d._kernels.vecmath.relative_weights` (:func:`npmrf3d._kernels.vecmath.
    relative_weight`), and a kept weight is added to the same one of its label's four partial
    sums as there (by its place in the label's range): the weights left out are 0, and adding
    0 leaves a sum as it is, so each ``W_j`` keeps its bits. With more than
    :data:`KEPT_CHUNKS_MAX` of the chunks in play it is :func:`all_label_weights`.
    """
    n = n_patches
    bits = dist[:n].view(np.int32)
    n_chunks = (n + SCAN - 1) // SCAN
    lows = np.empty(n_chunks, dtype=np.int32)  # each chunk's smallest distance (as its bits)
    for c in range(n // SCAN):  # full chunks: a fixed-length loop, vectorised
        m = bits[c * SCAN]
        for p in range(c * SCAN + 1, c * SCAN + SCAN):
            m = min(m, bits[p])
        lows[c] = m
    if n % SCAN:
        m = bits[n - n % SCAN]
        for p in range(n - n % SCAN + 1, n):
            m = min(m, bits[p])
        lows[n_chunks - 1] = m
    cell = wbuf[1][:1]
    cell.view(np.int32)[0] = lows.min()
    d_min = np.float64(cell[0])  # as smallest_distance() finds it
    inv = neighbour_bandwidth(d_min, inv_two_h2, adapt_eps, min_two_h2)
    top = np.float32(d_min)
    scale32 = np.float32(inv)
    floor = np.float32(max(-prune, WEIGHT_LOG_MIN))
    cell[0] = np.inf  # a kept d has (top - d) * scale32 >= floor, so d <= top - floor / scale32
    if scale32 > 0.0:
        cell[0] = np.float32((np.float64(top) - np.float64(floor) / np.float64(scale32))
                             * (1.0 + 1e-5))
    bound = cell.view(np.int32)[0]
    n_in = 0
    for c in range(n_chunks):
        if lows[c] <= bound:
            n_in += 1
    if n_in > KEPT_CHUNKS_MAX * n_chunks:
        return all_label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps,
                                 min_two_h2, prune, weights, nonzero, wbuf)
    n_labels = label_starts.shape[0] - 1
    first, last = label_starts[0], label_starts[n_labels]
    n_nz = 0
    j = 0
    s0 = s1 = s2 = s3 = 0.0
    for c in range(n_chunks):
        if lows[c] > bound:
            continue
        for p in range(max(c * SCAN, first), min(c * SCAN + SCAN, n, last)):
            if bits[p] > bound:
                continue
            w32 = relative_weight(dist[p], top, scale32, floor)
            if w32 == 0.0:
                continue
            if p >= label_starts[j + 1]:  # the first kept patch of a later label
                n_nz = _listed(weights, nonzero, n_nz, j, (s0 + s1) + (s2 + s3))
                s0 = s1 = s2 = s3 = 0.0
                while p >= label_starts[j + 1]:
                    j += 1
            start, stop = label_starts[j], label_starts[j + 1]
            slot = (p - start) % 4 if p < start + (stop - start) // 4 * 4 else 0
            if slot == 0:
                s0 += w32
            elif slot == 1:
                s1 += w32
            elif slot == 2:
                s2 += w32
            else:
                s3 += w32
    return _listed(weights, nonzero, n_nz, j, (s0 + s1) + (s2 + s3))


@jit
def label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps, min_two_h2, prune,
                  log_norm_const, weights, nonzero, log_weights, wbuf):
    """Patch weights summed per centre label, and the log normaliser ``log sum_j W_j c_j``.

    ``W_j = sum_{p: y_p = j} exp(-(D_p - D_min) / (2 h^2))`` (patches more than ``prune`` below
    the best skipped) goes to ``weights[j]`` for the ``n_nz`` labels listed in ``nonzero``
    (in label order), ``log W_j`` to ``log_weights[:n_nz]``. Returns ``(n_nz, log_z)``; the
    caller must reset ``weights`` at the listed labels to 0. The distances must be >= 0, the
    patches grouped by label (``label_starts`` (K + 1,), :class:`npmrf3d._kernels.relax.
    ViewModels`).

    The weights come from the vectorised float32 ``exp`` of
    :func:`npmrf3d._kernels.vecmath.relative_weights`, which also applies the pruning (in
    float32); each label's range is then summed in float64 (four partial sums). Kept log
    weights below that ``exp``'s range (only with ``prune > 87``) come from ``math.exp``.
    With pruning (``prune <= 87``) only the kept patches are visited
    (:func:`kept_label_weights`, the same sums). ``wbuf`` (2, >= n) float32 is scratch.
    """
    if prune > -WEIGHT_LOG_MIN:
        n_nz = all_label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps,
                                 min_two_h2, prune, weights, nonzero, wbuf)
    else:
        n_nz = kept_label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps,
                                  min_two_h2, prune, weights, nonzero, wbuf)
    top = -np.inf
    for a in range(n_nz):
        jl = nonzero[a]
        log_weights[a] = math.log(weights[jl])
        v = log_weights[a] + log_norm_const[jl]
        if v > top:
            top = v
    acc = 0.0
    for a in range(n_nz):
        acc += math.exp(log_weights[a] + log_norm_const[nonzero[a]] - top)
    return n_nz, top + math.log(acc)


@jit
def log_lcpdf_at_labels(
    dist, n_patches, label_starts, labels, inv_two_h2, inv_two_hc2, adapt_eps, min_two_h2,
    prune, log_norm_const, outlier, query, weights, nonzero, log_weights, wbuf, out,
):
    """The log-LCPDF of :func:`log_lcpdf_from_distances` at the labels ``query`` (Q,) only.

    Costs O(patches + Q * weighted labels) instead of O(K * weighted labels): what a
    Metropolis step needs (the current and the proposed label) with thousands of colours.
    Writes ``out`` (Q,). Same buffer contract as :func:`log_lcpdf_from_distances`.
    """
    n_labels = labels.shape[0]
    n_nz, log_z = label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps,
                                min_two_h2, prune, log_norm_const, weights, nonzero, log_weights,
                                wbuf)
    for q in range(query.shape[0]):
        value = smoothed_log_weight(labels, query[q], nonzero, log_weights, n_nz,
                                    inv_two_hc2) - log_z
        if outlier > 0.0:
            value = math.log((1.0 - outlier) * math.exp(value) + outlier / n_labels)
        out[q] = value
    for a in range(n_nz):
        weights[nonzero[a]] = 0.0


@jit
def log_lcpdf_from_distances(
    dist, n_patches, label_starts, labels, inv_two_h2, inv_two_hc2, adapt_eps,
    min_two_h2, prune, log_norm_const, kernel_table, outlier, weights, nonzero, log_weights, wbuf,
    out,
):
    """Turn neighbour distances into the log-LCPDF over all labels (see module docstring).

    ``kernel_table`` (K, K) holds ``exp(-||lam_j - lam_k||^2 / (2 h_c^2))`` (or is (0, 0):
    then every term is computed in the log domain); where the table's sum underflows the
    label falls back to the log domain, so both paths give the same result.

    With ``outlier = a > 0`` the result is the robust LCPDF ``log((1 - a) L(k) + a / K)``: each
    view keeps a uniform share ``a``, so in a product of views one view cannot veto a value
    the others agree on. Labels whose ``L(k)`` underflows float64 then get ``log(a / K)``
    (exact to ~1e-270 relative), which spares the log-domain fallback.

    ``weights`` (K,) must be all zero on entry and is all zero again on exit; ``nonzero`` and
    ``log_weights`` are scratch (K,), ``wbuf`` (2, >= n) float32 (:func:`label_weights`).
    Writes ``out`` (K,) and returns the number of distinct centre labels that carried weight.
    """
    n_labels = labels.shape[0]
    n_nz, log_z = label_weights(dist, n_patches, label_starts, inv_two_h2, adapt_eps,
                                min_two_h2, prune, log_norm_const, weights, nonzero, log_weights,
                                wbuf)
    # linear domain with the kernel table (1 <= max W_j <= n, so no overflow); out holds sums
    have_table = kernel_table.shape[0] == n_labels
    for kl in range(n_labels):
        out[kl] = 0.0
    if have_table:  # four table rows per pass over out (a quarter of its loads and stores)
        a = 0
        while a + 4 <= n_nz:
            j0, j1, j2, j3 = nonzero[a], nonzero[a + 1], nonzero[a + 2], nonzero[a + 3]
            w0, w1, w2, w3 = weights[j0], weights[j1], weights[j2], weights[j3]
            r0, r1, r2, r3 = kernel_table[j0], kernel_table[j1], kernel_table[j2], kernel_table[j3]
            for kl in range(n_labels):
                out[kl] += (w0 * r0[kl] + w1 * r1[kl]) + (w2 * r2[kl] + w3 * r3[kl])
            a += 4
        while a < n_nz:
            jl = nonzero[a]
            w = weights[jl]
            row = kernel_table[jl]
            for kl in range(n_labels):
                out[kl] += w * row[kl]
            a += 1
    if outlier > 0.0 and have_table:
        scale = (1.0 - outlier) / math.exp(log_z)
        floor = outlier / n_labels
        log_floor = math.log(floor)
        for kl in range(n_labels):
            x = out[kl] * scale + floor
            out[kl] = log_floor if x == floor else math.log(x)  # far labels: the floor alone
    else:
        for kl in range(n_labels):
            if out[kl] > 1e-280:
                out[kl] = math.log(out[kl]) - log_z
                continue
            # log domain (no table, or the sum underflows): log-sum-exp over weighted labels
            out[kl] = smoothed_log_weight(labels, kl, nonzero, log_weights, n_nz,
                                          inv_two_hc2) - log_z
        if outlier > 0.0:  # no kernel table: mix the exact values
            for kl in range(n_labels):
                out[kl] = math.log((1.0 - outlier) * math.exp(out[kl]) + outlier / n_labels)
    for a in range(n_nz):
        weights[nonzero[a]] = 0.0
    return n_nz


@jit
def label_log_norm_const(labels, inv_two_hc2):
    """``log c_j = log sum_k exp(-||lam_j - lam_k||^2 / (2 h_c^2))`` for every label j."""
    n_labels = labels.shape[0]
    out = np.empty(n_labels, dtype=np.float64)
    for jl in range(n_labels):
        s = 0.0
        for kl in range(n_labels):
            s += math.exp(-label_sq_distance(labels, jl, kl) * inv_two_hc2)
        out[jl] = math.log(s)
    return out


@jit
def label_kernel_table(labels, inv_two_hc2):
    """``exp(-||lam_j - lam_k||^2 / (2 h_c^2))`` for all label pairs, (K, K) float64."""
    n_labels = labels.shape[0]
    out = np.empty((n_labels, n_labels), dtype=np.float64)
    for jl in range(n_labels):
        for kl in range(n_labels):
            out[jl, kl] = math.exp(-label_sq_distance(labels, jl, kl) * inv_two_hc2)
    return out
