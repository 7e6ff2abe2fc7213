"""Compiled loops of the k-coherence search (Chen & Wang 2010): candidates and the search phase.

Private: called by :mod:`npmrf3d.model.kcoherence` and :mod:`npmrf3d.model.kcoherence_engine`
with validated arrays only; nothing here raises a user-facing error. The solver that follows
each search is :mod:`npmrf3d._kernels.kcoherence_solver`. Why one module of ~500 lines: the
search kernel and the helpers it inlines (gathering, projection, candidates, their distances,
the division-free wrap) share one geometry and are read together against their twins in
``tests/naive.py``. Kernels:

* :func:`candidates` (sequential, one site): the k-coherence candidate set of one site of one
  view, in a fixed enumeration order (duplicates kept; they do not change an argmin that keeps
  the first minimum).
* :func:`search_view` (parallel over the slices of a batch): for every site of one view, the
  PCA projection of its volume neighbourhood, the candidate with the smallest distance
  multiplied by the index-histogram factor, and its IRLS weight. The index histogram is frozen
  within a batch and updated (sequentially) between batches. Its arguments come in two bundles,
  the view's exemplar model (:class:`SearchExemplar`) and the settings (:class:`SearchRule`).
* :func:`project_sites` (parallel over sites): PCA projections of listed sites (the global
  search of the worst-matched sites); :func:`value_bins`: histogram bins of values;
  :func:`voxel_batches`: the solver's batches of a block-local run, hashed from grid positions.

Geometry (shared with :mod:`npmrf3d.model.kcoherence`): a window of side ``w`` "at" a site ``u`` covers
plane positions ``u - a .. u - a + w - 1`` along both plane axes (toroidal volume), with
``a = (w - 1) // 2`` (:func:`npmrf3d.model.kcoherence.anchor`); an exemplar neighbourhood at pixel ``p``
covers ``p - a .. p - a + w - 1`` and exists for the *valid centres*, the pixels whose window lies
inside the exemplar. Sources and centres are flat pixel indices ``row * W + col``.

Results depend only on the inputs: parallel loops write only their own site or voxel, and every
order-dependent step (histogram updates) runs in one thread in a fixed order.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._jit import jit, jit_inline, jit_parallel, prange


class SearchExemplar(NamedTuple):
    """One view's exemplar at one level as the search reads it (:func:`search_view`,
    :func:`candidates`).

    window, anchor : int, the window side and its anchor ``a``
    width : int, the exemplar's width (row stride of the flat pixel indices)
    lo_r, hi_r, lo_c, hi_c : int, the valid centres (inclusive)
    mean : (d,) float64, basis : (d, D) float64, the PCA of the neighbourhoods
    proj : (H * W, D) float64, the projection of every valid centre's neighbourhood
    kcoh : (H * W, k) int32, the k-coherence set of every valid centre
    texels : (H * W, C) float32, the exemplar's pixels (the trust-weighted distances of
        :func:`search_view` compare them in full)
    """

    window: int
    anchor: int
    width: int
    lo_r: int
    hi_r: int
    lo_c: int
    hi_c: int
    mean: np.ndarray
    basis: np.ndarray
    proj: np.ndarray
    kcoh: np.ndarray
    texels: np.ndarray


#: :func:`search_view`'s ``trust`` when every neighbour is trusted: PCA distances.
NO_TRUST = np.zeros((0, 0, 0), dtype=np.float32)


class SearchRule(NamedTuple):
    """The settings of one view's search (:func:`search_view`).

    grid : int, sites every ``grid`` voxels of the level's whole grid along both plane axes (at
        grid positions that are multiples of ``grid``: :func:`first_site`)
    batches : int, the slices along the normal axis ``n`` form batches ``n % batches``
    phi, index_weight : float, the index histogram's even share and strength; a candidate's
        distance is multiplied by ``1 + index_weight * max(0, index_hist[e] / phi - 1)``
    r, floor : float, IRLS exponent and distance floor, ``omega = max(dist, floor) ** (r - 2)``
    n_random, salt : int, extra uniformly random valid centres per site (:func:`random_centres`
        with the voxel's :func:`global_flat` index as site; 0 = none, the paper)
    origin, extent : (3,) int64 each, where the volume lies in the level's whole grid
        (:func:`global_flat`; the default ``extent`` 0: the volume is the whole grid)
    box_lo, box_hi : (3,) int64 each, only the sites with ``box_lo <= index < box_hi`` along
        every axis are searched (their assignments and weights kept elsewhere; the default: every
        site). A block's pass needs only the sites that vote for the voxels it decides.
    follow : bool, the index histogram follows the new assignments after each batch (False:
        nothing reads it -- ``index_weight`` 0 and no global search, as in a block -- so every
        site is searched in one parallel loop, its assignment written as it is found, and the
        histogram is left as it was; the same assignments)
    """

    grid: int
    batches: int
    phi: float
    index_weight: float
    r: float
    floor: float
    n_random: int
    salt: int
    origin: np.ndarray = np.zeros(3, dtype=np.int64)
    extent: np.ndarray = np.zeros(3, dtype=np.int64)
    box_lo: np.ndarray = np.zeros(3, dtype=np.int64)
    box_hi: np.ndarray = np.full(3, np.iinfo(np.int64).max, dtype=np.int64)
    follow: bool = True


@jit
def lattice_span(lo, hi, first, grid, count):
    """The lattice indices ``i`` (of ``count`` sites ``first + i * grid``) whose site lies in
    ``lo <= site < hi``: ``(i_lo, i_hi)``, empty when ``i_lo >= i_hi``."""
    i_lo = 0 if lo <= first else (lo - first + grid - 1) // grid
    i_hi = count if hi >= first + count * grid else max(0, (hi - first + grid - 1) // grid)
    return i_lo, min(i_hi, count)


@jit
def global_flat(p0, p1, p2, shape, origin, extent):
    """The flat index ``(g0 * E1 + g1) * E2 + g2`` of voxel ``(p0, p1, p2)`` of a volume of
    ``shape`` that is the region of a level's grid ``extent`` starting at ``origin`` (toroidal:
    ``g = (origin + p) % extent``); with ``extent[0] == 0`` the volume is the whole grid. The
    random numbers of a voxel hash this index, so a region made alone draws those of the whole."""
    if extent[0] == 0:
        return (p0 * shape[1] + p1) * shape[2] + p2
    g0 = (origin[0] + p0) % extent[0]
    g1 = (origin[1] + p1) % extent[1]
    g2 = (origin[2] + p2) % extent[2]
    return (g0 * extent[1] + g1) * extent[2] + g2


@jit
def first_site(origin, extent, axis, grid):
    """The array index of the first search site along ``axis`` of a volume that is the region
    of a level's grid starting at ``origin`` (``extent`` as :func:`global_flat`): sites lie at the
    grid positions that are multiples of ``grid``, so a region made alone searches the sites the
    whole grid searches there (0 for the whole grid)."""
    if extent[0] == 0:
        return 0
    return (grid - origin[axis] % grid) % grid


@jit
def grid_voxels(shape, extent):
    """Voxels of the level's whole grid: ``extent``'s product, or ``shape``'s when ``extent[0]`` is 0."""
    if extent[0] == 0:
        return shape[0] * shape[1] * shape[2]
    return extent[0] * extent[1] * extent[2]


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
def wrap(i, n):
    """``i % n`` (toroidal index) with the division only when ``i`` is outside ``0..n - 1``."""
    if i < 0 or i >= n:
        i %= n
    return i


