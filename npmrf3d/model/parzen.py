"""Public Parzen-window LCPDF functions and the per-level view models (docs/model.md, section 2).

The compiled work lives in :mod:`npmrf3d._kernels.parzen`; this module builds its inputs
(patch matrices, bandwidths, normalisers) from validated exemplars.
"""

from __future__ import annotations

import numpy as np

from .._kernels._jit import single_threaded_blas
from .._kernels.gemm import make_gemm_operands, sites_log_lcpdfs
from .._kernels.parzen import LcpdfOptions, label_kernel_table, label_log_norm_const
from .._kernels.relax import ViewModels
from ..config import DecisionRule
from .exemplar import decimation_phases, extract_patches
from .neighbourhood import union_offsets, view_offsets

__all__ = ["build_view_models", "h_opt", "log_lcpdf", "log_lcpdf_sites"]

#: Floor of the adaptive bandwidth, as a factor of h_opt (keeps 1/(2h^2) finite on exact matches).
ADAPTIVE_FLOOR = 0.05
#: Patches whose log weight is more than this below the best contribute < e^-40: skipped.
PRUNE = 40.0
#: Largest memory for the label kernel tables (beyond it every label term is computed in logs).
KERNEL_TABLE_BYTES = 512 * 2**20


def h_opt(sigma: float, n: int, d: int) -> float:
    """Optimal Parzen bandwidth ``h_opt = sigma * (4 / (n (d + 2)))**(1 / (d + 4))``.

    Parameters
    ----------
    sigma : float
        Square root of the exemplar's marginal variance (pooled over channels).
    n : int
        Number of exemplar patches.
    d : int
        Dimension of a patch vector, ``C * w**2``.

    Examples
    --------
    >>> round(h_opt(1.0, 3364, 49), 4)
    0.8177
    """
    return float(sigma) * (4.0 / (n * (d + 2.0))) ** (1.0 / (d + 4.0))


def build_view_models(
    label_images: dict[str, np.ndarray], labels: np.ndarray, *, window: int, level: int,
    rule: DecisionRule, toroidal: bool = False,
) -> tuple[ViewModels, dict]:
    """Patch matrices, bandwidths and normalisers for one pyramid level.

    Parameters
    ----------
    label_images : dict view -> (H, W) int32 ndarray
        The label image of each constrained view's exemplar (full resolution).
    labels : (K, C) float32 ndarray
    window : int
    level : int
        Pyramid level; the exemplar is decimated by ``2**level`` using all phases.
    rule : DecisionRule
        Supplies the bandwidth factors.
    toroidal : bool
        Whether exemplar patches wrap around.

    Returns
    -------
    models : ViewModels
    info : dict
        Per view: ``n`` patches, ``d``, ``sigma``, ``h_opt``, ``h``, ``h_centre``.
    """
    views = tuple(label_images)
    nc = labels.shape[1]
    d = nc * window * window
    per_view, info = [], {}
    for v in views:
        image = label_images[v]
        phases = decimation_phases(image, level)
        parts = [extract_patches(ph, labels, window, toroidal=toroidal) for ph in phases
                 if toroidal or min(ph.shape) >= window]
        patches = np.concatenate([p for p, _ in parts])
        centres = np.concatenate([c for _, c in parts])
        values = labels[image].reshape(-1, nc).astype(np.float64)
        sigma = float(np.sqrt(values.var(axis=0).mean()))
        if sigma == 0.0:  # constant exemplar: every bandwidth gives the same answer
            sigma = 1.0
        hopt = h_opt(sigma, len(centres), d)
        per_view.append((patches, centres))
        info[v] = {"n": len(centres), "d": d, "sigma": sigma, "h_opt": hopt,
                   "h": rule.bandwidth * hopt, "h_centre": rule.centre_bandwidth * hopt}
    n_max = max(len(c) for _, c in per_view)
    m_c = per_view[0][0].shape[1]
    n_labels = labels.shape[0]
    patches_t = np.zeros((len(views), m_c, n_max), dtype=np.float32)
    centre_labels = np.zeros((len(views), n_max), dtype=np.int32)
    label_starts = np.zeros((len(views), n_labels + 1), dtype=np.int64)
    for a, (p, c) in enumerate(per_view):
        # grouped by centre label, so that the label stage sums each label's weights over one
        # contiguous range (npmrf3d._kernels.parzen.label_weights); raster order within a label
        order = np.argsort(c, kind="stable")
        patches_t[a, :, : len(c)] = p[order].T
        centre_labels[a, : len(c)] = c[order]
        label_starts[a] = np.searchsorted(c[order], np.arange(n_labels + 1))
    inv_h2 = np.array([1.0 / (2.0 * info[v]["h"] ** 2) for v in views])
    inv_hc2 = np.array([1.0 / (2.0 * info[v]["h_centre"] ** 2) for v in views])
    log_norm = np.stack([label_log_norm_const(labels, x) for x in inv_hc2])
    if len(views) * n_labels**2 * 8 <= KERNEL_TABLE_BYTES:
        tables = np.stack([label_kernel_table(labels, x) for x in inv_hc2])
    else:
        tables = np.zeros((len(views), 0, 0))
    models = ViewModels(
        offsets=np.stack([view_offsets(v, window) for v in views]),
        patches_t=patches_t,
        centre_labels=centre_labels,
        label_starts=label_starts,
        n_patches=np.array([len(c) for _, c in per_view], dtype=np.int64),
        inv_two_h2=inv_h2,
        inv_two_hc2=inv_hc2,
        log_norm_const=log_norm,
        kernel_tables=tables,
        labels=np.ascontiguousarray(labels, dtype=np.float32),
        union_offsets=union_offsets(views, window),
    )
    return models, info


