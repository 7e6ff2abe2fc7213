"""Compiled loops of the NP_K baseline (Kopf et al. 2007; docs/kopf.md).

Private: called by :mod:`npmrf3d.methods.kopf` with validated arrays only; no user-facing
errors are raised here. Two kernels:

* :func:`gather_texels` (parallel, one voxel per iteration, no shared writes): for every voxel,
  the exemplar texels that the overlapping sparse-grid neighbourhoods of each view assign to it
  and their IRLS weights.
* :func:`optimise_sweep` (sequential, random voxel order): the histogram- and
  constraint-reweighted average of equation (4) of the paper, optionally restricted to the
  dominant mean-shift cluster, with the per-channel histograms of the volume updated after every
  voxel (the paper's section 5).

The split keeps the result independent of the thread count: the parallel part writes only its own
voxel's rows, and everything that depends on the visiting order runs in one thread.
"""

from __future__ import annotations

import numpy as np

from ._jit import jit, jit_parallel, prange


@jit
def _contributors(i, j, k, assign, omega, view_axes, ewidth, window, grid, rows_out, w_out):
    """Exemplar rows and IRLS weights of every sparse-grid window (all views) covering voxel
    ``(i, j, k)``; returns their number.

    Windows are anchored at their top-left site ``u`` and cover ``u .. u + window - 1``
    (toroidal) along both plane axes; sites are the positions divisible by ``grid`` (every
    level size is a multiple of ``grid`` and at least ``window``). ``assign[v, site]`` holds
    the flat exemplar row of the top-left texel of the site's exemplar patch, so texel
    ``(a, b)`` of the patch is row ``assign + a * ewidth[v] + b``."""
    count = 0
    for v in range(assign.shape[0]):
        ra = view_axes[v, 0]
        ca = view_axes[v, 1]
        xr = i if ra == 0 else (j if ra == 1 else k)
        xc = i if ca == 0 else (j if ca == 1 else k)
        nr = assign.shape[1 + ra]
        nc = assign.shape[1 + ca]
        ew = ewidth[v]
        for a in range(xr % grid, window, grid):
            ur = xr - a
            if ur < 0:
                ur += nr
            for b in range(xc % grid, window, grid):
                uc = xc - b
                if uc < 0:
                    uc += nc
                s0 = i
                s1 = j
                s2 = k
                if ra == 0:
                    s0 = ur
                elif ra == 1:
                    s1 = ur
                else:
                    s2 = ur
                if ca == 0:
                    s0 = uc
                elif ca == 1:
                    s1 = uc
                else:
                    s2 = uc
                rows_out[count] = assign[v, s0, s1, s2] + a * ew + b
                w_out[count] = omega[v, s0, s1, s2]
                count += 1
    return count


@jit
def _mean_shift_mode(texels, weights, count, bandwidth, iterations, mode, scratch):
    """Mode of the dominant cluster of ``count`` weighted points (flat-kernel mean-shift).

    Mean-shift with a flat kernel of radius ``h`` (each step moves ``y`` to the weighted mean of
    the points within ``h``) runs from the heaviest point and from the weighted mean of all
    points (skipped when the first cluster already holds more than half of the weight: it is the
    dominant one); the mode whose ``h``-ball holds the larger weight wins. At convergence the
    mode is the weighted mean of the points of its cluster, which is written to ``mode``.
    Returns False (``mode`` untouched) when neither start has a point within ``h``."""
    channels = texels.shape[1]
    h2 = bandwidth * bandwidth
    best = 0.0
    heaviest = 0
    weight_total = weights[0]
    for q in range(1, count):
        weight_total += weights[q]
        if weights[q] > weights[heaviest]:
            heaviest = q
    for s in range(2):
        if s == 1 and best > 0.5 * weight_total:
            break
        if s == 0:
            for c in range(channels):
                scratch[c] = texels[heaviest, c]
        else:
            total = 0.0
            for c in range(channels):
                scratch[c] = 0.0
            for q in range(count):
                total += weights[q]
                for c in range(channels):
                    scratch[c] += weights[q] * texels[q, c]
            for c in range(channels):
                scratch[c] /= total
        mass = 0.0
        for _ in range(iterations):
            mass = 0.0
            for c in range(channels):
                scratch[channels + c] = 0.0
            for q in range(count):
                d2 = 0.0
                for c in range(channels):
                    t = texels[q, c] - scratch[c]
                    d2 += t * t
                if d2 <= h2:
                    mass += weights[q]
                    for c in range(channels):
                        scratch[channels + c] += weights[q] * texels[q, c]
            if mass <= 0.0:
                break
            moved = 0.0
            for c in range(channels):
                t = scratch[channels + c] / mass
                moved += (t - scratch[c]) ** 2
                scratch[c] = t
            if moved <= 1e-12 * h2:
                break
        if mass > best:
            best = mass
            for c in range(channels):
                mode[c] = scratch[c]
    return best > 0.0


