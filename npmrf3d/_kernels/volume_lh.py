"""Compiled loops of the 3D-exemplar method (:mod:`npmrf3d.methods.volume_lh`).

Private: called with validated arrays only; nothing here raises a user-facing error.

* :func:`similarity_sets` (parallel over exemplar voxels): from each voxel's nearest neighbours
  in appearance space, the ``k`` most similar voxels with every later one outside the
  ``exclude``-neighbourhood (Chebyshev) of all earlier ones; the first is the voxel itself.
* :func:`project` (parallel over exemplar slices): appearance-space vectors of every voxel.
* :func:`correct_parzen`: the same sub-pass decided by the Parzen LCPDF of full ``w^3``
  neighbourhoods (the NP-MRF with one 3D view, ``npmrf-3d``).
* :func:`correct` (parallel over the planes of one parity class): one voxel-correction sub-pass.
  Reads coordinates from ``coords`` and writes the corrected ones to ``out`` (Jacobi within the
  sub-pass), so a voxel's result depends on the inputs only, never on the thread count.

Coordinates are exemplar voxel positions ``(a, b, c)`` kept inside the valid box ``[lo, hi]``
per axis; ``feat`` is the appearance-space exemplar ``(D, H, W, d)`` (PCA of 5^3 neighbourhoods);
``kset`` holds flat exemplar indices ``(a * H + b) * W + c`` (in :func:`correct`: the same sets
as positions, ``(D * H * W, k, 3)``).
"""

from __future__ import annotations

import numpy as np

from ._jit import jit, jit_parallel, prange

#: The eight diagonal neighbours (+-1, +-1, +-1) of the synthesis neighbourhood (the
#: vector-field deformation method, IET Image Processing 2012, eq. 3).
DIAGONALS = np.array([[a, b, c] for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)], dtype=np.int64)
#: The six face neighbours, added by the ``faces`` neighbourhood (the diagonals alone split the
#: grid into four sub-lattices that never see each other).
FACES = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], dtype=np.int64)


@jit_parallel
def similarity_sets(neighbours, coords, k, exclude, out):
    """``out[q, :]`` = the ``k``-set of valid voxel ``q`` (row ``q`` of ``neighbours``: its nearest
    valid voxels in appearance space, itself first, as row indices; ``coords`` their positions).
    Where fewer than ``k`` satisfy the exclusion, the set is filled with the nearest remaining."""
    n, m = neighbours.shape
    for q in prange(n):
        out[q, 0] = neighbours[q, 0]
        count = 1
        for t in range(1, m):
            if count == k:
                break
            cand = neighbours[q, t]
            ok = True
            for s in range(count):
                prev = out[q, s]
                dz = abs(coords[cand, 0] - coords[prev, 0])
                dy = abs(coords[cand, 1] - coords[prev, 1])
                dx = abs(coords[cand, 2] - coords[prev, 2])
                if max(dz, max(dy, dx)) <= exclude:
                    ok = False
                    break
            if ok:
                out[q, count] = cand
                count += 1
        t = 1
        while count < k:  # too few far-apart neighbours: nearest ones, in order
            out[q, count] = neighbours[q, min(t, m - 1)]
            count += 1
            t += 1


@jit
def _clamp(v, lo, hi):
    return lo if v < lo else (hi if v > hi else v)


@jit
def _wrap(q, n):
    """``q % n`` for a ``q`` a few periods off (neighbour offsets), without a division."""
    while q < 0:
        q += n
    while q >= n:
        q -= n
    return q


@jit
def _offset(frames, single, i, j, k, offsets, d, out):
    """``out = floor(R(i, j, k) @ offsets[d] + 0.5)``: the output-space offset of offset ``d``."""
    fi = 0 if single else i
    fj = 0 if single else j
    fk = 0 if single else k
    for r in range(3):
        s = 0.0
        for c in range(3):
            s += frames[fi, fj, fk, r, c] * offsets[d, c]
        out[r] = np.int64(np.floor(s + 0.5))