@jit
def split(a, b, inv_b):
    """``(a // b, a % b)`` of ``0 <= a < 2**50`` and ``b >= 1`` (``inv_b = 1 / b``) by a
    floating-point quotient corrected to the exact integer one: no integer division."""
    q = np.int64(np.float64(a) * inv_b)
    r = a - q * b
    while r < 0:
        q -= 1
        r += b
    while r >= b:
        q += 1
        r -= b
    return q, r


@jit_inline
def gather(volume, ra, ca, n, u_r, u_c, window, anchor, trust, vec, weights):
    """The neighbourhood of the site at plane position ``(u_r, u_c)`` of slice ``n`` (view axes
    ``ra``, ``ca``; toroidal volume) into ``vec`` (``window**2 * C``, in (row, column, channel)
    order) and, when ``trust`` is not empty, each pixel's trust into ``weights`` (``window**2``).
    The pixels are read from the flat C-ordered volume at ``n * S_n + x_r * S_r + x_c * S_c``
    (``S`` the axes' strides in values)."""
    na = 3 - ra - ca
    nr = volume.shape[ra]
    nc = volume.shape[ca]
    channels = volume.shape[3]
    flat = volume.reshape(-1)
    step = (volume.shape[1] * volume.shape[2] * channels, volume.shape[2] * channels, channels)
    step_r = step[ra]
    step_c = step[ca]
    base = n * step[na]
    trusted = trust.shape[0] > 0
    m = 0
    for wr in range(window):
        x_r = wrap(u_r - anchor + wr, nr)
        row = base + x_r * step_r
        for wc in range(window):
            x_c = wrap(u_c - anchor + wc, nc)
            if trusted:
                q0 = n if na == 0 else (x_r if ra == 0 else x_c)
                q1 = n if na == 1 else (x_r if ra == 1 else x_c)
                q2 = n if na == 2 else (x_r if ra == 2 else x_c)
                weights[wr * window + wc] = trust[q0, q1, q2]
            at = row + x_c * step_c
            for ch in range(channels):
                vec[m] = flat[at + ch]
                m += 1