@jit_parallel
def gather_texels(voxels, assign, omega, view_axes, ewidth, window, grid, rows, weights, counts):
    """For the t-th voxel of ``voxels`` (flat C-order indices) fill ``rows[t, :]`` (exemplar
    rows), ``weights[t, :]`` (IRLS weights) and ``counts[t]``. Parallel over voxels; each
    iteration writes only its own rows."""
    n2, n3 = assign.shape[2], assign.shape[3]
    for t in prange(voxels.shape[0]):
        v = voxels[t]
        i = v // (n2 * n3)
        rest = v - i * n2 * n3
        j = rest // n3
        k = rest - j * n3
        counts[t] = _contributors(i, j, k, assign, omega, view_axes, ewidth, window, grid,
                                  rows[t], weights[t])


@jit
def optimise_sweep(volume, order, rows, weights, counts, ex_flat, ex_bins, hist, hist_target,
                   hist_scale, lo, scale, bins, constraint, tau, use_constraint, bandwidth,
                   ms_iterations):
    """Part of one optimisation phase: visit the voxels ``order`` (flat indices, in this order)
    and set each to the reweighted average of its exemplar texels (paper eq. 4 with eqs. 5 and
    6), or to the mode of their dominant mean-shift cluster when ``bandwidth > 0``; keep
    ``hist`` (per-channel bin counts of the volume) up to date after every voxel.
    Returns the sum of absolute changes.

    Row t of ``rows``/``weights``/``counts`` belongs to voxel ``order[t]``. Weight of
    contributor q (``weights[t, q]`` holds the IRLS weight ``||s - e||^(r-2)``)::

        w'_q = w_q / (1 + hist_scale * sum_c max(0, hist[c, b_c(e_q)] / N - hist_target[c, b_c(e_q)]))
                   / (1 + tau_v * ||e_q - t_v||)            (the second factor if use_constraint)
    """
    n1, n2, n3, channels = volume.shape
    inv_n = 1.0 / (n1 * n2 * n3)
    value = np.zeros(channels)
    texels = np.empty((rows.shape[1], channels))
    wkept = np.empty(rows.shape[1])
    scratch = np.empty(2 * channels)
    change = 0.0
    for t in range(order.shape[0]):
        v = order[t]
        i = v // (n2 * n3)
        rest = v - i * n2 * n3
        j = rest // n3
        k = rest - j * n3
        wsum = 0.0
        kept = 0
        for c in range(channels):
            value[c] = 0.0
        for q in range(counts[t]):
            w = weights[t, q]
            if w <= 0.0:
                continue
            row = rows[t, q]
            if hist_scale > 0.0:
                excess = 0.0
                for c in range(channels):
                    b = ex_bins[row, c]
                    d = hist[c, b] * inv_n - hist_target[c, b]
                    if d > 0.0:
                        excess += d
                w /= 1.0 + hist_scale * excess
            if use_constraint:
                tv = tau[i, j, k]
                if tv > 0.0:
                    d2 = 0.0
                    for c in range(channels):
                        d = ex_flat[row, c] - constraint[i, j, k, c]
                        d2 += d * d
                    w /= 1.0 + tv * np.sqrt(d2)
            wsum += w
            for c in range(channels):
                value[c] += w * ex_flat[row, c]
                texels[kept, c] = ex_flat[row, c]
            wkept[kept] = w
            kept += 1
        if wsum <= 0.0:
            continue
        for c in range(channels):
            value[c] /= wsum
        if bandwidth > 0.0 and kept > 1:
            _mean_shift_mode(texels, wkept, kept, bandwidth, ms_iterations, value, scratch)
        for c in range(channels):
            new = np.float32(value[c])
            old = volume[i, j, k, c]
            b_old = int((old - lo[c]) * scale[c])
            b_old = min(max(b_old, 0), bins - 1)
            b_new = int((new - lo[c]) * scale[c])
            b_new = min(max(b_new, 0), bins - 1)
            hist[c, b_old] -= 1
            hist[c, b_new] += 1
            change += abs(new - old)
            volume[i, j, k, c] = new
    return change
