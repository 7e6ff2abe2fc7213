"""Slow, obviously correct twins of the compiled kernels, written straight from the equations
(docs/model.md and the papers).

Everything here is plain numpy in float64 with explicit loops or broadcasting: no pruning, no
label-histogram identity, no kernel tables, no scratch buffers. The tests compare the library
against these functions.

Axis mapping of the views (npmrf3d.model.neighbourhood's documented table, restated independently):
front = plane (i, j) -> exemplar (row, col); right = plane (j, k); top = plane (i, k).
"""

from __future__ import annotations

import itertools

import numpy as np
from scipy.special import logsumexp

#: view -> (volume axis that maps to the exemplar row, volume axis that maps to the column)
NAIVE_VIEW_AXES = {"front": (0, 1), "right": (1, 2), "top": (0, 2)}


# --------------------------------------------------------------------------- geometry


def naive_window_offsets(window: int) -> list[tuple[int, int]]:
    """(d_row, d_col) of the w x w square without its centre, row-major."""
    r = window // 2
    out = []
    for a in range(-r, r + 1):
        for b in range(-r, r + 1):
            if a == 0 and b == 0:
                continue
            out.append((a, b))
    return out


def naive_view_offsets(view: str, window: int) -> np.ndarray:
    """3D offsets of one view's window, same order as :func:`naive_window_offsets`."""
    row_axis, col_axis = NAIVE_VIEW_AXES[view]
    out = []
    for a, b in naive_window_offsets(window):
        o = [0, 0, 0]
        o[row_axis] = a
        o[col_axis] = b
        out.append(o)
    return np.array(out, dtype=np.int64)


def naive_union_offsets(views, window: int) -> set[tuple[int, int, int]]:
    """The 3D neighbourhood N_s as a set of offsets (union of the views' windows)."""
    out = set()
    for v in views:
        for o in naive_view_offsets(v, window):
            out.add(tuple(int(x) for x in o))
    return out


def torus_interact(a, b, shape, views, window: int) -> bool:
    """Whether site ``b`` lies in the 3D neighbourhood of site ``a`` on the torus (or vice versa).

    ``b`` is in ``a``'s window of a view iff the coordinate along the view's normal axis agrees
    (mod n) and both in-plane coordinates are within ``r`` on the ring, and ``a != b``.
    The relation is symmetric, so one test covers both directions.
    """
    if tuple(a) == tuple(b):
        return False
    r = window // 2
    for v in views:
        plane = NAIVE_VIEW_AXES[v]
        normal = 3 - plane[0] - plane[1]
        if (a[normal] - b[normal]) % shape[normal] != 0:
            continue
        close = True
        for ax in plane:
            d = (a[ax] - b[ax]) % shape[ax]
            if min(d, shape[ax] - d) > r:
                close = False
        if close:
            return True
    return False


def naive_colouring_ok(classes, shape, views=("front", "right", "top"), window: int = 3) -> bool:
    """Brute force: classes partition all sites exactly once and no two sites of a class interact."""
    seen = np.zeros(shape, dtype=np.int64)
    for cls in classes:
        for s in cls:
            seen[tuple(s)] += 1
    if not (seen == 1).all():
        return False
    for cls in classes:
        sites = [tuple(int(x) for x in s) for s in cls]
        for a, b in itertools.combinations(sites, 2):
            if torus_interact(a, b, shape, views, window):
                return False
    return True


# --------------------------------------------------------------------------- exemplar


def naive_extract_patches(label_image, labels, window: int, toroidal: bool = False):
    """Neighbour values (n, w*w - 1, C) float64 and centre labels (n,) with explicit loops.

    Centres in row-major order; non-toroidal: only centres whose whole window lies inside.
    """
    labels = np.asarray(labels, dtype=np.float64)
    h, w = label_image.shape
    r = window // 2
    offsets = naive_window_offsets(window)
    rows = range(h) if toroidal else range(r, h - r)
    cols = range(w) if toroidal else range(r, w - r)
    patches, centres = [], []
    for i in rows:
        for j in cols:
            vec = []
            for a, b in offsets:
                vec.append(labels[label_image[(i + a) % h, (j + b) % w]])
            patches.append(vec)
            centres.append(int(label_image[i, j]))
    nc = labels.shape[1]
    return (np.array(patches, dtype=np.float64).reshape(len(centres), len(offsets), nc),
            np.array(centres, dtype=np.int64))


def naive_sigma(values) -> float:
    """sqrt of the marginal variance pooled over channels (mean of the per-channel variances)."""
    values = np.asarray(values, dtype=np.float64).reshape(-1, np.shape(values)[-1])
    variances = []
    for c in range(values.shape[1]):
        col = values[:, c]
        mean = sum(col) / len(col)
        variances.append(sum((x - mean) ** 2 for x in col) / len(col))
    return float(np.sqrt(sum(variances) / len(variances)))


def naive_h_opt(sigma: float, n: int, d: int) -> float:
    """docs/model.md, section 2: h_opt = sigma * (4 / (n (d + 2)))^(1 / (d + 4))."""
    return sigma * (4.0 / (n * (d + 2.0))) ** (1.0 / (d + 4.0))


# --------------------------------------------------------------------------- Parzen LCPDF