@jit_inline
def project(volume, ra, ca, n, u_r, u_c, window, anchor, mean, basis, vec, y):
    """PCA projection of the neighbourhood of the site at plane position ``(u_r, u_c)`` of
    slice ``n`` (view axes ``ra``, ``ca``; toroidal volume) into ``y`` (``vec``: scratch of
    ``window**2 * C``). The neighbourhood is read in (row, column, channel) order (:func:`gather`)
    minus ``mean``, then ``y = vec @ basis`` accumulated in that order."""
    dims = basis.shape[1]
    gather(volume, ra, ca, n, u_r, u_c, window, anchor, NO_TRUST, vec, vec)
    for m in range(vec.shape[0]):
        vec[m] -= mean[m]
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
def value_bins(values, lo, scale, bins, out):
    """Bins of every row of ``values`` (n, C) per channel (:func:`value_bin`) into ``out`` (n, C)."""
    for i in range(values.shape[0]):
        for ch in range(values.shape[1]):
            out[i, ch] = value_bin(values[i, ch], lo[ch], scale[ch], bins)


@jit_parallel
def voxel_batches(shape, origin, extent, salt, batches, lo, hi, out):
    """The batch ``mix(mix(g) + salt) % batches`` of every voxel of a region (``origin``,
    ``extent``: :func:`global_flat`; ``g`` its flat index in the level's whole grid) inside the
    box ``lo <= p < hi`` into ``out`` (``shape``, int16), -1 outside it: a voxel's batch depends on
    its grid position and ``salt < 2**31`` only, so a region made alone cuts its voxels as the
    whole grid does."""
    for p0 in prange(shape[0]):
        for p1 in range(shape[1]):
            for p2 in range(shape[2]):
                inside = lo[0] <= p0 < hi[0] and lo[1] <= p1 < hi[1] and lo[2] <= p2 < hi[2]
                out[p0, p1, p2] = mix(mix(global_flat(p0, p1, p2, shape, origin, extent)) + salt) % batches \
                    if inside else -1


