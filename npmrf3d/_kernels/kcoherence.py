"""Compiled loops of the k-coherence machinery (Chen & Wang 2010; issue 11).

Why one module of ~450 lines: the search and the solver share the vote and candidate helpers,
and numba compiles a module's kernels together; splitting them would duplicate the helpers.

Private: called by :mod:`npmrf3d.model.kcoherence` and :mod:`npmrf3d.methods.chen_wang` with
validated arrays only; nothing here raises a user-facing error. Three kernels:

* :func:`candidates` (sequential, one site): the k-coherence candidate set of one site of one
  view, in a fixed enumeration order (duplicates kept; they do not change an argmin that keeps
  the first minimum).
* :func:`search_view` (parallel over the slices of a batch): for every site of one view, the
  PCA projection of its volume neighbourhood, the candidate with the smallest distance
  multiplied by the index-histogram factor, and its IRLS weight. The index histogram is frozen
  within a batch and updated (sequentially) between batches.
* :func:`solve` (parallel over the voxels of a batch): the discrete solver. Every voxel takes,
  among the texels voted by all overlapping neighbourhoods of all views, the one nearest to their
  weighted mean (IRLS weights divided by the position-histogram factor), colour and source. The
  position histograms are frozen within a batch and updated (sequentially) between batches.

Geometry (shared with :mod:`npmrf3d.model.kcoherence`): a window of side ``w`` "at" a site ``u`` covers
plane positions ``u - a .. u - a + w - 1`` along both plane axes (toroidal volume), with
``a = (w - 1) // 2`` (:func:`npmrf3d.model.kcoherence.anchor`); an exemplar neighbourhood at pixel ``p``
covers ``p - a .. p - a + w - 1`` and exists for the *valid centres*, the pixels whose window lies
inside the exemplar. Sources and centres are flat pixel indices ``row * W + col``.

Results depend only on the inputs: parallel loops write only their own site or voxel, and every
order-dependent step (histogram updates) runs in one thread in a fixed order.
"""

from __future__ import annotations

import numpy as np

from ._jit import jit, jit_parallel, prange

#: The solver's rule among a voxel's heaviest votes (:func:`solve`'s ``likelihood``): the
#: configuration's own (medoid or mean), or the NP-MRF score with the views' Parzen estimates
#: combined by the product (ML_H2b) or the minimum (ML_H2a).
OWN_SOLVER, ML_H2B, ML_H2A = 0, 1, 2


@jit
def mix(x):
    """A 31-bit integer hash of a non-negative ``x < 2**62`` (per-site randomness that depends on
    ``x`` only, so on no thread count). Products stay below ``2**62``: no overflow, so the same
    code runs compiled and as plain Python (``NUMBA_DISABLE_JIT``)."""
    h = (x ^ (x >> 31)) & 0x7FFFFFFF
    h = ((h ^ (h >> 15)) * 0x2C1B3C6D) & 0x7FFFFFFF
    h = ((h ^ (h >> 12)) * 0x297A2D39) & 0x7FFFFFFF
    h = ((h ^ (h >> 15)) * 0x2C1B3C6D) & 0x7FFFFFFF
    return h ^ (h >> 15)


@jit
def project(volume, ra, ca, n, u_r, u_c, window, anchor, mean, basis, vec, y):
    """PCA projection of the neighbourhood of the site at plane position ``(u_r, u_c)`` of
    slice ``n`` (view axes ``ra``, ``ca``; toroidal volume) into ``y`` (``vec``: scratch of
    ``window**2 * C``). The neighbourhood is read in (row, column, channel) order minus ``mean``,
    then ``y = vec @ basis`` accumulated in that order."""
    na = 3 - ra - ca
    nr = volume.shape[ra]
    nc = volume.shape[ca]
    channels = volume.shape[3]
    dims = basis.shape[1]
    m = 0
    for wr in range(window):
        x_r = (u_r - anchor + wr) % nr
        for wc in range(window):
            x_c = (u_c - anchor + wc) % nc
            q0 = n if na == 0 else (x_r if ra == 0 else x_c)
            q1 = n if na == 1 else (x_r if ra == 1 else x_c)
            q2 = n if na == 2 else (x_r if ra == 2 else x_c)
            for ch in range(channels):
                vec[m] = volume[q0, q1, q2, ch] - mean[m]
                m += 1
    for j in range(dims):
        y[j] = 0.0
    for m in range(vec.shape[0]):
        xm = vec[m]
        for j in range(dims):
            y[j] += xm * basis[m, j]