def gather(volume, temps, site, view_offsets3d):
    """Neighbour values (M, C) and temperatures (M,) of ``site``, toroidal."""
    n = volume.shape[:3]
    vals, ts = [], []
    for o in view_offsets3d:
        q = tuple((int(site[a]) + int(o[a])) % n[a] for a in range(3))
        vals.append(np.asarray(volume[q], dtype=np.float64))
        ts.append(float(temps[q]))
    return np.array(vals), np.array(ts)


def naive_neighbour_distances(volume, temps, site, view_offsets3d, patches):
    """D_p = sum_r ||(x_r - y_{p,r}) (1 - t_r)||^2 for every patch p (float64)."""
    x, t = gather(volume, temps, site, view_offsets3d)
    diff = (x[None, :, :] - np.asarray(patches, dtype=np.float64)) * (1.0 - t)[None, :, None]
    return (diff**2).sum(axis=(1, 2))


def naive_log_lcpdf(volume, temps, site, view_offsets3d, patches, centre_labels, labels, h,
                    h_centre=None, neighbour_two_h2=None):
    """log L(lam) over all labels for one view (docs/model.md, section 2, every patch, float64).

    dist2(lam, p) = ||lam - y_p||^2 / (2 h_c^2) + D_p / (2 h^2);  f(lam) = sum_p exp(-dist2);
    L = f / sum_lam f. ``h_centre=None`` means h_c = h (the paper's single bandwidth).
    ``neighbour_two_h2`` overrides 2 h^2 of the neighbour term (adaptive bandwidth).
    """
    labels = np.asarray(labels, dtype=np.float64)
    patches = np.asarray(patches, dtype=np.float64)
    h_centre = h if h_centre is None else h_centre
    two_h2 = 2.0 * h * h if neighbour_two_h2 is None else neighbour_two_h2
    d_nb = naive_neighbour_distances(volume, temps, site, view_offsets3d, patches)
    y_centre = labels[np.asarray(centre_labels)]  # (n, C)
    # (K, n): centre term per label and patch
    d_c = ((labels[:, None, :] - y_centre[None, :, :]) ** 2).sum(axis=2)
    dist2 = d_c / (2.0 * h_centre**2) + d_nb[None, :] / two_h2
    log_f = logsumexp(-dist2, axis=1)
    return log_f - logsumexp(log_f)


def naive_label_log_norm_const(labels, inv_two_hc2) -> np.ndarray:
    labels = np.asarray(labels, dtype=np.float64)
    k = len(labels)
    out = np.empty(k)
    for a in range(k):
        s = 0.0
        for b in range(k):
            s += np.exp(-np.sum((labels[a] - labels[b]) ** 2) * inv_two_hc2)
        out[a] = np.log(s)
    return out


def naive_label_kernel_table(labels, inv_two_hc2) -> np.ndarray:
    labels = np.asarray(labels, dtype=np.float64)
    k = len(labels)
    out = np.empty((k, k))
    for a in range(k):
        for b in range(k):
            out[a, b] = np.exp(-np.sum((labels[a] - labels[b]) ** 2) * inv_two_hc2)
    return out


# --------------------------------------------------------------------------- heuristics


def naive_ml_h1a(log_l, labels):
    """Per view argmax (first on ties); keep the view argmax with the lowest L (first view on ties)."""
    best = [int(np.argmax(row)) for row in log_l]
    tops = [log_l[v, best[v]] for v in range(len(best))]
    v = int(np.argmin(tops))
    return best[v], np.asarray(labels[best[v]], dtype=np.float64)


def naive_ml_h1b(log_l, labels):
    """Per view argmax; the average of the chosen values (label -1: generally not a label)."""
    best = [int(np.argmax(row)) for row in log_l]
    value = np.mean([np.asarray(labels[b], dtype=np.float64) for b in best], axis=0)
    return -1, value


def naive_ml_h2a(log_l, labels, penalty=None):
    """argmax_lam min_v L_v(lam) (+ penalty)."""
    score = np.min(log_l, axis=0) + (0.0 if penalty is None else penalty)
    k = int(np.argmax(score))
    return k, np.asarray(labels[k], dtype=np.float64)


def naive_ml_h2b(log_l, labels, penalty=None):
    """argmax_lam sum_v log L_v(lam) (+ penalty)."""
    score = np.sum(log_l, axis=0) + (0.0 if penalty is None else penalty)
    k = int(np.argmax(score))
    return k, np.asarray(labels[k], dtype=np.float64)


NAIVE_HEURISTICS = {"ML_H1a": naive_ml_h1a, "ML_H1b": naive_ml_h1b,
                    "ML_H2a": naive_ml_h2a, "ML_H2b": naive_ml_h2b}


def naive_sample_probabilities(score, tau: float) -> np.ndarray:
    """exp(score / tau) / Z."""
    z = np.asarray(score, dtype=np.float64) / tau
    return np.exp(z - logsumexp(z))


# --------------------------------------------------------------------------- NP_K (Kopf et al. 2007)


def naive_kopf_patches(exemplar: np.ndarray, window: int) -> np.ndarray:
    """Every window fully inside the exemplar, row-major over top-left corners, (row, col, c)."""
    h, w, _ = exemplar.shape
    out = []
    for pr in range(h - window + 1):
        for pc in range(w - window + 1):
            out.append(exemplar[pr:pr + window, pc:pc + window].reshape(-1))
    return np.array(out, dtype=np.float64)


