"""Slow, obviously correct twins of the compiled kernels, written straight from SPEC.md.

Everything here is plain numpy in float64 with explicit loops or broadcasting: no pruning, no
label-histogram identity, no kernel tables, no scratch buffers. The tests compare the library
against these functions (STYLE.md practice 2).

Axis mapping of the views (npmrf3d.neighborhood's documented table, restated independently):
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
    """SPEC.md section 2: h_opt = sigma * (4 / (n (d + 2)))^(1 / (d + 4))."""
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
    """log L(lam) over all labels for one view (SPEC.md section 2, every patch, float64).

    dist2(lam, p) = ||lam - y_p||^2 / (2 h_c^2) + D_p / (2 h^2);  f(lam) = sum_p exp(-dist2);
    L = f / sum_lam f. ``h_centre=None`` means h_c = h (SPEC's single bandwidth).
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


# --------------------------------------------------------------------------- NP_K (SPEC.md section 6)


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