@jit
def _distance(feat, a, b, c, h, offsets, neigh, shape, bound):
    """``sum_D ||feat[(a, b, c) + h D] - neigh[D]||^2`` over ``offsets`` (positions clamped to
    the exemplar); stops early once the partial sum reaches ``bound`` (it can then only be
    ``>= bound``, and a candidate must be strictly better to win, so the choice is unchanged)."""
    total = 0.0
    dims = feat.shape[3]
    for d in range(offsets.shape[0]):
        if total >= bound:
            return total
        x = _clamp(a + h * offsets[d, 0], 0, shape[0] - 1)
        y = _clamp(b + h * offsets[d, 1], 0, shape[1] - 1)
        z = _clamp(c + h * offsets[d, 2], 0, shape[2] - 1)
        for e in range(dims):
            diff = feat[x, y, z, e] - neigh[d, e]
            total += diff * diff
    return total


@jit
def _distance_flat(flat_feat, base, flat_offsets, neigh, bound):
    """:func:`_distance` where no position needs clamping: ``flat_feat`` is ``feat`` as
    ``(D * H * W, d)``, ``base`` the candidate's flat index and ``flat_offsets[D]`` the flat
    step of ``h D``; the same sums in the same order (the same bits), without the index arithmetic."""
    total = 0.0
    dims = flat_feat.shape[1]
    for d in range(flat_offsets.shape[0]):
        if total >= bound:
            return total
        row = base + flat_offsets[d]
        for e in range(dims):
            diff = flat_feat[row, e] - neigh[d, e]
            total += diff * diff
    return total


@jit
def _usage_penalty(counts, h, ua, ub, uc, own, even, weight):
    """Position-histogram penalty ``weight * max(0, c / even - 1)`` of candidate ``u``: ``c`` is
    the count of the exemplar cell ``u // h`` (``counts``), less one if it is the cell ``own`` of
    the voxel's current coordinate (its own use)."""
    if weight == 0.0:
        return 0.0
    ca, cb, cc = ua // h, ub // h, uc // h
    c = counts[ca, cb, cc]
    if (ca * counts.shape[1] + cb) * counts.shape[2] + cc == own:
        c -= 1.0
    return weight * max(0.0, c / even - 1.0)


#: Early termination stops at ``best - penalty`` raised by this share of ``best``, so that a
#: partial sum that stops can never have been a winner once its penalty is added (rounding).
BOUND_SLACK = 1e-9


