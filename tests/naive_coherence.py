"""Slow, literal numpy twins of the k-coherence kernels (Chen & Wang 2010; issue 11).

Written from the definitions in the paper and the docstrings of :mod:`npmrf3d.coherence`, with
plain loops in float64 and no scratch buffers (to be folded into ``tests/naive.py``). Geometry:
a window of side ``w`` at plane position ``u`` covers ``u - a .. u - a + w - 1``, ``a = (w-1)//2``;
the volume wraps around, the exemplar does not; sources and centres are flat ``row * W + col``.
"""

from __future__ import annotations

import numpy as np

#: view -> (volume axis of the exemplar row, volume axis of the exemplar column)
NAIVE_VIEW_AXES = {"front": (0, 1), "right": (1, 2), "top": (0, 2)}


def naive_anchor(window):
    return (window - 1) // 2


def naive_site(view, normal, row, col):
    """3D voxel of plane position (row, col) on the slice ``normal`` of ``view``."""
    ra, ca = NAIVE_VIEW_AXES[view]
    p = [0, 0, 0]
    p[3 - ra - ca] = normal
    p[ra] = row
    p[ca] = col
    return tuple(p)


def naive_exemplar_patch(exemplar, centre_r, centre_c, window):
    a = naive_anchor(window)
    return exemplar[centre_r - a:centre_r - a + window, centre_c - a:centre_c - a + window].astype(np.float64).reshape(-1)


def naive_volume_patch(volume, view, site, window):
    ra, ca = NAIVE_VIEW_AXES[view]
    a = naive_anchor(window)
    out = []
    for dr in range(window):
        for dc in range(window):
            p = list(site)
            p[ra] = (site[ra] - a + dr) % volume.shape[ra]
            p[ca] = (site[ca] - a + dc) % volume.shape[ca]
            out.extend(float(x) for x in volume[p[0], p[1], p[2]])
    return np.array(out)


def naive_k_coherence(points, k, exclude=0.0, coords=None):
    """Brute force: for each point the k nearest *other* points (Euclidean, ties by index)."""
    points = np.asarray(points, dtype=np.float64)
    out = []
    for i in range(len(points)):
        dist = np.sqrt(((points - points[i]) ** 2).sum(axis=1))
        order = sorted(range(len(points)), key=lambda j: (dist[j], j))
        chosen = []
        for j in order:
            if j == i:
                continue
            if exclude > 0 and np.abs(coords[j] - coords[i]).max() <= exclude:
                continue
            chosen.append(j)
            if len(chosen) == k:
                break
        out.append(chosen)
    return np.array(out)