@jit_parallel
def project_sites(volume, ra, ca, window, anchor, mean, basis, sites, out):
    """PCA projections of the neighbourhoods of the listed sites of one view.

    Parameters
    ----------
    volume : (N0, N1, N2, C) float32
    ra, ca : volume axes of the exemplar row and column
    window, anchor : window side and anchor
    mean : (d,) float64, basis : (d, D) float64
    sites : (m,) int64 flat voxel indices ``(p0 * N1 + p1) * N2 + p2``
    out : (m, D) float64, out: the projection of each site (as :func:`project`)
    """
    n1 = volume.shape[1]
    n2 = volume.shape[2]
    na = 3 - ra - ca
    d = window * window * volume.shape[3]
    for i in prange(sites.shape[0]):
        vec = np.empty(d, dtype=np.float64)
        y = np.empty(basis.shape[1], dtype=np.float64)
        flat = sites[i]
        p = (flat // (n1 * n2), (flat // n2) % n1, flat % n2)
        project(volume, ra, ca, p[na], p[ra], p[ca], window, anchor, mean, basis, vec, y)
        for j in range(basis.shape[1]):
            out[i, j] = y[j]


@jit
def value_bin(x, lo, scale, bins):
    """Histogram bin of the value ``x``: ``floor((x - lo) * scale)`` clamped to ``0..bins - 1``."""
    b = int(np.floor((np.float64(x) - lo) * scale))
    return min(max(b, 0), bins - 1)


@jit
def value_prior(ex_bins, g, val_hist, val_target, val_unit, kappa):
    """Histogram prior of copying texel ``g``: ``kappa * sum_c log((T_c(b) + e) / (H_c(b) + e))`` over its
    bins ``b = ex_bins[g, c]`` (``H`` the volume's, ``T`` the exemplars' histogram in units of an
    even bin, ``e = 1 / val_unit``: one voxel). Positive for under-represented values, zero when
    the histograms agree."""
    e = 1.0 / val_unit
    prior = 0.0
    for ch in range(ex_bins.shape[1]):
        b = ex_bins[g, ch]
        prior += kappa * np.log((val_target[ch, b] + e) / (max(val_hist[ch, b], 0.0) + e))
    return prior


@jit
def value_bins(values, lo, scale, bins, out):
    """Bins of every row of ``values`` (n, C) per channel (:func:`value_bin`) into ``out`` (n, C)."""
    for i in range(values.shape[0]):
        for ch in range(values.shape[1]):
            out[i, ch] = value_bin(values[i, ch], lo[ch], scale[ch], bins)


@jit
def random_centres(salt, site, n_random, lo_r, hi_r, lo_c, hi_c, ewidth, out, start):
    """Append ``n_random`` valid centres drawn from ``mix(salt + site * n_random + t)`` to ``out``
    at ``start``; return the new count (``salt < 2**31``)."""
    nr = hi_r - lo_r + 1
    nc = hi_c - lo_c + 1
    for t in range(n_random):
        h = mix(salt + site * n_random + t)
        cell = h % (nr * nc)
        out[start + t] = (lo_r + cell // nc) * ewidth + lo_c + cell % nc
    return start + n_random


@jit
def candidates(src_v, ra, ca, pos0, pos1, pos2, ewidth, lo_r, hi_r, lo_c, hi_c, kcoh, out):
    """Fill ``out`` with the candidate centres of the site ``(pos0, pos1, pos2)``; return count.

    For every in-plane neighbour ``u + delta`` (``delta`` in ``{-1, 0, 1}^2``, row-major, the
    site itself included) with source ``s``: its coherent shift ``s - delta`` clamped to the
    valid centres ``[lo_r, hi_r] x [lo_c, hi_c]``, then that centre's k-coherence set
    ``kcoh[shift]``. ``out`` needs ``9 * (1 + k)`` entries.
    """
    n0, n1, n2 = src_v.shape
    count = 0
    k = kcoh.shape[1]
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            q0 = pos0
            q1 = pos1
            q2 = pos2
            if ra == 0:
                q0 = (pos0 + dr) % n0
            elif ra == 1:
                q1 = (pos1 + dr) % n1
            else:
                q2 = (pos2 + dr) % n2
            if ca == 0:
                q0 = (pos0 + dc) % n0
            elif ca == 1:
                q1 = (pos1 + dc) % n1
            else:
                q2 = (pos2 + dc) % n2
            s = src_v[q0, q1, q2]
            sr = s // ewidth - dr
            sc = s % ewidth - dc
            sr = min(max(sr, lo_r), hi_r)
            sc = min(max(sc, lo_c), hi_c)
            centre = sr * ewidth + sc
            out[count] = centre
            count += 1
            for t in range(k):
                out[count] = kcoh[centre, t]
                count += 1
    return count


@jit_parallel
def search_view(volume, src_v, ra, ca, window, anchor, grid, ewidth, lo_r, hi_r, lo_c, hi_c,
                mean, basis, proj, kcoh, batches, index_hist, phi, index_weight, r, floor,
                n_random, salt, assign_v, fresh_v, omega_v, energy):
    """Search phase of one view (paper section 4.3 with eq. 5-6).

    Parameters
    ----------
    volume : (N0, N1, N2, C) float32
    src_v : (N0, N1, N2) int32, this view's source pixel of every voxel
    ra, ca : volume axes of the exemplar row and column
    window, anchor, grid : window side, its anchor ``a`` and the site spacing in the plane
    ewidth : exemplar width; ``lo_r..hi_r`` x ``lo_c..hi_c`` the valid centres
    mean : (d,) float64, basis : (d, D) float64, proj : (H * W, D) float64 (rows of valid centres)
    kcoh : (H * W, k) int32, k-coherence sets of the valid centres
    batches : int, the slices along the normal axis ``n`` form batches ``n % batches``
    index_hist : (H * W,) float64, updated in place: sites currently assigned to each centre
    phi, index_weight : the index histogram's even share and strength; the distance is
        multiplied by ``1 + index_weight * max(0, index_hist[e] / phi - 1)``
    r, floor : IRLS exponent and distance floor, ``omega = max(dist, floor) ** (r - 2)``
    n_random, salt : extra uniformly random valid centres per site (:func:`random_centres` with
        the flat voxel index as site; 0 = none, the paper)
    assign_v : (N0, N1, N2) int32, in/out: the centre matched at every site (-1 elsewhere;
        on entry the previous assignment, whose counts ``index_hist`` holds)
    fresh_v : (N0, N1, N2) int32, scratch for the new assignments of a batch
    omega_v : (N0, N1, N2) float32, out: IRLS weight at every site
    energy : (N_normal,) float64, out: ``sum dist ** r`` over the sites of each slice
    """
    na = 3 - ra - ca
    shape = volume.shape
    nn = shape[na]
    nr = shape[ra]
    nc = shape[ca]
    channels = shape[3]
    d = window * window * channels
    dims = basis.shape[1]
    cap = 9 * (1 + kcoh.shape[1]) + n_random
    gr = nr // grid
    gc = nc // grid
    for b in range(batches):
        nb = (nn - b + batches - 1) // batches
        for t in prange(nb):
            n = b + t * batches
            vec = np.empty(d, dtype=np.float64)
            y = np.empty(dims, dtype=np.float64)
            cand = np.empty(cap, dtype=np.int64)
            acc = 0.0
            for ar in range(gr):
                u_r = ar * grid
                for ac in range(gc):
                    u_c = ac * grid
                    p0 = n if na == 0 else (u_r if ra == 0 else u_c)
                    p1 = n if na == 1 else (u_r if ra == 1 else u_c)
                    p2 = n if na == 2 else (u_r if ra == 2 else u_c)
                    project(volume, ra, ca, n, u_r, u_c, window, anchor, mean, basis, vec, y)
                    count = candidates(src_v, ra, ca, p0, p1, p2, ewidth, lo_r, hi_r, lo_c, hi_c,
                                       kcoh, cand)
                    if n_random > 0:
                        count = random_centres(salt, (p0 * shape[1] + p1) * shape[2] + p2, n_random,
                                               lo_r, hi_r, lo_c, hi_c, ewidth, cand, count)
                    best = -1
                    best_cost = np.inf
                    best_d2 = 0.0
                    for t2 in range(count):
                        e = cand[t2]
                        d2 = 0.0
                        for j in range(dims):
                            diff = y[j] - proj[e, j]
                            d2 += diff * diff
                        excess = index_hist[e] / phi - 1.0
                        cost = d2 * (1.0 + index_weight * excess) if excess > 0.0 else d2
                        if cost < best_cost:
                            best_cost = cost
                            best = e
                            best_d2 = d2
                    dist = np.sqrt(best_d2)
                    acc += dist ** r
                    omega_v[p0, p1, p2] = max(dist, floor) ** (r - 2.0)
                    fresh_v[p0, p1, p2] = best
            energy[n] = acc
        # sequential, fixed order: move the batch's sites from their old centres to the new ones
        for t in range(nb):
            n = b + t * batches
            for ar in range(gr):
                for ac in range(gc):
                    u_r = ar * grid
                    u_c = ac * grid
                    p0 = n if na == 0 else (u_r if ra == 0 else u_c)
                    p1 = n if na == 1 else (u_r if ra == 1 else u_c)
                    p2 = n if na == 2 else (u_r if ra == 2 else u_c)
                    old = assign_v[p0, p1, p2]
                    if old >= 0:
                        index_hist[old] -= 1.0
                    new = fresh_v[p0, p1, p2]
                    index_hist[new] += 1.0
                    assign_v[p0, p1, p2] = new
    return 0


@jit
def _votes(p0, p1, p2, assign, omega, view_axes, ex_off, ewidth, window, anchor, grid, pos_hist,
           hist_off, theta, position_weight, position_boost, ex_bins, val_hist, val_target, val_weight,
           out_g, out_v, out_w):
    """Texels voted for voxel ``(p0, p1, p2)`` by every overlapping neighbourhood of every view.

    A neighbourhood at site ``u`` matched with centre ``e`` votes for the texel ``e + (x - u)``
    (plane offsets) with weight ``omega[u] / (1 + position_weight * max(0, H(texel) / theta - 1))``
    (paper eq. 4 with a strength); with ``position_boost > 0`` an under-used texel's weight is
    multiplied by ``1 + position_boost * (1 - H(texel) / theta)`` (this project's addition).
    With ``val_weight > 0`` the weight is further divided by the **value-histogram** factor
    ``1 + val_weight * sum_c max(0, val_hist[c, b_c] - val_target[c, b_c])`` (``b_c`` =
    ``ex_bins[texel, c]``; histograms in units of an even bin's share, this project's addition
    after Kopf et al. 2007's histogram matching). Votes are enumerated view by view, then by row offset
    ``x_r - u_r`` from ``-anchor`` to ``window - 1 - anchor``, then by column offset; texels are
    written as packed rows ``ex_off[v] + local``. Returns the number of votes.
    """
    shape = assign.shape
    count = 0
    for v in range(assign.shape[0]):
        ra = view_axes[v, 0]
        ca = view_axes[v, 1]
        nr = shape[1 + ra]
        nc = shape[1 + ca]
        xr = p0 if ra == 0 else (p1 if ra == 1 else p2)
        xc = p0 if ca == 0 else (p1 if ca == 1 else p2)
        w = ewidth[v]
        for orow in range(-anchor, window - anchor):
            u_r = (xr - orow) % nr
            if u_r % grid:
                continue
            for ocol in range(-anchor, window - anchor):
                u_c = (xc - ocol) % nc
                if u_c % grid:
                    continue
                q0 = p0
                q1 = p1
                q2 = p2
                if ra == 0:
                    q0 = u_r
                elif ra == 1:
                    q1 = u_r
                else:
                    q2 = u_r
                if ca == 0:
                    q0 = u_c
                elif ca == 1:
                    q1 = u_c
                else:
                    q2 = u_c
                e = assign[v, q0, q1, q2]
                if e < 0:
                    continue
                local = (e // w + orow) * w + (e % w + ocol)
                excess = pos_hist[hist_off[v] + local] / theta[v] - 1.0
                weight = omega[v, q0, q1, q2]
                if excess > 0.0:
                    weight = weight / (1.0 + position_weight * excess)
                elif position_boost > 0.0:
                    weight = weight * (1.0 - position_boost * excess)
                if val_weight > 0.0:
                    over = 0.0
                    for ch in range(ex_bins.shape[1]):
                        b = ex_bins[ex_off[v] + local, ch]
                        gap = val_hist[ch, b] - val_target[ch, b]
                        if gap > 0.0:
                            over += gap
                    weight = weight / (1.0 + val_weight * over)
                out_g[count] = ex_off[v] + local
                out_v[count] = v
                out_w[count] = weight
                count += 1
    return count


@jit
def _group_votes(vg, vv, vw, count, n_views, slot, ug, uv, uw, umax, uarg):
    """Merge the ``count`` votes by (texel, view) (views may share an exemplar's rows): group ``i`` (in order of first appearance) has texel
    ``ug[i]``, view ``uv[i]``, summed weight ``uw[i]``, heaviest single weight ``umax[i]`` and
    the index ``uarg[i]`` of its first vote of that weight. ``slot`` (one entry per texel and view,
    all -1) is scratch and is left all -1. Returns the number of groups. A score summed over the
    groups equals the sum over the votes (up to rounding) at a fraction of the cost: coherent
    neighbourhoods vote for the same texels."""
    u = 0
    for q in range(count):
        g = vg[q]
        key = g * n_views + vv[q]
        i = slot[key]
        if i < 0:
            i = u
            slot[key] = i
            ug[i] = g
            uv[i] = vv[q]
            uw[i] = vw[q]
            umax[i] = vw[q]
            uarg[i] = q
            u += 1
        else:
            uw[i] += vw[q]
            if vw[q] > umax[i]:
                umax[i] = vw[q]
                uarg[i] = q
    for i in range(u):
        slot[ug[i] * n_views + uv[i]] = -1
    return u


@jit_parallel
def solve(volume, src, assign, omega, view_axes, ex_flat, ex_off, ewidth, window, anchor, grid,
          order, batch_bounds, pos_hist, hist_off, theta, position_weight, position_boost, medoid, balance, chunk,
          likelihood, h2c, outlier, ex_bins, val_hist, val_target, val_weight, val_prior, val_lo, val_scale,
          val_unit, temperature, salt):
    """Discrete solver (paper section 4.2 with eq. 4), one pass over all voxels.

    Voxels are visited in ``order`` (flat indices), cut into batches at ``batch_bounds``. Within a
    batch every voxel (in parallel) gathers its votes (:func:`_votes`), computes their weighted
    mean colour and copies the voted texel nearest to it (first one on ties) -- or, with
    ``medoid > 0``, among the texels of the ``medoid`` heaviest votes (distinct texel and view),
    the one ``p`` minimising ``sum_q w_q ||e_p - e_q||`` over all votes (a weighted medoid): ``volume`` gets its
    colour, and each view's source becomes that view's voted texel nearest to the copied colour
    (the copied texel itself for its own view). After the batch, in one thread, the position
    histograms ``pos_hist`` (packed per view at ``hist_off``, counts of voxels per source pixel)
    move from the old sources to the new ones. Returns the number of voxels whose colour changed.

    With ``likelihood`` 1 (ML_H2b) or 2 (ML_H2a) the candidates of the ``medoid`` heaviest votes
    are scored instead by the NP-MRF rule (the coherent NP-MRF sampler, :mod:`npmrf3d.methods.npmrf_coherent`):
    per view, a Parzen estimate of the candidate colour's probability from that view's votes,
    ``L_v(p) = sum_{q in v} w_q exp(-||e_p - e_q||^2 / h2c) / sum_{q in v} w_q``, mixed with an
    ``outlier`` share; the views are combined by the product (1) or the minimum (2) and the
    highest score wins (first on ties).

    Value histograms (``val_weight > 0``): ``val_hist`` (C, bins) holds the volume's per-channel
    histogram in units of ``val_unit`` voxels (an even bin's share), ``val_target`` the
    exemplars' in the same units, ``ex_bins`` (rows of ``ex_flat``, C) every texel's bins (by
    :func:`value_bins` with ``val_lo``, ``val_scale``); votes are weighted down by the excess of
    their texel's bins (:func:`_votes`) and ``val_hist`` follows the changed voxels between
    batches, so the volume's histogram is pulled towards the exemplars'. With the NP-MRF rule the
    score of a candidate also gets the histogram prior :func:`value_prior` with strength
    ``val_prior`` (0 = off; added to the ML_H2b
    log-score, a factor ``exp(prior)`` on the ML_H2a score), which vanishes when the histograms
    agree.

    Annealing (``temperature > 0``, NP-MRF rule only): instead of the highest score, the voxel
    draws candidate ``a`` with probability proportional to ``exp(l_a / temperature)`` (a
    heat-bath step over its candidates; ``l_a`` the ML_H2b log-score, or the log of the ML_H2a
    score), from the uniform ``(mix(salt * n_voxels + flat) + 0.5) / 2**31`` -- a hash of the
    voxel, so the draw depends on no thread count (``salt < 2**31``).
    """
    n_views = assign.shape[0]
    n0, n1, n2, channels = volume.shape
    n_vox = n0 * n1 * n2
    cap = n_views * window * window
    changed = 0
    for b in range(batch_bounds.shape[0] - 1):
        start = batch_bounds[b]
        m = batch_bounds[b + 1] - start
        new_src = np.empty((m, n_views), dtype=np.int32)
        flags = np.zeros(m, dtype=np.int64)
        old_bins = np.zeros((m, channels), dtype=np.int64)
        new_bins = np.zeros((m, channels), dtype=np.int64)
        n_chunks = (m + chunk - 1) // chunk
        for c in prange(n_chunks):
            vg = np.empty(cap, dtype=np.int64)
            vv = np.empty(cap, dtype=np.int64)
            vw = np.empty(cap, dtype=np.float64)
            mean = np.empty(channels, dtype=np.float64)
            vsum = np.empty(n_views, dtype=np.float64)
            taken = np.zeros(cap, dtype=np.bool_)
            slot = np.full(ex_flat.shape[0] * n_views, -1, dtype=np.int64)
            ug = np.empty(cap, dtype=np.int64)
            uv = np.empty(cap, dtype=np.int64)
            uw = np.empty(cap, dtype=np.float64)
            umax = np.empty(cap, dtype=np.float64)
            uarg = np.empty(cap, dtype=np.int64)
            tops = np.empty(max(medoid, 1), dtype=np.int64)
            lik = np.empty(n_views, dtype=np.float64)
            scores = np.empty(max(medoid, 1), dtype=np.float64)
            for t in range(c * chunk, min(m, (c + 1) * chunk)):
                flat = order[start + t]
                p0 = flat // (n1 * n2)
                p1 = (flat // n2) % n1
                p2 = flat % n2
                count = _votes(p0, p1, p2, assign, omega, view_axes, ex_off, ewidth, window,
                               anchor, grid, pos_hist, hist_off, theta, position_weight, position_boost,
                               ex_bins, val_hist, val_target, val_weight, vg, vv, vw)
                for v in range(n_views):
                    new_src[t, v] = src[v, p0, p1, p2]
                if count == 0:
                    continue
                if balance:
                    # every view gets the same total say: its votes' weights sum to 1
                    for v in range(n_views):
                        vsum[v] = 0.0
                    for q in range(count):
                        vsum[vv[q]] += vw[q]
                    for q in range(count):
                        vw[q] /= vsum[vv[q]]
                # the votes merged by (texel, view): summed weight, heaviest
                # single vote and its index; groups in order of first appearance
                u = _group_votes(vg, vv, vw, count, n_views, slot, ug, uv, uw, umax, uarg)
                best = 0
                if medoid:
                    # candidates: the `medoid` heaviest votes with distinct (texel, view), heaviest
                    # first (ties: the earlier vote) -- the groups of the heaviest single votes
                    n_try = 0
                    for q in range(u):
                        taken[q] = False
                    for a in range(medoid):
                        top = -1
                        for q in range(u):
                            if not taken[q] and (top < 0 or umax[q] > umax[top]
                                                 or (umax[q] == umax[top] and uarg[q] < uarg[top])):
                                top = q
                        if top < 0:
                            break
                        taken[top] = True
                        tops[n_try] = top
                        n_try += 1
                    best_e = np.inf
                    if likelihood:
                        for v in range(n_views):
                            vsum[v] = 0.0
                        for q in range(count):
                            vsum[vv[q]] += vw[q]
                    for a in range(n_try):
                        ga = ug[tops[a]]
                        if likelihood:
                            for v in range(n_views):
                                lik[v] = 0.0
                            for q2 in range(u):
                                dd = 0.0
                                for ch in range(channels):
                                    diff = ex_flat[ga, ch] - ex_flat[ug[q2], ch]
                                    dd += diff * diff
                                lik[uv[q2]] += uw[q2] * np.exp(-dd / h2c)
                            score = 0.0 if likelihood == 1 else np.inf
                            for v in range(n_views):
                                lv = (1.0 - outlier) * lik[v] / vsum[v] + outlier if vsum[v] > 0.0 else outlier
                                if likelihood == 1:
                                    score += np.log(lv)
                                else:
                                    score = min(score, lv)
                            if val_prior > 0.0:
                                prior = value_prior(ex_bins, ga, val_hist, val_target, val_unit, val_prior)
                                score = score + prior if likelihood == 1 else score * np.exp(prior)
                            scores[a] = score if likelihood == 1 else np.log(score)
                            if -score < best_e:
                                best_e = -score
                                best = uarg[tops[a]]
                            continue
                        e_sum = 0.0
                        for q2 in range(u):
                            dd = 0.0
                            for ch in range(channels):
                                diff = ex_flat[ga, ch] - ex_flat[ug[q2], ch]
                                dd += diff * diff
                            e_sum += uw[q2] * np.sqrt(dd)
                        if val_prior > 0.0:
                            e_sum *= np.exp(-value_prior(ex_bins, ga, val_hist, val_target, val_unit, val_prior))
                        if e_sum < best_e:
                            best_e = e_sum
                            best = uarg[tops[a]]
                    if likelihood and temperature > 0.0 and n_try > 1:
                        top_l = scores[0]
                        for a in range(1, n_try):
                            top_l = max(top_l, scores[a])
                        if top_l > -np.inf:
                            total = 0.0
                            for a in range(n_try):
                                total += np.exp((scores[a] - top_l) / temperature)
                            x = (mix(salt * n_vox + flat) + 0.5) / 2147483648.0 * total
                            acc = 0.0
                            pick = n_try - 1
                            for a in range(n_try):
                                acc += np.exp((scores[a] - top_l) / temperature)
                                if x < acc:
                                    pick = a
                                    break
                            best = uarg[tops[pick]]
                else:
                    total = 0.0
                    for ch in range(channels):
                        mean[ch] = 0.0
                    for q in range(count):
                        total += vw[q]
                        for ch in range(channels):
                            mean[ch] += vw[q] * ex_flat[vg[q], ch]
                    for ch in range(channels):
                        mean[ch] /= total
                    best_d = np.inf
                    for q in range(u):
                        dd = 0.0
                        for ch in range(channels):
                            diff = ex_flat[ug[q], ch] - mean[ch]
                            dd += diff * diff
                        if dd < best_d:
                            best_d = dd
                            best = uarg[q]
                g = vg[best]
                for ch in range(channels):
                    if volume[p0, p1, p2, ch] != ex_flat[g, ch]:
                        flags[t] = 1
                if flags[t]:
                    for ch in range(channels):
                        old_bins[t, ch] = value_bin(volume[p0, p1, p2, ch], val_lo[ch], val_scale[ch],
                                                    val_hist.shape[1])
                        new_bins[t, ch] = ex_bins[g, ch]
                for ch in range(channels):
                    volume[p0, p1, p2, ch] = ex_flat[g, ch]
                for v in range(n_views):
                    if v == vv[best]:
                        new_src[t, v] = g - ex_off[v]
                        continue
                    near = -1
                    near_d = np.inf
                    for q in range(u):
                        if uv[q] != v:
                            continue
                        dd = 0.0
                        for ch in range(channels):
                            diff = ex_flat[ug[q], ch] - ex_flat[g, ch]
                            dd += diff * diff
                        if dd < near_d:
                            near_d = dd
                            near = q
                    if near >= 0:
                        new_src[t, v] = ug[near] - ex_off[v]
        # sequential, fixed order: histograms follow the new sources
        for t in range(m):
            flat = order[start + t]
            p0 = flat // (n1 * n2)
            p1 = (flat // n2) % n1
            p2 = flat % n2
            changed += flags[t]
            if flags[t]:
                for ch in range(channels):
                    val_hist[ch, old_bins[t, ch]] -= 1.0 / val_unit
                    val_hist[ch, new_bins[t, ch]] += 1.0 / val_unit
            for v in range(n_views):
                old = src[v, p0, p1, p2]
                new = new_src[t, v]
                pos_hist[hist_off[v] + old] -= 1.0
                pos_hist[hist_off[v] + new] += 1.0
                src[v, p0, p1, p2] = new
    return changed