@jit_parallel
def upsample_sources(src, ra, ca, coarse_width, fine_height, fine_width, out):
    """Child ``2 * x + o`` of every coarse voxel ``x`` gets the source ``2 * parent + offset``
    (:func:`npmrf3d.model.kcoherence.upsample_sources`): row ``2 * r + o[ra]`` and column ``2 * c +
    o[ca]`` of the finer exemplar (clipped into it), for ``src`` (N1, N2, N3) flat coarse sources
    and ``out`` (2 N1, 2 N2, 2 N3) int32."""
    for p0 in prange(src.shape[0]):
        for p1 in range(src.shape[1]):
            for p2 in range(src.shape[2]):
                r = 2 * (src[p0, p1, p2] // coarse_width)
                c = 2 * (src[p0, p1, p2] % coarse_width)
                for o0 in range(2):
                    for o1 in range(2):
                        for o2 in range(2):
                            o = (o0, o1, o2)
                            row = min(r + o[ra], fine_height - 1)
                            col = min(c + o[ca], fine_width - 1)
                            out[2 * p0 + o0, 2 * p1 + o1, 2 * p2 + o2] = row * fine_width + col


#: Parts of the voxels that :func:`group_by_batch` counts and places in parallel (a fixed number,
#: so the work is the same on any number of threads; the result does not depend on it).
GROUP_PARTS = 64


@jit_parallel
def group_by_batch(ids, batches, order, bounds):
    """The flat indices ``i`` of ``ids`` (int16, each voxel's batch ``0 .. batches - 1``, or -1
    for none) grouped by batch, in index order within a batch, into ``order``, and each batch's
    first position in it into ``bounds`` (``batches + 1`` entries): a counting sort, the order a
    stable sort of the non-negative ``ids`` gives. The indices are cut into
    :data:`GROUP_PARTS` parts, counted and placed each on its own, a part's share of a batch
    after the earlier parts'."""
    n = ids.shape[0]
    size = (n + GROUP_PARTS - 1) // GROUP_PARTS
    counts = np.zeros((GROUP_PARTS, batches), dtype=np.int64)
    for part in prange(GROUP_PARTS):
        for i in range(part * size, min(n, (part + 1) * size)):
            if ids[i] >= 0:
                counts[part, ids[i]] += 1
    starts = np.empty((GROUP_PARTS, batches), dtype=np.int64)
    bounds[0] = 0
    for b in range(batches):
        run = bounds[b]
        for part in range(GROUP_PARTS):
            starts[part, b] = run
            run += counts[part, b]
        bounds[b + 1] = run
    for part in prange(GROUP_PARTS):
        fill = starts[part]
        for i in range(part * size, min(n, (part + 1) * size)):
            b = ids[i]
            if b >= 0:
                order[fill[b]] = i
                fill[b] += 1


@jit
def sort_within_batches(order, bounds, n):
    """Each batch ``order[bounds[b]:bounds[b + 1]]`` of distinct indices ``0 .. n - 1`` sorted in
    place (ascending), by marking every index with its batch and grouping the marked ones by
    batch (:func:`group_by_batch`): one pass over ``n`` instead of a sort per batch."""
    mark = np.full(n, -1, dtype=np.int16)
    for b in range(bounds.shape[0] - 1):
        for i in range(bounds[b], bounds[b + 1]):
            mark[order[i]] = b
    group_by_batch(mark, bounds.shape[0] - 1, order, bounds.copy())


@jit_parallel
def central_texels(texels, out):
    """Every voxel's most central texel among the views' (:func:`npmrf3d.model.kcoherence_engine.initial_colours`):
    ``texels`` (V, n, C) float32, the views' texels of ``n`` voxels; ``out`` (n, C) float32 gets
    the one nearest (squared distance summed over channels) to their float64 mean (summed over
    the views in order, divided by V), the first view on ties."""
    n_views, n, channels = texels.shape
    for i in prange(n):
        best = 0
        best_d = np.inf
        for v in range(n_views):
            d = 0.0
            for ch in range(channels):
                centre = 0.0
                for u in range(n_views):
                    centre += np.float64(texels[u, i, ch])
                diff = np.float64(texels[v, i, ch]) - centre / n_views
                d += diff * diff
            if d < best_d:
                best_d = d
                best = v
        for ch in range(channels):
            out[i, ch] = texels[best, i, ch]


@jit_inline
def random_centres(salt, site, n_random, exemplar, out, start):
    """Append ``n_random`` valid centres of ``exemplar`` (:class:`SearchExemplar`) drawn from
    ``mix(salt + site * n_random + t)`` to ``out`` at ``start``; return the new count
    (``salt < 2**31``)."""
    nr = exemplar.hi_r - exemplar.lo_r + 1
    nc = exemplar.hi_c - exemplar.lo_c + 1
    inv_cells = 1.0 / (nr * nc)
    inv_nc = 1.0 / nc
    for t in range(n_random):
        h = mix(salt + site * n_random + t)
        cell = split(h, nr * nc, inv_cells)[1]  # h % (nr * nc)
        row, col = split(cell, nc, inv_nc)
        out[start + t] = (exemplar.lo_r + row) * exemplar.width + exemplar.lo_c + col
    return start + n_random


@jit_inline
def candidates(src_v, ra, ca, pos0, pos1, pos2, exemplar, out):
    """Fill ``out`` with the candidate centres of the site ``(pos0, pos1, pos2)``; return count.

    For every in-plane neighbour ``u + delta`` (``delta`` in ``{-1, 0, 1}^2``, row-major, the
    site itself included) with source ``s``: its coherent shift ``s - delta`` clamped to the
    valid centres ``[lo_r, hi_r] x [lo_c, hi_c]`` of ``exemplar`` (:class:`SearchExemplar`),
    then that centre's k-coherence set ``kcoh[shift]``. ``out`` needs ``9 * (1 + k)`` entries.
    """
    n0, n1, n2 = src_v.shape
    count = 0
    kcoh = exemplar.kcoh
    ewidth = exemplar.width
    lo_r, hi_r, lo_c, hi_c = exemplar.lo_r, exemplar.hi_r, exemplar.lo_c, exemplar.hi_c
    k = kcoh.shape[1]
    inv_width = 1.0 / ewidth
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            q0 = pos0
            q1 = pos1
            q2 = pos2
            if ra == 0:
                q0 = wrap(pos0 + dr, n0)
            elif ra == 1:
                q1 = wrap(pos1 + dr, n1)
            else:
                q2 = wrap(pos2 + dr, n2)
            if ca == 0:
                q0 = wrap(pos0 + dc, n0)
            elif ca == 1:
                q1 = wrap(pos1 + dc, n1)
            else:
                q2 = wrap(pos2 + dc, n2)
            s_r, s_c = split(np.int64(src_v[q0, q1, q2]), ewidth, inv_width)
            sr = s_r - dr
            sc = s_c - dc
            sr = min(max(sr, lo_r), hi_r)
            sc = min(max(sc, lo_c), hi_c)
            centre = sr * ewidth + sc
            out[count] = centre
            count += 1
            for t in range(k):
                out[count] = kcoh[centre, t]
                count += 1
    return count


@jit_inline
def trusted_distance(vec, weights, exemplar, e):
    """Squared distance of a neighbourhood gathered by :func:`gather` (values ``vec``, trusts
    ``weights``) to the exemplar neighbourhood centred at ``e``, each pixel's term weighted by
    its trust ``1 - t`` (Urs et al. 2014): summed over rows, columns, channels."""
    window, anchor, width, texels = exemplar.window, exemplar.anchor, exemplar.width, exemplar.texels
    channels = texels.shape[1]
    er = e // width - anchor
    ec = e % width - anchor
    d2 = 0.0
    for wr in range(window):
        for wc in range(window):
            weight = np.float64(weights[wr * window + wc])
            if weight == 0.0:
                continue
            g = (er + wr) * width + ec + wc
            m = (wr * window + wc) * channels
            part = 0.0
            for ch in range(channels):
                diff = vec[m + ch] - np.float64(texels[g, ch])
                part += diff * diff
            d2 += weight * part
    return d2


@jit_inline
def distinct_blocks(cand, count, kk, keep):
    """The candidates ``cand[:count]`` of :func:`candidates` (and :func:`random_centres`) into
    ``keep`` without the neighbours' blocks that repeat an earlier block: a block is a coherent
    shift and its k-coherence set (``kk`` entries), so one whose shift equals an earlier block's
    repeats it entirely. A repeated candidate has the cost of its first occurrence, so an
    argmin that keeps the first minimum is the same over ``keep``. Returns the number kept."""
    blocks = min(9, count // kk)
    n = 0
    for bi in range(blocks):
        centre = cand[bi * kk]
        repeat = False
        for bj in range(bi):
            if cand[bj * kk] == centre:
                repeat = True
                break
        if repeat:
            continue
        for t in range(bi * kk, (bi + 1) * kk):
            keep[n] = cand[t]
            n += 1
    for t in range(blocks * kk, count):
        keep[n] = cand[t]
        n += 1
    return n


@jit_inline
def pca_distances(y, proj, keep, count, out):
    """Squared distances ``sum_j (y[j] - proj[e, j])**2`` (summed in ``j`` order) of ``y`` to the
    projections of the centres ``keep[:count]`` into ``out``; eight centres at a time, each its
    own sum, so the same bits as one at a time with eight independent chains of additions
    instead of one."""
    dims = y.shape[0]
    i = 0
    while i + 8 <= count:
        e0 = keep[i]
        e1 = keep[i + 1]
        e2 = keep[i + 2]
        e3 = keep[i + 3]
        e4 = keep[i + 4]
        e5 = keep[i + 5]
        e6 = keep[i + 6]
        e7 = keep[i + 7]
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
        for j in range(dims):
            yj = y[j]
            d0 = yj - proj[e0, j]
            d1 = yj - proj[e1, j]
            d2 = yj - proj[e2, j]
            d3 = yj - proj[e3, j]
            d4 = yj - proj[e4, j]
            d5 = yj - proj[e5, j]
            d6 = yj - proj[e6, j]
            d7 = yj - proj[e7, j]
            s0 += d0 * d0
            s1 += d1 * d1
            s2 += d2 * d2
            s3 += d3 * d3
            s4 += d4 * d4
            s5 += d5 * d5
            s6 += d6 * d6
            s7 += d7 * d7
        out[i] = s0
        out[i + 1] = s1
        out[i + 2] = s2
        out[i + 3] = s3
        out[i + 4] = s4
        out[i + 5] = s5
        out[i + 6] = s6
        out[i + 7] = s7
        i += 8
    while i < count:
        e = keep[i]
        d2 = 0.0
        for j in range(dims):
            diff = y[j] - proj[e, j]
            d2 += diff * diff
        out[i] = d2
        i += 1


@jit_parallel
def search_view(volume, src_v, ra, ca, exemplar, rule, index_hist, assign_v, fresh_v, omega_v, energy, trust):
    """Search phase of one view (paper section 4.3 with eq. 5-6).

    Parameters
    ----------
    volume : (N0, N1, N2, C) float32
    src_v : (N0, N1, N2) int32, this view's source pixel of every voxel
    ra, ca : volume axes of the exemplar row and column
    exemplar : SearchExemplar, the view's exemplar model at this level
    rule : SearchRule, the site spacing, batches, index histogram, IRLS and random candidates
    index_hist : (H * W,) float64, updated in place: sites currently assigned to each centre
    assign_v : (N0, N1, N2) int32, in/out: the centre matched at every site (-1 elsewhere;
        on entry the previous assignment, whose counts ``index_hist`` holds)
    fresh_v : (N0, N1, N2) int32, scratch for the new assignments of a batch
    omega_v : (N0, N1, N2) float32, out: IRLS weight at every site
    energy : (N_normal,) float64, out: ``sum dist ** r`` over the sites of each slice
    trust : (N0, N1, N2) float32 or :data:`NO_TRUST`
        Every voxel's trust ``1 - t`` (ICM with per-voxel temperatures): the distances are then
        the full-dimensional ones with each pixel's term weighted by its trust
        (:func:`trusted_distance`) instead of the PCA ones.
    """
    weighted = trust.shape[0] > 0
    window, anchor, mean, basis, proj = exemplar.window, exemplar.anchor, exemplar.mean, exemplar.basis, exemplar.proj
    grid, batches, phi, index_weight, r, floor = rule.grid, rule.batches, rule.phi, rule.index_weight, rule.r, rule.floor
    n_random, salt = rule.n_random, rule.salt
    na = 3 - ra - ca
    shape = volume.shape
    nn = shape[na]
    nr = shape[ra]
    nc = shape[ca]
    channels = shape[3]
    d = window * window * channels
    dims = basis.shape[1]
    kk = 1 + exemplar.kcoh.shape[1]
    cap = 9 * kk + n_random
    sr = first_site(rule.origin, rule.extent, ra, grid)
    sc = first_site(rule.origin, rule.extent, ca, grid)
    gr = (nr - sr + grid - 1) // grid
    gc = (nc - sc + grid - 1) // grid
    ar_lo, ar_hi = lattice_span(rule.box_lo[ra], rule.box_hi[ra], sr, grid, gr)
    ac_lo, ac_hi = lattice_span(rule.box_lo[ca], rule.box_hi[ca], sc, grid, gc)
    n_lo, n_hi = rule.box_lo[na], rule.box_hi[na]
    follow = rule.follow
    rounds = batches if follow else 1
    # each centre's cost factor while the index histogram is frozen (one batch):
    # 1 + index_weight * excess when over-used, else exactly 1.0 (a distance keeps its bits)
    factor = np.empty(index_hist.shape[0], dtype=np.float64)
    for b in range(rounds):
        nb = (nn - b + rounds - 1) // rounds
        for e in range(index_hist.shape[0]):
            excess = index_hist[e] / phi - 1.0
            factor[e] = 1.0 + index_weight * excess if excess > 0.0 else 1.0
        for t in prange(nb):
            n = b + t * rounds
            if n < n_lo or n >= n_hi:
                continue
            vec = np.empty(d, dtype=np.float64)
            y = np.empty(dims, dtype=np.float64)
            cand = np.empty(cap, dtype=np.int64)
            keep = np.empty(cap, dtype=np.int64)
            dists = np.empty(cap, dtype=np.float64)
            weights = np.empty(window * window, dtype=np.float32)
            acc = 0.0
            for ar in range(ar_lo, ar_hi):
                u_r = sr + ar * grid
                for ac in range(ac_lo, ac_hi):
                    u_c = sc + ac * grid
                    p0 = n if na == 0 else (u_r if ra == 0 else u_c)
                    p1 = n if na == 1 else (u_r if ra == 1 else u_c)
                    p2 = n if na == 2 else (u_r if ra == 2 else u_c)
                    if weighted:
                        gather(volume, ra, ca, n, u_r, u_c, window, anchor, trust, vec, weights)
                    else:
                        project(volume, ra, ca, n, u_r, u_c, window, anchor, mean, basis, vec, y)
                    count = candidates(src_v, ra, ca, p0, p1, p2, exemplar, cand)
                    if n_random > 0:
                        count = random_centres(salt, global_flat(p0, p1, p2, shape, rule.origin, rule.extent),
                                               n_random, exemplar, cand, count)
                    count = distinct_blocks(cand, count, kk, keep)
                    if weighted:
                        for t2 in range(count):
                            dists[t2] = trusted_distance(vec, weights, exemplar, keep[t2])
                    else:
                        pca_distances(y, proj, keep, count, dists)
                    best = -1
                    best_cost = np.inf
                    best_d2 = 0.0
                    for t2 in range(count):
                        e = keep[t2]
                        d2 = dists[t2]
                        cost = d2 * factor[e]
                        if cost < best_cost:
                            best_cost = cost
                            best = e
                            best_d2 = d2
                    dist = np.sqrt(best_d2)
                    acc += dist ** r
                    omega_v[p0, p1, p2] = max(dist, floor) ** (r - 2.0)
                    if follow:
                        fresh_v[p0, p1, p2] = best
                    else:
                        assign_v[p0, p1, p2] = best
            energy[n] = acc
        if not follow:
            continue
        # sequential, fixed order: move the batch's sites from their old centres to the new ones
        for t in range(nb):
            n = b + t * rounds
            if n < n_lo or n >= n_hi:
                continue
            for ar in range(ar_lo, ar_hi):
                for ac in range(ac_lo, ac_hi):
                    u_r = sr + ar * grid
                    u_c = sc + ac * grid
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