@jit_parallel
def correct(coords, out, frames, feat, kset, h, lo, hi, offsets, parity, cost, counts, even,
            weight, bias):
    """One correction sub-pass over the voxels ``(i, j, k)`` with ``(i % 2, j % 2, k % 2) ==
    parity`` (the vector-field deformation method, IET Image Processing 2012, section 3.2.4).

    For voxel ``p`` and every ``D`` of ``offsets`` (the 8 diagonals of the paper, or more): the
    warped neighbours ``I_D = p + floor(R(p) D + 0.5)`` (toroidal), the
    neighbourhood vector ``[feat[coords[I_D]]]_D``; candidates ``kset[coords[I_D]][j] - h D``
    (clamped to the valid box) and the current coordinate; the candidate ``u`` minimising
    ``sum_D ||feat[u + h D] - feat[coords[I_D]]||^2 + P(u)`` (first on ties) is written to
    ``out[p]`` and that score to ``cost[p]``. ``P`` is the position-histogram penalty
    (:func:`_usage_penalty`: ``counts`` holds how many voxels use each ``h``-cell of the
    exemplar, ``even`` the count of an even use; ``weight = 0`` gives ``P = 0``, the paper's rule)
    plus ``bias[u]``, a non-negative cost of the exemplar voxel itself (the phase-histogram
    balance, :func:`npmrf3d.model.phases.class_balance`); a ``(1, 1, 1)`` ``bias`` means none.
    ``frames`` is ``(N1, N2, N3, 3, 3)`` or ``(1, 1, 1, 3, 3)`` (one frame for all voxels).

    A candidate equal to one already scored is skipped: its distance is the same, and only a
    strictly smaller one wins, so the choice is that of scoring every candidate (coherent
    neighbours propose the same coordinate many times). ``kset`` holds the sets as exemplar
    positions, ``(D * H * W, k, 3)`` (row: flat index of the voxel), so no candidate is decoded by
    division. Where ``[lo - h |D|, hi + h |D|]`` lies
    inside the exemplar (every level but the coarsest ones) no position is clamped, and the
    distances run on flat indices (:func:`_distance_flat`). The loop runs in parallel over planes
    ``i`` of the parity class, each with its own scratch arrays; every voxel's result depends on
    the inputs only.
    """
    n1, n2, n3 = coords.shape[0], coords.shape[1], coords.shape[2]
    shape = np.array([feat.shape[0], feat.shape[1], feat.shape[2]], dtype=np.int64)
    single = frames.shape[0] == 1
    biased = bias.shape[0] > 1
    dims = feat.shape[3]
    k = kset.shape[1]
    n_off = offsets.shape[0]
    plane = shape[1] * shape[2]
    c0 = (n1 - parity[0] + 1) // 2
    reach = 0
    for d in range(n_off):
        for r in range(3):
            reach = max(reach, h * abs(offsets[d, r]))
    inside = True
    for r in range(3):
        if lo[r] - reach < 0 or hi[r] + reach > shape[r] - 1:
            inside = False
    flat_feat = feat.reshape(shape[0] * plane, dims)  # a view: feat is C-contiguous
    flat_offsets = np.empty(n_off, dtype=np.int64)
    for d in range(n_off):
        flat_offsets[d] = (h * offsets[d, 0] * shape[1] + h * offsets[d, 1]) * shape[2] + h * offsets[d, 2]
    for ti in prange(c0):
        i = parity[0] + 2 * ti
        off = np.empty(3, dtype=np.int64)
        neigh = np.empty((n_off, dims), dtype=np.float64)
        src = np.empty((n_off, 3), dtype=np.int64)
        seen = np.empty(1 + n_off * k, dtype=np.int64)
        for j in range(parity[1], n2, 2):
            for kk in range(parity[2], n3, 2):
                for d in range(n_off):
                    _offset(frames, single, i, j, kk, offsets, d, off)
                    qi = _wrap(i + off[0], n1)
                    qj = _wrap(j + off[1], n2)
                    qk = _wrap(kk + off[2], n3)
                    for r in range(3):
                        src[d, r] = coords[qi, qj, qk, r]
                    for e in range(dims):
                        neigh[d, e] = feat[src[d, 0], src[d, 1], src[d, 2], e]
                ba, bb, bc = coords[i, j, kk, 0], coords[i, j, kk, 1], coords[i, j, kk, 2]
                seen[0] = (ba * shape[1] + bb) * shape[2] + bc
                own = ((ba // h) * counts.shape[1] + bb // h) * counts.shape[2] + bc // h
                if inside:
                    best = _distance_flat(flat_feat, seen[0], flat_offsets, neigh, np.inf)
                else:
                    best = _distance(feat, ba, bb, bc, h, offsets, neigh, shape, np.inf)
                best += _usage_penalty(counts, h, ba, bb, bc, own, even, weight)
                if biased:
                    best += bias[ba, bb, bc]
                n_seen = 1
                for d in range(n_off):
                    flat = (src[d, 0] * shape[1] + src[d, 1]) * shape[2] + src[d, 2]
                    for s in range(k):
                        ua = _clamp(kset[flat, s, 0] - h * offsets[d, 0], lo[0], hi[0])
                        ub = _clamp(kset[flat, s, 1] - h * offsets[d, 1], lo[1], hi[1])
                        uc = _clamp(kset[flat, s, 2] - h * offsets[d, 2], lo[2], hi[2])
                        key = (ua * shape[1] + ub) * shape[2] + uc
                        fresh = True
                        for t in range(n_seen):
                            if seen[t] == key:
                                fresh = False
                                break
                        if not fresh:
                            continue
                        seen[n_seen] = key
                        n_seen += 1
                        penalty = _usage_penalty(counts, h, ua, ub, uc, own, even, weight)
                        if biased:
                            penalty += bias[ua, ub, uc]
                        bound = best - penalty + BOUND_SLACK * best if penalty != 0.0 else best
                        if inside:
                            dist = _distance_flat(flat_feat, key, flat_offsets, neigh, bound)
                        else:
                            dist = _distance(feat, ua, ub, uc, h, offsets, neigh, shape, bound)
                        if penalty != 0.0:
                            dist += penalty
                        if dist < best:
                            best = dist
                            ba, bb, bc = ua, ub, uc
                out[i, j, kk, 0] = ba
                out[i, j, kk, 1] = bb
                out[i, j, kk, 2] = bc
                cost[i, j, kk] = best


@jit_parallel
def project(ex, h, radius, mean, basis, out):
    """``out[x] = (N(x) - mean) @ basis``: the appearance-space vector of every exemplar voxel.

    ``N(x)`` is the ``(2 radius + 1)^3``-neighbourhood of ``x`` sampled every ``h`` voxels in
    ``ex`` ``(D, H, W, C)``, positions clamped to the exemplar, flattened offset-major (offsets
    in lexicographic order, channels inside), as ``mean`` ``(n C,)`` and ``basis`` ``(n C, d)``.
    """
    d0, d1, d2, channels = ex.shape
    dims = basis.shape[1]
    side = 2 * radius + 1
    for x in prange(d0):
        acc = np.empty(dims, dtype=np.float64)
        for y in range(d1):
            for z in range(d2):
                for e in range(dims):
                    acc[e] = 0.0
                for t in range(side * side * side):
                    a = _clamp(x + h * (t // (side * side) - radius), 0, d0 - 1)
                    b = _clamp(y + h * ((t // side) % side - radius), 0, d1 - 1)
                    c = _clamp(z + h * (t % side - radius), 0, d2 - 1)
                    for ch in range(channels):
                        row = t * channels + ch
                        v = ex[a, b, c, ch] - mean[row]
                        for e in range(dims):
                            acc[e] += v * basis[row, e]
                for e in range(dims):
                    out[x, y, z, e] = acc[e]


@jit_parallel
def correct_parzen(coords, out, frames, feat, values, kset, h, lo, hi, offsets, window_offsets,
                   parity, adaptive, centre_h2, cost):
    """One sub-pass of the NP-MRF with one 3D view (``npmrf-3d``): the same coherent candidates
    as :func:`correct`, decided by the Parzen LCPDF over full ``w^3`` neighbourhoods.

    For voxel ``p`` with candidates ``u`` (the current coordinate first): the neighbourhood
    distance ``D_u = sum_r ||values[coords[p + R r]] - values[u + h r]||^2`` over
    ``window_offsets`` (the ``w^3`` offsets without the centre; positions clamped to the
    exemplar), log-weights ``a_u = -D_u / (adaptive * max(min D, 1e-12))``, and for each candidate
    centre value ``y_u = values[u]`` the log-LCPDF ``log sum_v exp(a_v - ||y_u - y_v||^2 /
    (2 centre_h2))``; the candidate with the largest (first on ties) is written to ``out[p]``
    and its ``D_u`` to ``cost[p]``.
    """
    n1, n2, n3 = coords.shape[0], coords.shape[1], coords.shape[2]
    shape = np.array([feat.shape[0], feat.shape[1], feat.shape[2]], dtype=np.int64)
    single = frames.shape[0] == 1
    channels = values.shape[3]
    k = kset.shape[1]
    n_off = offsets.shape[0]
    n_win = window_offsets.shape[0]
    n_cand = 1 + n_off * k
    c1 = (n2 - parity[1] + 1) // 2
    c2 = (n3 - parity[2] + 1) // 2
    count = ((n1 - parity[0] + 1) // 2) * c1 * c2
    for t in prange(count):
        i = parity[0] + 2 * (t // (c1 * c2))
        j = parity[1] + 2 * ((t // c2) % c1)
        kk = parity[2] + 2 * (t % c2)
        off = np.empty(3, dtype=np.int64)
        cand = np.empty((n_cand, 3), dtype=np.int64)
        cand[0, 0], cand[0, 1], cand[0, 2] = coords[i, j, kk, 0], coords[i, j, kk, 1], coords[i, j, kk, 2]
        for d in range(n_off):
            _offset(frames, single, i, j, kk, offsets, d, off)
            qi = (i + off[0]) % n1
            qj = (j + off[1]) % n2
            qk = (kk + off[2]) % n3
            flat = (coords[qi, qj, qk, 0] * shape[1] + coords[qi, qj, qk, 1]) * shape[2] + coords[qi, qj, qk, 2]
            for s in range(k):
                q = kset[flat, s]
                row = 1 + d * k + s
                cand[row, 0] = _clamp(q // (shape[1] * shape[2]) - h * offsets[d, 0], lo[0], hi[0])
                cand[row, 1] = _clamp((q // shape[2]) % shape[1] - h * offsets[d, 1], lo[1], hi[1])
                cand[row, 2] = _clamp(q % shape[2] - h * offsets[d, 2], lo[2], hi[2])
        neigh = np.empty((n_win, channels), dtype=np.float64)
        for r in range(n_win):
            _offset(frames, single, i, j, kk, window_offsets, r, off)
            qi = (i + off[0]) % n1
            qj = (j + off[1]) % n2
            qk = (kk + off[2]) % n3
            for ch in range(channels):
                neigh[r, ch] = values[coords[qi, qj, qk, 0], coords[qi, qj, qk, 1], coords[qi, qj, qk, 2], ch]
        dist = np.empty(n_cand, dtype=np.float64)
        dmin = np.inf
        for u in range(n_cand):
            total = 0.0
            for r in range(n_win):
                x = _clamp(cand[u, 0] + h * window_offsets[r, 0], 0, shape[0] - 1)
                y = _clamp(cand[u, 1] + h * window_offsets[r, 1], 0, shape[1] - 1)
                z = _clamp(cand[u, 2] + h * window_offsets[r, 2], 0, shape[2] - 1)
                for ch in range(channels):
                    diff = values[x, y, z, ch] - neigh[r, ch]
                    total += diff * diff
            dist[u] = total
            if total < dmin:
                dmin = total
        scale = adaptive * max(dmin, 1e-12)
        best_score = -np.inf
        best = 0
        for u in range(n_cand):
            top = -np.inf
            terms = np.empty(n_cand, dtype=np.float64)
            for v in range(n_cand):
                c = 0.0
                for ch in range(channels):
                    diff = values[cand[u, 0], cand[u, 1], cand[u, 2], ch] - values[cand[v, 0], cand[v, 1], cand[v, 2], ch]
                    c += diff * diff
                terms[v] = -dist[v] / scale - c / (2.0 * centre_h2)
                if terms[v] > top:
                    top = terms[v]
            acc = 0.0
            for v in range(n_cand):
                acc += np.exp(terms[v] - top)
            score = top + np.log(acc)
            if score > best_score:
                best_score = score
                best = u
        out[i, j, kk, 0] = cand[best, 0]
        out[i, j, kk, 1] = cand[best, 1]
        out[i, j, kk, 2] = cand[best, 2]
        cost[i, j, kk] = dist[best]