def naive_kopf_neighbourhood(volume: np.ndarray, view: str, site, window: int) -> np.ndarray:
    """The window of ``view`` anchored (top-left) at ``site``, toroidal, flattened (row, col, c)."""
    ra, ca = NAIVE_VIEW_AXES[view]
    n = volume.shape
    out = []
    for a in range(window):
        for b in range(window):
            s = list(site)
            s[ra] = (s[ra] + a) % n[ra]
            s[ca] = (s[ca] + b) % n[ca]
            out.extend(volume[s[0], s[1], s[2]])
    return np.array(out, dtype=np.float64)


def naive_bin(x: float, lo: float, scale: float, bins: int) -> int:
    return min(max(int((float(x) - lo) * scale), 0), bins - 1)


def naive_kopf_update(volume, assign, omega, views, exemplars, window, order, *, hist_weight=0.0,
                 lo=None, scale=None, bins=16, target_hist=None, constraint=None, tau=None):
    """Equation (4) of the paper evaluated literally, voxel by voxel in ``order``.

    For voxel v: every view i and every site u of that view whose window contains v (found by
    scanning all sites and all window offsets) contributes the exemplar texel of its patch at
    v's position, with weight omega_u / (1 + w * sum_c max(0, H_s,c(b) - H_e,c(b)))
    / (1 + tau_v ||e - t_v||); the histograms H_s are recounted from the volume every time.
    ``assign[i]`` holds patch indices (row-major over top-left corners).
    """
    vol = volume.astype(np.float64).copy()
    n1, n2, n3, channels = vol.shape
    out32 = volume.copy()
    for flat in order:
        v = np.unravel_index(flat, (n1, n2, n3))
        num = np.zeros(channels)
        den = 0.0
        for vi, view in enumerate(views):
            ra, ca = NAIVE_VIEW_AXES[view]
            ex = exemplars[vi]
            pw = ex.shape[1] - window + 1
            for u in zip(*np.nonzero(assign[vi] >= 0)):
                for a in range(window):
                    for b in range(window):
                        pos = list(u)
                        pos[ra] = (pos[ra] + a) % vol.shape[ra]
                        pos[ca] = (pos[ca] + b) % vol.shape[ca]
                        if tuple(pos) != tuple(v):
                            continue
                        p = int(assign[vi][u])
                        e = ex[p // pw + a, p % pw + b].astype(np.float64)
                        w = float(omega[vi][u])
                        if hist_weight > 0:
                            excess = 0.0
                            for c in range(channels):
                                b_c = naive_bin(e[c], lo[c], scale[c], bins)
                                count = sum(naive_bin(x, lo[c], scale[c], bins) == b_c
                                            for x in out32[..., c].ravel())
                                excess += max(0.0, count - (n1 * n2 * n3) * target_hist[c, b_c])
                            w /= 1.0 + hist_weight * excess
                        if constraint is not None:
                            w /= 1.0 + tau[v] * np.linalg.norm(e - constraint[v])
                        num += w * e
                        den += w
        out32[v] = (num / den).astype(np.float32)
    return out32


# --------------------------------------------------------------------------- k-coherence (Chen & Wang 2010)
# Literal twins of the k-coherence kernels (:mod:`npmrf3d._kernels.kcoherence` and
# :mod:`npmrf3d._kernels.kcoherence_solver`), written from the paper and the docstrings of
# :mod:`npmrf3d.model.kcoherence`, in float64 loops without scratch buffers.
# Geometry: a window of side ``w`` at plane position ``u`` covers ``u - a .. u - a + w - 1``,
# ``a = (w-1)//2``; the volume wraps around, the exemplar does not; sources and centres are flat
# ``row * W + col``.


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
                      r, floor, assign_v, n_random=0, salt=0, trust=None, box=None):
    """Literal search phase of one view; returns (assign, omega, energy per slice, index_hist).
    ``trust`` (N0, N1, N2): the full-dimensional distances with every pixel's term weighted by
    its trust, instead of the PCA ones (Urs et al. 2014). ``box`` ((lo0, lo1, lo2), (hi0, hi1,
    hi2)): only the sites with ``lo <= index < hi`` along every axis are searched."""
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
                    if box is not None and not all(lo <= i < hi for i, lo, hi in zip(site, *box)):
                        continue
                    patch = naive_volume_patch(volume, view, site, window)
                    y = (patch - model.mean) @ model.basis.astype(np.float64)
                    best, best_cost, best_d2 = None, np.inf, 0.0
                    cands = naive_candidate_list(src_v, view, site, w, model.bounds, model.kcoh)
                    flat = (site[0] * volume.shape[1] + site[1]) * volume.shape[2] + site[2]
                    cands += naive_random_centres(salt, flat, n_random, model.bounds, w)
                    for e in cands:
                        d2 = float(((y - model.proj[e].astype(np.float64)) ** 2).sum())
                        if trust is not None:
                            weights = np.repeat(naive_volume_patch(trust[..., None], view, site, window),
                                                ex.shape[2])
                            ex_patch = naive_exemplar_patch(ex, e // w, e % w, window)
                            d2 = float((weights * (patch - ex_patch) ** 2).sum())
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


def naive_value_bin(x, lo, scale, bins):
    """Bin of one value: floor((x - lo) * scale), clamped to 0..bins-1."""
    return int(min(max(np.floor((float(x) - lo) * scale), 0), bins - 1))


def naive_votes(site, views, assign, omega, exemplars, window, grid, pos_hist, theta, position_weight,
                position_boost=0.0, values=None, trust=None):
    """Votes (texel colour, view, local texel index, weight) for one voxel, in the kernel's order.
    ``trust`` (N0, N1, N2): each weight times the mean trust of the neighbourhood's pixels other
    than the voxel; a neighbourhood without any trusted one does not vote.
    ``values``: None, or a dict with the value histogram (``hist``, ``target`` per channel and
    bin, ``weight``, ``lo``, ``scale``) that divides each weight by
    ``1 + weight * sum_c max(0, hist[c][b_c] - target[c][b_c])``."""
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
                share = 1.0
                if trust is not None:
                    window_sum = naive_volume_patch(trust[..., None], view, tuple(u), window).sum()
                    share = (window_sum - float(trust[site])) / (window * window - 1)
                    if share <= 0:
                        continue
                local = (e // w + orow) * w + (e % w + ocol)
                excess = pos_hist[vi][local] / theta[vi] - 1.0
                weight = float(omega[vi][tuple(u)])
                if excess > 0:
                    weight /= 1.0 + position_weight * excess
                else:
                    weight *= 1.0 + position_boost * (-excess)
                colour = exemplars[vi].reshape(-1, exemplars[vi].shape[2])[local].astype(np.float64)
                if values is not None and values["weight"] > 0:
                    over = 0.0
                    for ch in range(len(colour)):
                        b = naive_value_bin(colour[ch], values["lo"][ch], values["scale"][ch],
                                            len(values["hist"][ch]))
                        over += max(0.0, values["hist"][ch][b] - values["target"][ch][b])
                    weight /= 1.0 + values["weight"] * over
                votes.append([colour, vi, local, weight * share])
    return votes


def naive_view_estimates(colour, votes, totals, n_views, h2c, outlier):
    """Every view's Parzen estimate of ``colour`` from its votes, mixed with the outlier share
    (the outlier share alone for a view without votes); differences in float32."""
    lik = {}
    for m in votes:
        dd = 0.0
        for ch in range(len(m[0])):
            diff = np.float32(colour[ch]) - np.float32(m[0][ch])
            dd += float(diff * diff)
        lik[m[1]] = lik.get(m[1], 0.0) + m[3] * np.exp(-dd / h2c)
    return [(1.0 - outlier) * lik.get(v, 0.0) / totals[v] + outlier if totals.get(v, 0.0) > 0 else outlier
            for v in range(n_views)]


def naive_kernel_table(texels, h2c):
    """The Parzen kernel between every two distinct colours of ``texels`` (G, C) float32, as
    :func:`naive_view_estimates` computes it, and every texel's index among the distinct colours
    (sorted as ``numpy.unique`` sorts rows)."""
    colours, ids = np.unique(texels, axis=0, return_inverse=True)
    table = np.empty((len(colours), len(colours)))
    for a, ca in enumerate(colours):
        for b, cb in enumerate(colours):
            dd = 0.0
            for ch in range(len(ca)):
                diff = np.float32(ca[ch]) - np.float32(cb[ch])
                dd += float(diff * diff)
            table[a, b] = np.exp(-dd / h2c)
    return ids.reshape(-1), table


def naive_prior(colour, values):
    """The histogram prior of a colour: ``prior * sum_c log((target + e) / (max(hist, 0) + e))``
    at its bins (0 without ``values`` or with a zero strength)."""
    if values is None or values.get("prior", 0.0) <= 0:
        return 0.0
    eps = 1.0 / values["unit"]
    prior = 0.0
    for ch in range(len(colour)):
        b = naive_value_bin(colour[ch], values["lo"][ch], values["scale"][ch], len(values["hist"][ch]))
        prior += values["prior"] * np.log((values["target"][ch][b] + eps) / (max(values["hist"][ch][b], 0.0) + eps))
    return prior


def naive_score(per_view, prior, likelihood, has_prior):
    """The raw score of an objective rule: ML_H2b (1) the sum of logs plus the prior, ML_H2a (2)
    the minimum times ``exp(prior)``."""
    score = sum(np.log(x) for x in per_view) if likelihood == 1 else min(per_view)
    if has_prior:
        score = score + prior if likelihood == 1 else score * np.exp(prior)
    return score


def naive_smoothness(colour, previous, site, span, beta):
    """The smoothness prior of ``colour`` at ``site``: ``-beta`` times the sum over the six face
    neighbours (toroidal) of ``previous`` of the mean over channels of ``((colour - neighbour) /
    span)^2``."""
    total = 0.0
    for axis in range(3):
        for shift in (-1, 1):
            n = list(site)
            n[axis] = (n[axis] + shift) % previous.shape[axis]
            gap = (np.asarray(colour, dtype=np.float64) - previous[tuple(n)].astype(np.float64)) / span
            total += float(np.mean(gap ** 2))
    return -beta * total


def naive_solve(volume, src, assign, omega, views, exemplars, *, window, grid, order, bounds,
                pos_hist, theta, position_weight, position_boost=0.0, medoid=0, balance=False,
                likelihood=0, h2c=1.0, outlier=0.0, values=None, temperature=0.0, salt=0, sampler=0, trust=None,
                smoothness=0.0, span=None):
    """Literal discrete solver; returns (volume, src, pos_hist, changed). ``likelihood`` 1 or 2:
    the coherent NP-MRF decision (per-view Parzen estimate of each candidate's colour, product or
    minimum over views) instead of the medoid; with ``temperature > 0`` a heat-bath draw among the
    candidates, ``P(a) ~ exp(l_a / temperature)`` (``l`` the log-score), from the voxel's hash
    ``(naive_mix(salt * n + flat) + 0.5) / 2**31``, or with ``sampler`` 1 a Metropolis step: the
    proposal ``a = floor(u * n_candidates)`` from that hash ``u``, accepted if its log-score is at
    least the current colour's, else if ``(naive_mix(naive_mix(salt * n + flat) + 2**31) + 0.5) /
    2**31 < exp(gap / temperature)``; a rejected voxel is left as it is. ``likelihood`` 3
    (ML_H1a) or 4 (ML_H1b): every view with votes picks the candidate of highest estimate (times
    ``exp(prior)``; first on ties); ML_H1a copies the pick of lowest own estimate (first view on
    ties), ML_H1b takes the mean of the picks' colours and each view's source becomes its pick
    (its nearest own vote when the pick is another view's). ``values`` (see
    :func:`naive_votes`, plus ``unit``): the value histogram, which follows every changed voxel
    between batches (updated in place).
    ``trust``: see :func:`naive_votes`. ``smoothness > 0``: every candidate's prior also gets
    :func:`naive_smoothness` against the volume as it was before the pass (``span`` per channel).
    """
    previous = volume.astype(np.float64)
    volume = volume.copy()
    src = src.copy()
    pos_hist = [h.astype(np.float64).copy() for h in pos_hist]
    n1, n2 = volume.shape[1], volume.shape[2]
    changed = 0
    for b in range(len(bounds) - 1):
        updates = []
        binned = []
        for flat in order[bounds[b]:bounds[b + 1]]:
            site = (flat // (n1 * n2), (flat // n2) % n1, flat % n2)
            votes = naive_votes(site, views, assign, omega, exemplars, window, grid, pos_hist, theta,
                                position_weight, position_boost, values, trust)
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
                picks = None
                if likelihood:
                    totals = {}
                    for m in votes:
                        totals[m[1]] = totals.get(m[1], 0.0) + m[3]
                    has_prior = values is not None and values.get("prior", 0.0) > 0 or smoothness > 0
                    best_score = -np.inf
                    logs, tables = [], []
                    for q in ranked:
                        per_view = naive_view_estimates(votes[q][0], votes, totals, len(views), h2c, outlier)
                        prior = naive_prior(votes[q][0], values)
                        if smoothness > 0:
                            prior += naive_smoothness(votes[q][0], previous, site, span, smoothness)
                        if likelihood >= 3:
                            tables.append([x * np.exp(prior) for x in per_view])
                            continue
                        score = naive_score(per_view, prior, likelihood, has_prior)
                        logs.append(score if likelihood == 1 else np.log(score))
                        if score > best_score:
                            best, best_score = votes[q], score
                    n_vox = volume.shape[0] * n1 * n2
                    if likelihood >= 3:
                        picks = {}
                        for v in range(len(views)):
                            if totals.get(v, 0.0) > 0:
                                picks[v] = 0
                                for a in range(1, len(ranked)):
                                    if tables[a][v] > tables[picks[v]][v]:
                                        picks[v] = a
                        if not picks:
                            updates.append((site, new, False))
                            continue
                        lowest = min(picks, key=lambda v: (tables[picks[v]][v], v))
                        best = votes[ranked[picks[lowest]]]
                        picks = {v: votes[ranked[a]] for v, a in picks.items()}
                        if likelihood == 4:
                            acc = np.zeros(len(best[0]))
                            for v in picks:
                                acc += picks[v][0]
                            best = [(acc / len(picks)).astype(np.float32).astype(np.float64), -1, -1, 0.0]
                    elif temperature > 0 and sampler == 1:
                        cur = volume[site]
                        per_view = naive_view_estimates(cur, votes, totals, len(views), h2c, outlier)
                        cur_prior = naive_prior(cur, values)
                        if smoothness > 0:
                            cur_prior += naive_smoothness(cur, previous, site, span, smoothness)
                        cur_score = naive_score(per_view, cur_prior, likelihood, has_prior)
                        cur_log = cur_score if likelihood == 1 else np.log(cur_score)
                        h = naive_mix(salt * n_vox + int(flat))
                        a = min(int((h + 0.5) / 2147483648.0 * len(ranked)), len(ranked) - 1)
                        gap = logs[a] - cur_log
                        if not (gap >= 0 or (naive_mix(h + 2147483648) + 0.5) / 2147483648.0 < np.exp(gap / temperature)):
                            updates.append((site, new, False))
                            continue
                        best = votes[ranked[a]]
                    elif temperature > 0 and len(ranked) > 1 and max(logs) > -np.inf:
                        top = max(logs)
                        weights = [np.exp((x - top) / temperature) for x in logs]
                        u = (naive_mix(salt * n_vox + int(flat)) + 0.5) / 2147483648.0 * sum(weights)
                        cum, pick = 0.0, len(ranked) - 1
                        for a, wgt in enumerate(weights):
                            cum += wgt
                            if u < cum:
                                pick = a
                                break
                        best = votes[ranked[pick]]
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
            if flag and values is not None:
                old = volume[site].copy()
                binned.append([(naive_value_bin(old[ch], values["lo"][ch], values["scale"][ch],
                                                len(values["hist"][ch])),
                                naive_value_bin(colour[ch], values["lo"][ch], values["scale"][ch],
                                                len(values["hist"][ch]))) for ch in range(len(colour))])
            for vi in range(len(views)):
                target = best
                if likelihood == 4:  # ML_H1b: each proposing view's source is its own pick
                    if vi not in picks:
                        continue
                    target = picks[vi]
                if vi == target[1]:
                    new[vi] = target[2]
                    continue
                own = [v for v in votes if v[1] == vi]
                if own:
                    new[vi] = min(own, key=lambda v: ((v[0] - target[0]) ** 2).sum())[2]
            volume[site] = colour
            updates.append((site, new, flag))
        for pairs in binned:
            for ch, (old_b, new_b) in enumerate(pairs):
                values["hist"][ch][old_b] -= 1.0 / values["unit"]
                values["hist"][ch][new_b] += 1.0 / values["unit"]
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


# --------------------------------------------------------------------------- 3D exemplars (volume-lh)


def naive_project(ex: np.ndarray, h: int, radius: int, mean: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Appearance-space vectors: each voxel's (2r+1)^3 neighbourhood every h voxels (clamped),
    offset-major with channels inside, minus ``mean``, times ``basis``."""
    shape = ex.shape[:3]
    out = np.zeros(shape + (basis.shape[1],))
    offsets = list(itertools.product(range(-radius, radius + 1), repeat=3))
    for x in itertools.product(*[range(n) for n in shape]):
        vec = []
        for o in offsets:
            p = tuple(min(max(x[a] + h * o[a], 0), shape[a] - 1) for a in range(3))
            vec.extend(ex[p].tolist())
        out[x] = (np.array(vec) - mean) @ basis
    return out


def naive_similarity_sets(neighbours: np.ndarray, coords: np.ndarray, k: int, exclude: int) -> np.ndarray:
    """Greedy k-sets: first entry, then each neighbour farther than ``exclude`` (Chebyshev) from all
    chosen; short sets filled with the nearest neighbours after the first, in order."""
    out = np.empty((len(neighbours), k), dtype=np.int64)
    for q, row in enumerate(neighbours):
        chosen = [int(row[0])]
        for cand in row[1:]:
            if len(chosen) == k:
                break
            if all(np.abs(coords[cand] - coords[c]).max() > exclude for c in chosen):
                chosen.append(int(cand))
        t = 1
        while len(chosen) < k:
            chosen.append(int(row[min(t, len(row) - 1)]))
            t += 1
        out[q] = chosen
    return out


def naive_cell_usage(coords, shape, h, lo, hi):
    """Twin of ``cell_usage``: a dictionary of counts per exemplar cell ``u // h`` and the even
    count (output voxels over the cells that meet the valid box)."""
    counts = {}
    for u in coords.reshape(-1, 3):
        cell = tuple(int(x) // h for x in u)
        counts[cell] = counts.get(cell, 0) + 1
    cells = {tuple(int(x) // h for x in u) for u in itertools.product(*[range(lo[a], hi[a] + 1) for a in range(3)])}
    return counts, coords[..., 0].size / len(cells)


def naive_phase_footprint(classes, phases, h):
    """Twin of ``phase_footprint``: for every exemplar voxel, count the phases of the voxels of its
    box ``u + [1 - h/2, h/2]`` (indices clamped to the faces), one voxel at a time."""
    out = np.zeros((phases,) + classes.shape)
    span = range(1 - h // 2, h // 2 + 1) if h > 1 else range(0, 1)
    for idx in itertools.product(*[range(n) for n in classes.shape]):
        for off in itertools.product(span, span, span):
            v = tuple(min(max(idx[a] + off[a], 0), classes.shape[a] - 1) for a in range(3))
            out[(int(classes[v]),) + idx] += 1.0 / len(span) ** 3
    return out


def naive_membership_footprint(member, h):
    """Twin of ``phase_footprint`` of a soft membership ``(P, D, H, W)``: every exemplar voxel's
    mean membership over its box ``u + [1 - h/2, h/2]`` (indices clamped), one voxel at a time."""
    shape = member.shape[1:]
    out = np.zeros(member.shape)
    span = range(1 - h // 2, h // 2 + 1) if h > 1 else range(0, 1)
    for idx in itertools.product(*[range(n) for n in shape]):
        for off in itertools.product(span, span, span):
            v = tuple(min(max(idx[a] + off[a], 0), shape[a] - 1) for a in range(3))
            out[(slice(None),) + idx] += member[(slice(None),) + v] / len(span) ** 3
    return out


def naive_class_balance(coords, footprint, share, prices, weight):
    """Twin of ``phase_error`` and ``class_balance``: the volume's phase mix summed voxel by voxel,
    then every exemplar voxel's cost from its own phase mix."""
    held = [0.0] * len(share)
    for u in coords.reshape(-1, 3):
        for c in range(len(share)):
            held[c] += footprint[(c,) + tuple(u)]
    error = [held[c] / coords[..., 0].size / share[c] - 1.0 for c in range(len(share))]
    cost = np.zeros(footprint.shape[1:])
    for idx in itertools.product(*[range(n) for n in cost.shape]):
        cost[idx] = weight * sum(footprint[(c,) + idx] * (max(0.0, error[c]) + prices[c]) for c in range(len(share)))
    return np.array(error), cost


def naive_correct(coords, frames, feat, kset, h, lo, hi, offsets, parity, weight=0.0, bias=None):
    """One correction sub-pass, straight from the docstring of the kernel: (new coords, costs);
    ``bias`` (exemplar-shaped, or None) is added to each candidate's distance."""
    out = coords.copy()
    cost = np.zeros(coords.shape[:3])
    shape = feat.shape[:3]
    n = coords.shape[:3]
    counts, even = naive_cell_usage(coords, shape, h, lo, hi)

    def penalty(u, current):
        cell = tuple(int(x) // h for x in u)
        c = counts.get(cell, 0) - (cell == tuple(int(x) // h for x in current))
        return weight * max(0.0, c / even - 1.0) + (0.0 if bias is None else bias[tuple(u)])

    def clamp_box(u):
        return np.minimum(np.maximum(u, lo), hi)

    def exemplar_neighbourhood(u):
        return np.stack([feat[tuple(np.clip(u + h * d, 0, np.array(shape) - 1))] for d in offsets])

    for p in itertools.product(*[range(parity[a], n[a], 2) for a in range(3)]):
        r = frames[0, 0, 0] if frames.shape[0] == 1 else frames[p]
        warped = [tuple((np.array(p) + np.floor(r.astype(np.float64) @ d + 0.5).astype(int)) % n)
                  for d in offsets]
        sources = [coords[w] for w in warped]
        neigh = np.stack([feat[tuple(s)] for s in sources])
        candidates = [coords[p]]
        for d, s in zip(offsets, sources):
            for q in kset[np.ravel_multi_index(tuple(s), shape)]:
                candidates.append(clamp_box(np.array(np.unravel_index(q, shape)) - h * d))
        dists = [((exemplar_neighbourhood(np.asarray(u)) - neigh) ** 2).sum() + penalty(u, coords[p])
                 for u in candidates]
        best = int(np.argmin(dists))
        out[p] = candidates[best]
        cost[p] = dists[best]
    return out, cost


def naive_correct_parzen(coords, frames, values, kset, h, lo, hi, offsets, window_offsets, parity,
                         adaptive, centre_h2):
    """The NP-MRF sub-pass with one 3D view, from the kernel's docstring: (new coords, costs)."""
    out = coords.copy()
    cost = np.zeros(coords.shape[:3])
    shape = np.array(values.shape[:3])
    n = coords.shape[:3]
    for p in itertools.product(*[range(parity[a], n[a], 2) for a in range(3)]):
        r = (frames[0, 0, 0] if frames.shape[0] == 1 else frames[p]).astype(np.float64)

        def at(o):
            return tuple((np.array(p) + np.floor(r @ o + 0.5).astype(int)) % n)

        candidates = [coords[p].copy()]
        for d in offsets:
            for q in kset[np.ravel_multi_index(tuple(coords[at(d)]), tuple(shape))]:
                u = np.array(np.unravel_index(q, tuple(shape))) - h * d
                candidates.append(np.minimum(np.maximum(u, lo), hi))
        neigh = np.stack([values[tuple(coords[at(o)])] for o in window_offsets])
        dist = np.array([sum(((values[tuple(np.clip(u + h * o, 0, shape - 1))] - neigh[t]) ** 2).sum()
                             for t, o in enumerate(window_offsets)) for u in candidates])
        a = -dist / (adaptive * max(dist.min(), 1e-12))
        centres = np.stack([values[tuple(u)] for u in candidates])
        scores = [logsumexp(a - ((centres - centres[u]) ** 2).sum(axis=1) / (2 * centre_h2))
                  for u in range(len(candidates))]
        best = int(np.argmax(scores))
        out[p] = candidates[best]
        cost[p] = dist[best]
    return out, cost


# --------------------------------------------------------------------------- batched distances


def naive_gemm_operands(view_patches, n_channels: int):
    """Twin of ``make_gemm_operands``: the channel means ``mu`` over every view's patch entries,
    the centred patches ``y' = y - mu`` (n, M, C) and ``q[p, m] = ||y'_{p,m}||^2`` per view."""
    stacked = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, n_channels)
                              for p in view_patches])
    centre = stacked.mean(axis=0)
    centred = [np.asarray(p, dtype=np.float64) - centre for p in view_patches]
    return centre, centred, [(y**2).sum(axis=2) for y in centred]


def naive_gemm_rows(volume, temps, sites, view_offsets3d, centre):
    """Twin of ``gemm_rows``: per site the row ``[-2 t_m x'_{m,c} ..., t_m ...]`` and
    ``s0 = sum_m t_m ||x'_m||^2`` (float64)."""
    rows, s0 = [], []
    for site in sites:
        x, temp = gather(volume, temps, site, view_offsets3d)
        t = (1.0 - temp) ** 2
        xc = x - centre
        rows.append(np.concatenate([(-2.0 * t[:, None] * xc).ravel(), t]))
        s0.append(float((t * (xc**2).sum(axis=1)).sum()))
    return np.array(rows), np.array(s0)


def naive_block_distances(volume, temps, sites, view_offsets3d, patches):
    """``D_p`` of every site (S, n) by the direct sum (the definition, float64)."""
    return np.array([naive_neighbour_distances(volume, temps, s, view_offsets3d, patches)
                     for s in sites])


def naive_relative_weights(dist, d_min, inv, lowest):
    """``exp(-(D_p - D_min) inv)`` in float64 of the float32 log weight the kernel forms, 0
    below ``max(lowest, -87)`` (the kernel's float32 range)."""
    lw = (np.float32(d_min) - np.asarray(dist, dtype=np.float32)) * np.float32(inv)
    out = np.exp(lw.astype(np.float64))
    out[lw < max(lowest, -87.0)] = 0.0
    return out


def naive_label_weights(dist, label_starts, inv, prune):
    """``W_j = sum_{p in label j} exp(lw_p)`` (float64) over the patches kept by pruning, with
    ``lw_p`` the float32 log weight ``(D_min - D_p) inv`` the kernel forms (kept: ``lw_p >=
    max(-prune, -87)``)."""
    dist = np.asarray(dist, dtype=np.float32)
    w = naive_relative_weights(dist, float(dist.min()), inv, -prune)
    return np.array([w[label_starts[j]:label_starts[j + 1]].sum() for j in range(len(label_starts) - 1)])


# --------------------------------------------------------------------------- repetition


def naive_copy_repetition(coords: np.ndarray, min_shift: int, tolerance: int) -> float:
    """max over shifts t (max |t_i| >= min_shift, toroidal) of
    #{p : max_i |S(p + t)_i - S(p)_i| <= tolerance} / N, every voxel and shift looked at."""
    shape = coords.shape[:3]
    best = 0
    for t in itertools.product(*[range(m) for m in shape]):
        short = [ti if ti < (m + 1) // 2 else ti - m for ti, m in zip(t, shape)]
        if max(abs(x) for x in short) < min_shift:
            continue
        moved = np.roll(coords, shift=[-ti for ti in t], axis=(0, 1, 2))  # moved[p] = coords[p + t]
        count = int((np.abs(moved - coords).max(axis=-1) <= tolerance).sum())
        best = max(best, count)
    return best / int(np.prod(shape))


def naive_cool(temps, visited, inherited, xi):
    """ICM cooling (Urs et al. 2014) over the 6 face neighbours, every new value from the old
    temperatures: ``max(0, (xi + sum of the neighbours' t) / 6)`` for visited, not inherited voxels."""
    out = temps.astype(np.float64).copy()
    n = temps.shape
    for p in itertools.product(*(range(m) for m in n)):
        if not visited[p] or inherited[p]:
            continue
        total = 0.0
        for axis in range(3):
            for step in (-1, 1):
                q = list(p)
                q[axis] = (q[axis] + step) % n[axis]
                total += float(temps[tuple(q)])
        out[p] = max(0.0, (xi + total) / 6.0)
    return out


def naive_window_trust(trust, view, site, window):
    """Sum of ``trust`` over the window of ``view`` at ``site``."""
    return float(naive_volume_patch(trust[..., None], view, site, window).sum())


def naive_global_flat(p, shape, origin, extent):
    """The flat index of voxel ``p`` of a region (``origin``, ``extent``: the level's grid, 0 =
    the region is the grid) in that grid, toroidal: the kernels' random-number key."""
    if extent[0] == 0:
        return (p[0] * shape[1] + p[1]) * shape[2] + p[2]
    g = [(o + q) % e for o, q, e in zip(origin, p, extent)]
    return (g[0] * extent[1] + g[1]) * extent[2] + g[2]


def naive_voxel_batches(shape, origin, extent, salt, batches, lo=(0, 0, 0), hi=None):
    """Every voxel's batch of a block-local pass: a hash of its grid position and the salt; -1
    outside the box ``lo <= p < hi``."""
    hi = shape if hi is None else hi
    out = np.full(shape, -1, dtype=np.int16)
    for p in np.ndindex(*shape):
        if all(a <= q < b for a, q, b in zip(lo, p, hi)):
            out[p] = naive_mix(naive_mix(naive_global_flat(p, shape, origin, extent)) + salt) % batches
    return out


def naive_top_votes(vg, vv, vw, most):
    """The ``most`` heaviest distinct (texel, view) of the votes, heaviest first: each weighs its
    heaviest vote, ties to the earlier vote; returned as that vote's index."""
    best = {}
    for q, (g, v, w) in enumerate(zip(vg, vv, vw)):
        key = (int(g), int(v))
        if key not in best or w > vw[best[key]]:
            best[key] = q
    ranked = sorted(best.values(), key=lambda q: (-vw[q], q))
    return ranked[:most]


def naive_group_by_batch(ids, batches):
    """Indices of the voxels with a batch (``ids >= 0``) grouped by batch (a stable sort of their
    batch ids) and each batch's first position."""
    kept = np.flatnonzero(ids >= 0)
    order = kept[np.argsort(ids[kept], kind="stable")]
    bounds = np.concatenate([[0], np.cumsum(np.bincount(ids[kept], minlength=batches))])
    return order, bounds


def naive_central_texels(texels):
    """Per voxel, of the views' texels (V, n, C) the one nearest to their mean (first on ties)."""
    centre = texels.astype(np.float64).mean(axis=0)
    dist = ((texels - centre) ** 2).sum(axis=-1)
    pick = np.argmin(dist, axis=0)
    return np.take_along_axis(texels, pick[None, :, None], axis=0)[0]


def naive_sort_within_batches(order, bounds):
    """Every batch ``order[bounds[b]:bounds[b + 1]]`` sorted."""
    out = np.array(order)
    for b in range(len(bounds) - 1):
        out[bounds[b]:bounds[b + 1]] = np.sort(out[bounds[b]:bounds[b + 1]])
    return out