def naive_candidates(src_v, view, site, ewidth, bounds, kcoh):
    """The candidate set of the definition: neighbours' coherent shifts and their k-coherence sets."""
    ra, ca = NAIVE_VIEW_AXES[view]
    lo_r, hi_r, lo_c, hi_c = bounds
    out = set()
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            q = list(site)
            q[ra] = (site[ra] + dr) % src_v.shape[ra]
            q[ca] = (site[ca] + dc) % src_v.shape[ca]
            s = int(src_v[q[0], q[1], q[2]])
            r = min(max(s // ewidth - dr, lo_r), hi_r)
            c = min(max(s % ewidth - dc, lo_c), hi_c)
            centre = r * ewidth + c
            out.add(centre)
            out.update(int(x) for x in kcoh[centre])
    return sorted(out)


def naive_candidate_list(src_v, view, site, ewidth, bounds, kcoh):
    """Same as :func:`naive_candidates` but as the ordered list with repeats (neighbours row-major,
    each shift followed by its set): the order in which ties are resolved."""
    ra, ca = NAIVE_VIEW_AXES[view]
    lo_r, hi_r, lo_c, hi_c = bounds
    out = []
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            q = list(site)
            q[ra] = (site[ra] + dr) % src_v.shape[ra]
            q[ca] = (site[ca] + dc) % src_v.shape[ca]
            s = int(src_v[q[0], q[1], q[2]])
            centre = min(max(s // ewidth - dr, lo_r), hi_r) * ewidth + min(max(s % ewidth - dc, lo_c), hi_c)
            out.append(centre)
            out.extend(int(x) for x in kcoh[centre])
    return out


def naive_mix(x):
    """The kernel's 31-bit hash, in Python integers."""
    h = (x ^ (x >> 31)) & 0x7FFFFFFF
    for shift, mult in ((15, 0x2C1B3C6D), (12, 0x297A2D39), (15, 0x2C1B3C6D)):
        h = ((h ^ (h >> shift)) * mult) & 0x7FFFFFFF
    return h ^ (h >> 15)


def naive_random_centres(salt, site_flat, n_random, bounds, ewidth):
    lo_r, hi_r, lo_c, hi_c = bounds
    nr, nc = hi_r - lo_r + 1, hi_c - lo_c + 1
    out = []
    for t in range(n_random):
        cell = naive_mix(salt + site_flat * n_random + t) % (nr * nc)
        out.append((lo_r + cell // nc) * ewidth + lo_c + cell % nc)
    return out


def naive_search_view(volume, src_v, view, model, *, grid, batches, index_hist, phi, index_weight,
                      r, floor, assign_v, n_random=0, salt=0):
    """Literal search phase of one view; returns (assign, omega, energy per slice, index_hist)."""
    ra, ca = NAIVE_VIEW_AXES[view]
    na = 3 - ra - ca
    ex = model.exemplar
    w = ex.shape[1]
    window = model.window
    hist = index_hist.astype(np.float64).copy()
    assign = assign_v.copy()
    omega = np.zeros(volume.shape[:3])
    energy = np.zeros(volume.shape[na])
    for b in range(batches):
        fresh = {}
        for n in range(b, volume.shape[na], batches):
            for row in range(0, volume.shape[ra], grid):
                for col in range(0, volume.shape[ca], grid):
                    site = naive_site(view, n, row, col)
                    y = (naive_volume_patch(volume, view, site, window) - model.mean) @ model.basis.astype(np.float64)
                    best, best_cost, best_d2 = None, np.inf, 0.0
                    cands = naive_candidate_list(src_v, view, site, w, model.bounds, model.kcoh)
                    flat = (site[0] * volume.shape[1] + site[1]) * volume.shape[2] + site[2]
                    cands += naive_random_centres(salt, flat, n_random, model.bounds, w)
                    for e in cands:
                        d2 = float(((y - model.proj[e].astype(np.float64)) ** 2).sum())
                        cost = d2 * (1.0 + index_weight * max(0.0, hist[e] / phi - 1.0))
                        if cost < best_cost:
                            best, best_cost, best_d2 = e, cost, d2
                    dist = np.sqrt(best_d2)
                    energy[n] += dist ** r
                    omega[site] = max(dist, floor) ** (r - 2.0)
                    fresh[site] = best
        for site, best in fresh.items():
            if assign[site] >= 0:
                hist[assign[site]] -= 1
            hist[best] += 1
            assign[site] = best
    return assign, omega, energy, hist


def naive_votes(site, views, assign, omega, exemplars, window, grid, pos_hist, theta, position_weight,
                position_boost=0.0):
    """Votes (texel colour, view, local texel index, weight) for one voxel, in the kernel's order."""
    a = naive_anchor(window)
    votes = []
    for vi, view in enumerate(views):
        ra, ca = NAIVE_VIEW_AXES[view]
        w = exemplars[vi].shape[1]
        for orow in range(-a, window - a):
            for ocol in range(-a, window - a):
                u = list(site)
                u[ra] = (site[ra] - orow) % assign.shape[1 + ra]
                u[ca] = (site[ca] - ocol) % assign.shape[1 + ca]
                if u[ra] % grid or u[ca] % grid:
                    continue
                e = int(assign[vi][tuple(u)])
                if e < 0:
                    continue
                local = (e // w + orow) * w + (e % w + ocol)
                excess = pos_hist[vi][local] / theta[vi] - 1.0
                weight = float(omega[vi][tuple(u)])
                if excess > 0:
                    weight /= 1.0 + position_weight * excess
                else:
                    weight *= 1.0 + position_boost * (-excess)
                colour = exemplars[vi].reshape(-1, exemplars[vi].shape[2])[local].astype(np.float64)
                votes.append([colour, vi, local, weight])
    return votes


def naive_solve(volume, src, assign, omega, views, exemplars, *, window, grid, order, bounds,
                pos_hist, theta, position_weight, position_boost=0.0, medoid=0, balance=False,
                likelihood=0, h2c=1.0, outlier=0.0):
    """Literal discrete solver; returns (volume, src, pos_hist, changed). ``likelihood`` 1 or 2:
    the coherent NP-MRF decision (per-view Parzen estimate of each candidate's colour, product or
    minimum over views) instead of the medoid."""
    volume = volume.copy()
    src = src.copy()
    pos_hist = [h.astype(np.float64).copy() for h in pos_hist]
    n1, n2 = volume.shape[1], volume.shape[2]
    changed = 0
    for b in range(len(bounds) - 1):
        updates = []
        for flat in order[bounds[b]:bounds[b + 1]]:
            site = (flat // (n1 * n2), (flat // n2) % n1, flat % n2)
            votes = naive_votes(site, views, assign, omega, exemplars, window, grid, pos_hist, theta,
                                position_weight, position_boost)
            new = [int(src[vi][site]) for vi in range(len(views))]
            if not votes:
                updates.append((site, new, False))
                continue
            if balance:
                sums = {}
                for v in votes:
                    sums[v[1]] = sums.get(v[1], 0.0) + v[3]
                for v in votes:
                    v[3] /= sums[v[1]]
            if medoid:
                # candidates: texels of the `medoid` heaviest votes, distinct (texel, view), heaviest
                # first, ties to the earlier vote (stable sort); energy over all votes
                ranked, seen = [], set()
                for q in sorted(range(len(votes)), key=lambda q: -votes[q][3]):
                    key = (votes[q][1], votes[q][2])
                    if key not in seen:
                        seen.add(key)
                        ranked.append(q)
                ranked = ranked[:medoid]
                best, best_e = None, np.inf
                if likelihood:
                    totals = {}
                    for m in votes:
                        totals[m[1]] = totals.get(m[1], 0.0) + m[3]
                    best_score = -np.inf
                    for q in ranked:
                        lik = {}
                        for m in votes:
                            dd = 0.0
                            for ch in range(len(m[0])):
                                diff = np.float32(votes[q][0][ch]) - np.float32(m[0][ch])
                                dd += float(diff * diff)
                            lik[m[1]] = lik.get(m[1], 0.0) + m[3] * np.exp(-dd / h2c)
                        per_view = [(1.0 - outlier) * lik.get(v, 0.0) / totals[v] + outlier if totals.get(v, 0.0) > 0
                                    else outlier for v in range(len(views))]
                        score = sum(np.log(x) for x in per_view) if likelihood == 1 else min(per_view)
                        if score > best_score:
                            best, best_score = votes[q], score
                    ranked = []
                for q in ranked:
                    e_sum = sum(m[3] * float(np.sqrt(((votes[q][0] - m[0]) ** 2).sum())) for m in votes)
                    if e_sum < best_e:
                        best, best_e = votes[q], e_sum
            else:
                wsum = sum(v[3] for v in votes)
                mean = sum(v[3] * v[0] for v in votes) / wsum
                best = min(votes, key=lambda v: ((v[0] - mean) ** 2).sum())
            colour = best[0]
            flag = bool(np.any(volume[site] != colour.astype(np.float32)))
            for vi in range(len(views)):
                if vi == best[1]:
                    new[vi] = best[2]
                    continue
                own = [v for v in votes if v[1] == vi]
                if own:
                    new[vi] = min(own, key=lambda v: ((v[0] - colour) ** 2).sum())[2]
            volume[site] = colour
            updates.append((site, new, flag))
        for site, new, flag in updates:
            changed += flag
            for vi in range(len(views)):
                pos_hist[vi][src[vi][site]] -= 1
                pos_hist[vi][new[vi]] += 1
                src[vi][site] = new[vi]
    return volume, src, pos_hist, changed


def naive_upsample_sources(src, view, coarse_width, fine_shape):
    ra, ca = NAIVE_VIEW_AXES[view]
    out = np.zeros(tuple(2 * n for n in src.shape), dtype=np.int64)
    for x in np.ndindex(*out.shape):
        parent = tuple(c // 2 for c in x)
        s = int(src[parent])
        r = min(2 * (s // coarse_width) + x[ra] % 2, fine_shape[0] - 1)
        c = min(2 * (s % coarse_width) + x[ca] % 2, fine_shape[1] - 1)
        out[x] = r * fine_shape[1] + c
    return out