def adaptive_floor(info: dict) -> float:
    """``min_two_h2`` of the adaptive bandwidth: ``2 (ADAPTIVE_FLOOR * h_opt)^2`` (smallest view)."""
    return float(min(2.0 * (ADAPTIVE_FLOOR * x["h_opt"]) ** 2 for x in info.values()))


def log_lcpdf(
    volume: np.ndarray, temps: np.ndarray, site: tuple[int, int, int], models: ViewModels, *,
    adaptive: float = 0.0, min_two_h2: float = 0.0, prune: float = PRUNE, outlier: float = 0.0,
) -> np.ndarray:
    """Per-view log-LCPDF ``log L_v(lam_k)`` of one site over all labels.

    Parameters
    ----------
    volume : (N1, N2, N3, C) float32 ndarray
    temps : (N1, N2, N3) float32 ndarray, voxel temperatures in [0, 1]
    site : (i, j, k)
    models : ViewModels from :func:`build_view_models`
    adaptive, min_two_h2 : float
        Per-site bandwidth ``2h^2 = max(adaptive * D_min, min_two_h2)`` when ``adaptive > 0``.
    prune : float
        Skip patches whose log weight is more than this below the best (``np.inf`` keeps all).
    outlier : float in [0, 1)
        If > 0, return the robust ``log((1 - outlier) L + outlier / K)`` instead (the default
        sampler's per-view density, :class:`npmrf3d.config.DecisionRule`).

    Returns
    -------
    (V, K) float64 ndarray; ``exp`` of each row sums to 1 (also with ``outlier``).
    """
    out = np.empty((1, models.offsets.shape[0], models.labels.shape[0]), dtype=np.float64)
    sites_log_lcpdfs(np.ascontiguousarray(volume, dtype=np.float32),
                     np.ascontiguousarray(temps, dtype=np.float32),
                     np.array([site], dtype=np.int64).reshape(1, 3), models, None,
                     LcpdfOptions(float(adaptive), float(min_two_h2), float(prune), float(outlier)),
                     out)
    return out[0]


def log_lcpdf_sites(
    volume: np.ndarray, temps: np.ndarray, sites: np.ndarray, models: ViewModels, *,
    adaptive: float = 0.0, min_two_h2: float = 0.0, prune: float = PRUNE, outlier: float = 0.0,
) -> np.ndarray:
    """:func:`log_lcpdf` of many sites at once, the way the relaxations compute it.

    The neighbour distances of each block of sites come from one float32 matrix product per
    view (:mod:`npmrf3d._kernels.gemm`); they agree with the direct sum of :func:`log_lcpdf`
    to float32 rounding of ``||x - mu||^2 + ||y - mu||^2 - 2 (x - mu).(y - mu)``.

    Parameters
    ----------
    volume, temps, models, adaptive, min_two_h2, prune, outlier :
        As for :func:`log_lcpdf`.
    sites : (S, 3) int ndarray
        Voxel coordinates.

    Returns
    -------
    (S, V, K) float64 ndarray

    Examples
    --------
    >>> from npmrf3d.config import DecisionRule
    >>> from npmrf3d.model.exemplar import make_labels
    >>> ex = np.tile(np.array([0.0, 1.0], dtype=np.float32), (8, 4))[..., None]
    >>> labels, images = make_labels([ex], rng=0)
    >>> models, _ = build_view_models({"front": images[0]}, labels, window=3, level=0,
    ...                               rule=DecisionRule())
    >>> vol = labels[np.zeros((4, 4, 4), dtype=int)]
    >>> out = log_lcpdf_sites(vol, np.zeros((4, 4, 4)), np.array([[0, 0, 0], [1, 2, 3]]), models)
    >>> out.shape, bool(np.allclose(np.exp(out).sum(axis=2), 1.0))
    ((2, 1, 2), True)
    """
    sites = np.ascontiguousarray(sites, dtype=np.int64).reshape(-1, 3)
    out = np.empty((len(sites), models.offsets.shape[0], models.labels.shape[0]), dtype=np.float64)
    ops = make_gemm_operands(models.patches_t, models.n_patches, models.labels.shape[1])
    with single_threaded_blas():
        sites_log_lcpdfs(np.ascontiguousarray(volume, dtype=np.float32),
                         np.ascontiguousarray(temps, dtype=np.float32), sites, models, ops,
                         LcpdfOptions(float(adaptive), float(min_two_h2), float(prune),
                                      float(outlier)), out)
    return out
