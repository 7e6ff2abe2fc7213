"""NP_K: solid texture synthesis by texture optimisation with histogram matching.

The baseline the NP-MRF paper compares with (Kopf et al. 2007, "Solid texture synthesis from
2D exemplars"; SPEC.md section 6). The volume minimises

    E = sum_v sum_{i in views} ||s_{v,i} - e_{v,i}||^r,        r = 0.8,

over the ``window x window`` neighbourhoods ``s_{v,i}`` of the axis-orthogonal slices through
the voxels of a sparse grid, ``e_{v,i}`` being the closest exemplar neighbourhood. Each
iteration alternates

* **search**: every neighbourhood on the sparse grid (every ``grid``-th position along both
  plane axes, every slice) is projected on the exemplar's principal components that keep
  ``variance`` of the variance and matched with ``scipy.spatial.cKDTree.query(eps=eps)``
  (approximate nearest neighbour within a factor ``1 + eps`` of the exact distance);
* **optimisation** (IRLS): each voxel becomes the weighted average of the exemplar texels that
  the overlapping neighbourhoods assign to it (paper eq. 4), with weights
  ``omega = ||s - e||^(r - 2)`` divided by ``1 + histogram_weight * sum_c max(0, H_s,c(b) -
  H_e,c(b))`` (paper eq. 5; ``H`` are per-channel histograms with ``histogram_bins`` bins,
  in voxel counts, kept up to date while voxels change in a random order) and, for voxel
  constraints, by ``1 + tau_v ||e - t_v||`` (paper eq. 6). Optionally only the dominant
  mean-shift cluster of the texels is averaged, with a bandwidth that shrinks over the
  iterations of a level (less blur).

Levels run coarse to fine; a level's volume initialises the next finer one by trilinear
up-sampling (the paper) or by the project's ``8/8`` / ``1/8`` pyramid (:mod:`npmrf3d.pyramid`).

Choices where the paper is silent (also in ``docs/kopf.md``)
-------------------------------------------------------------
* Neighbourhood geometry: the views and axes of :mod:`npmrf3d.neighborhood` (front = plane
  ``(i, j)`` -> exemplar (row, column), right = ``(j, k)``, top = ``(i, k)``). A window is
  anchored at its top-left sparse-grid site ``u`` and covers ``u .. u + window - 1`` along both
  plane axes (toroidal volume), so even sizes such as the paper's 8x8 have no centre problem.
  Exemplar neighbourhoods are the windows that lie fully inside the exemplar.
* Coarse levels: the exemplar is box-averaged over ``2^l x 2^l`` blocks (the mean of its
  decimation phases); the volume of level ``l`` has ``size / 2^l`` voxels per side.
* Histograms: bins span each channel's range over all (full-resolution) exemplars; the target is
  the mean of the views' exemplar histograms at the current level, scaled to the volume's voxel
  count. ``H`` are bin *counts* (the paper's "value of bin b"), so ``histogram_weight = 1`` is
  the paper's formula; with fractions (``histogram_weight = 1 / N``) the re-weighting is too
  weak to counter the averaging's narrowing of the histogram (measured, ``docs/kopf.md``).
* IRLS weights use the exact (full-dimensional) distance of the chosen exemplar neighbourhood,
  floored at ``1e-3 * sigma * sqrt(d)`` (``sigma`` the exemplar standard deviation) so an exact
  match does not get an infinite weight.
* Mean-shift: Gaussian kernel; modes are sought from the heaviest contributors and from their
  weighted mean, the densest mode wins, and the texels within one bandwidth of it are averaged.
  Clusters are formed with the IRLS weights; the histogram and constraint re-weighting applies to
  the members (it must run in the sequential random-order pass).
* Determinism: voxel orders are drawn from ``rng`` before any parallel loop; KD-tree queries and
  the parallel gather are per-query/per-voxel, and the order-dependent pass is sequential, so the
  volume depends on the seed only, not on the thread count.
"""

from __future__ import annotations

import json
import math
import time
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.spatial import cKDTree

from .. import _validation as check
from .._kernels import _jit
from ..config import DEFAULT_SIZE, SynthesisMethod, SynthesisResult
from ..exemplar import resolve_exemplars
from ..neighborhood import VIEW_AXES, VIEWS
from ..pyramid import Levels, LevelState, run_pyramid
from ..pyramid import upsample as pyramid_upsample
from .._kernels import kopf as _k

__all__ = ["METHOD", "KopfConfig", "UPSAMPLING", "kopf_method", "kopf_synthesize", "make_kopf_config"]

#: Up-sampling between levels: the paper's trilinear interpolation, or the project's pyramid
#: (names of :data:`npmrf3d.pyramid.UPSAMPLERS`, the paper's first).
UPSAMPLING = ("trilinear", "8/8", "1/8")
#: Default mean-shift bandwidths (start, end) of each level, as multiples of the exemplar's
#: standard deviation (pooled over channels).
DEFAULT_MEAN_SHIFT = (1.0, 0.25)
#: Default strength of the histogram re-weighting (1 = the paper's formula with bin counts).
DEFAULT_HISTOGRAM_WEIGHT = 1.0
#: Default search + optimisation iterations of every level.
DEFAULT_ITERATIONS = 5
_MEAN_SHIFT_ITERATIONS = 8
_CHUNK_BYTES = 48 * 2**20  # neighbourhood vectors gathered per KD-tree batch
_SWEEP_CHUNK = 1 << 15  # voxels gathered per optimisation batch

ProgressCallback = Callable[[int, int, int, float], None]


@dataclass(frozen=True)
class KopfConfig:
    """A validated NP_K run (see :func:`kopf_synthesize` for the meaning of each field)."""

    size: tuple[int, int, int]
    window: int = 8
    levels: int = 3
    views: tuple[str, ...] = VIEWS
    iterations: tuple[int, ...] = (DEFAULT_ITERATIONS,) * 3
    r: float = 0.8
    eps: float = 2.0
    variance: float = 0.95
    grid: int = 2
    histogram_bins: int = 16
    histogram_weight: float = DEFAULT_HISTOGRAM_WEIGHT
    mean_shift: tuple[float, float] | None = DEFAULT_MEAN_SHIFT
    upsample: str = "trilinear"
    constrained: bool = False
    seed: int | None = None

    def to_dict(self) -> dict:
        """Plain JSON-able dictionary."""
        return asdict(self)


# --------------------------------------------------------------------------- validation


def make_kopf_config(
    *, size=DEFAULT_SIZE, window=KopfConfig.window, levels=KopfConfig.levels, views=KopfConfig.views,
    iterations=DEFAULT_ITERATIONS, r=KopfConfig.r, eps=KopfConfig.eps, variance=KopfConfig.variance,
    grid=KopfConfig.grid, histogram_bins=KopfConfig.histogram_bins,
    histogram_weight=KopfConfig.histogram_weight, mean_shift=KopfConfig.mean_shift,
    upsample=KopfConfig.upsample, constrained=False, seed=None,
) -> KopfConfig:
    """Validate plain keyword arguments into a frozen :class:`KopfConfig`."""
    levels = check.integer("levels", levels, low=1, high=8)
    window = check.integer("window", window, low=2, high=64)
    dims = check.size(size, levels=levels, window=1)
    f = 2 ** (levels - 1)
    grid = check.integer("grid", grid, low=1, high=window)
    for n in dims:
        if (n // f) % grid:
            check.fail(f"size {n} does not suit grid {grid} with {levels} levels: every level's size "
                       f"must be a multiple of grid, the coarsest is {n // f}; choose a multiple of "
                       f"{f * grid}")
        if n // f < window:
            check.fail(f"size {n} is too small for window {window} with {levels} levels: the "
                       f"coarsest level has {n // f} voxels per side, needs at least {window}; "
                       f"use a larger size, a smaller window or fewer levels")
    if isinstance(iterations, (int, np.integer)) and not isinstance(iterations, bool):
        iterations = (int(iterations),) * levels
    try:
        iterations = tuple(iterations)
    except TypeError:
        check.fail(f"iterations must be a positive integer or one per level; got {iterations!r}")
    if len(iterations) != levels:
        check.fail(f"iterations must be one integer or {levels} integers (one per level, coarsest "
                   f"first); got {len(iterations)}: {iterations!r}")
    iterations = tuple(check.integer("iterations", it, low=1) for it in iterations)
    r = check.real("r", r, low=0.0, high=2.0, low_open=True)
    eps = check.real("eps", eps, low=0.0)
    variance = check.real("variance", variance, low=0.0, high=1.0, low_open=True)
    histogram_bins = check.integer("histogram_bins", histogram_bins, low=2, high=4096)
    histogram_weight = check.real("histogram_weight", histogram_weight, low=0.0)
    if mean_shift is not None:
        if isinstance(mean_shift, (int, float, np.integer, np.floating)) and not isinstance(mean_shift, bool):
            mean_shift = (mean_shift, mean_shift)
        try:
            pair = tuple(mean_shift)
        except TypeError:
            check.fail(f"mean_shift must be None, a bandwidth or a pair (start, end); got {mean_shift!r}")
        if len(pair) != 2:
            check.fail(f"mean_shift must be None, a bandwidth or a pair (start, end); got {mean_shift!r}")
        mean_shift = tuple(check.real("mean_shift", h, low=0.0, low_open=True) for h in pair)
    upsample = check.choice("upsample", upsample, UPSAMPLING)
    views = check.views(views, VIEWS)
    if seed is not None:
        seed = check.integer("seed", seed, low=0)
    return KopfConfig(size=dims, window=window, levels=levels, views=views, iterations=iterations,
                      r=r, eps=eps, variance=variance, grid=grid, histogram_bins=histogram_bins,
                      histogram_weight=histogram_weight, mean_shift=mean_shift, upsample=upsample,
                      constrained=bool(constrained), seed=seed)


def _constraint_arrays(constraint, constraint_weight, size, channels):
    """Validated ``(N1, N2, N3, C)`` float32 targets and ``(N1, N2, N3)`` float32 weights."""
    if constraint is None:
        if constraint_weight is not None:
            check.fail("constraint_weight was given without a constraint volume")
        return None, None
    t = np.asarray(constraint)
    if t.dtype == object or not np.issubdtype(t.dtype, np.number) or np.issubdtype(t.dtype, np.complexfloating):
        check.fail(f"constraint must be a real-valued array; got dtype {t.dtype}")
    if t.ndim == 3 and channels == 1:
        t = t[..., None]
    want = (*size, channels)
    if t.shape != want:
        check.fail(f"constraint must have shape {want} (N1, N2, N3, C) like the volume; "
                   f"got {t.shape}")
    t = t.astype(np.float32)
    if not np.isfinite(t).all():
        check.fail(f"constraint contains {int((~np.isfinite(t)).sum())} NaN or Inf values; "
                   "give unconstrained voxels weight 0 instead")
    tau = 1.0 if constraint_weight is None else constraint_weight
    tau = np.asarray(tau, dtype=np.float64) if np.isscalar(tau) or np.ndim(tau) == 0 else np.asarray(tau)
    if tau.ndim == 0:
        tau = np.full(size, float(check.real("constraint_weight", float(tau), low=0.0)))
    if tau.shape != tuple(size):
        check.fail(f"constraint_weight must be a number or an array of shape {tuple(size)} "
                   f"(N1, N2, N3); got {tau.shape}")
    if tau.dtype == object or not np.issubdtype(tau.dtype, np.number):
        check.fail(f"constraint_weight must hold numbers; got dtype {tau.dtype}")
    tau = tau.astype(np.float32)
    if not np.isfinite(tau).all() or (tau < 0).any():
        check.fail("constraint_weight must be finite and >= 0 everywhere")
    return np.ascontiguousarray(t), np.ascontiguousarray(tau)


# --------------------------------------------------------------------------- building blocks


def downsample_exemplar(exemplar: np.ndarray, level: int) -> np.ndarray:
    """Box average over ``2^level x 2^level`` blocks (the mean of the decimation phases).

    Parameters
    ----------
    exemplar : (H, W, C) float32 ndarray
    level : int >= 0

    Returns
    -------
    (H // 2^level, W // 2^level, C) float32 ndarray

    Examples
    --------
    >>> downsample_exemplar(np.arange(16, dtype=np.float32).reshape(4, 4, 1), 1)[..., 0]
    array([[ 2.5,  4.5],
           [10.5, 12.5]], dtype=float32)
    """
    f = 2 ** level
    if f == 1:
        return np.ascontiguousarray(exemplar, dtype=np.float32)
    h, w, c = exemplar.shape[0] // f, exemplar.shape[1] // f, exemplar.shape[2]
    blocks = exemplar[: h * f, : w * f].astype(np.float64).reshape(h, f, w, f, c)
    return np.ascontiguousarray(blocks.mean(axis=(1, 3)), dtype=np.float32)


def exemplar_patches(exemplar: np.ndarray, window: int) -> np.ndarray:
    """All ``window x window`` neighbourhoods that lie fully inside the exemplar.

    Returns
    -------
    (n, window * window * C) float32 ndarray
        Row ``p = pr * (W - window + 1) + pc`` is ``exemplar[pr:pr + window, pc:pc + window]``
        flattened in (row, column, channel) order; ``n = (H - window + 1)(W - window + 1)``.
    """
    view = sliding_window_view(exemplar, (window, window), axis=(0, 1))  # (H', W', C, w, w)
    view = view.transpose(0, 1, 3, 4, 2)
    return np.ascontiguousarray(view, dtype=np.float32).reshape(-1, window * window * exemplar.shape[2])


def pca_basis(patches: np.ndarray, variance: float = 0.95) -> tuple[np.ndarray, np.ndarray, float]:
    """Principal components of the rows of ``patches`` that keep a fraction ``variance``.

    The SVD (``numpy.linalg.svd``) of the ``d x d`` scatter matrix of the centred rows gives
    the principal directions and variances; ``k`` is the smallest number of leading components
    whose variances sum to at least ``variance`` of the total.

    Returns
    -------
    mean : (d,) float64 ndarray
    basis : (d, k) float32 ndarray, orthonormal columns
    kept : float, the fraction of the variance kept (1.0 for constant data)

    Examples
    --------
    >>> x = np.random.default_rng(0).normal(size=(500, 3)) * [10.0, 1.0, 0.1]
    >>> pca_basis(x, 0.95)[1].shape
    (3, 1)
    """
    x = patches.astype(np.float64)
    mean = x.mean(axis=0)
    x -= mean
    _, s, vt = np.linalg.svd(x.T @ x)
    total = float(s.sum())
    if total <= 0.0:
        return mean, np.ascontiguousarray(vt[:1].T, dtype=np.float32), 1.0
    cumulative = np.cumsum(s) / total
    k = int(np.searchsorted(cumulative, variance * (1 - 1e-12))) + 1
    k = min(k, len(s))
    return mean, np.ascontiguousarray(vt[:k].T, dtype=np.float32), float(cumulative[k - 1])


class PatchIndex:
    """Approximate nearest-neighbour search among an exemplar's neighbourhoods.

    PCA keeping ``variance`` of the variance (:func:`pca_basis`), then a
    ``scipy.spatial.cKDTree`` over the projected neighbourhoods, queried with error bound ``eps``.

    Parameters
    ----------
    exemplar : (H, W, C) float32 ndarray
    window : int
    variance : float in (0, 1]
    """

    def __init__(self, exemplar: np.ndarray, window: int, variance: float = 0.95):
        self.exemplar = np.ascontiguousarray(exemplar, dtype=np.float32)
        self.window = window
        self.patches = exemplar_patches(self.exemplar, window)
        self.mean, self.basis, self.kept = pca_basis(self.patches, variance)
        self.projected = self.project(self.patches)
        self.tree = cKDTree(self.projected)
        self.pwidth = exemplar.shape[1] - window + 1

    @property
    def dims(self) -> int:
        """Number of principal components kept."""
        return int(self.basis.shape[1])

    def project(self, vectors: np.ndarray) -> np.ndarray:
        """``(vectors - mean) @ basis`` in float32."""
        return np.ascontiguousarray((vectors - self.mean.astype(np.float32)) @ self.basis, dtype=np.float32)

    def query(self, vectors: np.ndarray, eps: float = 2.0, workers: int = -1) -> tuple[np.ndarray, np.ndarray]:
        """Index of the (approximate) nearest exemplar neighbourhood of each row of ``vectors``
        and the exact full-dimensional distance to it.

        Returns
        -------
        index : (q,) int64 ndarray
        distance : (q,) float64 ndarray, ``||vectors[t] - patches[index[t]]||``
        """
        _, index = self.tree.query(self.project(vectors), k=1, eps=eps, workers=workers)
        index = np.asarray(index, dtype=np.int64)
        diff = vectors - self.patches[index]
        return index, np.sqrt(np.einsum("ij,ij->i", diff, diff, dtype=np.float64))


def volume_neighbourhoods(volume: np.ndarray, view: str, window: int, grid: int,
                          normal: slice = slice(None)) -> np.ndarray:
    """Neighbourhood vectors of one view at the sparse-grid sites of some slices.

    Parameters
    ----------
    volume : (N1, N2, N3, C) ndarray
    view : {"front", "right", "top"}
    window, grid : int
    normal : slice
        Which slices (positions along the view's normal axis).

    Returns
    -------
    (S * ceil(Nr / grid) * ceil(Nc / grid), window * window * C) ndarray
        Site ``(n, a * grid, b * grid)`` (normal, row-axis, column-axis positions) in C order;
        its window covers row-axis positions ``a * grid .. a * grid + window - 1`` (toroidal)
        and likewise for the column axis, flattened like :func:`exemplar_patches`.
    """
    ra, ca = VIEW_AXES[view]
    na = 3 - ra - ca
    planes = np.transpose(volume, (na, ra, ca, 3))[normal]
    padded = np.pad(planes, ((0, 0), (0, window - 1), (0, window - 1), (0, 0)), mode="wrap")
    win = sliding_window_view(padded, (window, window), axis=(1, 2))[:, ::grid, ::grid]
    win = win.transpose(0, 1, 2, 4, 5, 3)  # (S, Gr, Gc, w, w, C)
    return np.ascontiguousarray(win).reshape(-1, window * window * volume.shape[3])


def search_view(volume: np.ndarray, view: str, index: PatchIndex, *, grid: int, eps: float,
                r: float, floor: float, offset: int | None = None) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Search phase of one view: best exemplar neighbourhood and IRLS weight per sparse site.

    Parameters
    ----------
    offset : int, optional
        If given, ``assign`` holds ``offset + pr * W + pc`` instead of the patch index
        ``pr * (W - window + 1) + pc``: the row of the patch's top-left texel in a flat array of
        exemplar pixels that starts this exemplar at ``offset`` (what the compiled sweep reads).

    Returns
    -------
    assign : (N1, N2, N3) int32 ndarray, patch index (or row, see ``offset``) at the view's
        sparse sites, -1 elsewhere
    omega : (N1, N2, N3) float32 ndarray, ``max(||s - e||, floor)^(r - 2)`` at the sites
    energy : float, ``sum ||s - e||^r`` over the sites
    queries : int, number of sites searched
    """
    window = index.window
    ra, ca = VIEW_AXES[view]
    na = 3 - ra - ca
    shape = volume.shape[:3]
    assign = np.full(shape, -1, dtype=np.int32)
    omega = np.zeros(shape, dtype=np.float32)
    a_t = np.transpose(assign, (na, ra, ca))[:, ::grid, ::grid]
    o_t = np.transpose(omega, (na, ra, ca))[:, ::grid, ::grid]
    per_slice = a_t.shape[1] * a_t.shape[2] * window * window * volume.shape[3] * 4
    step = max(1, _CHUNK_BYTES // per_slice)
    energy = 0.0
    for start in range(0, shape[na], step):
        sl = slice(start, min(shape[na], start + step))
        vectors = volume_neighbourhoods(volume, view, window, grid, sl)
        idx, dist = index.query(vectors, eps=eps)
        energy += float(np.sum(dist ** r))
        if offset is not None:
            idx = offset + (idx // index.pwidth) * index.exemplar.shape[1] + idx % index.pwidth
        a_t[sl] = idx.reshape(a_t[sl].shape)
        o_t[sl] = (np.maximum(dist, floor) ** (r - 2.0)).reshape(o_t[sl].shape)
    return assign, omega, energy, int(a_t.size)


def channel_bins(values: np.ndarray, lo: np.ndarray, scale: np.ndarray, bins: int) -> np.ndarray:
    """Histogram bin of each channel value: ``clip(int((x - lo) * scale), 0, bins - 1)``
    (the same formula as the compiled sweep).

    Parameters
    ----------
    values : (..., C) ndarray
    lo, scale : (C,) float64 ndarrays

    Returns
    -------
    (..., C) int32 ndarray
    """
    b = np.trunc((values.astype(np.float64) - lo) * scale)
    return np.clip(b, 0, bins - 1).astype(np.int32)


def channel_histograms(values: np.ndarray, lo, scale, bins: int) -> np.ndarray:
    """Per-channel bin counts of ``values`` (..., C) as a (C, bins) int64 array."""
    b = channel_bins(values, lo, scale, bins).reshape(-1, values.shape[-1])
    return np.stack([np.bincount(b[:, c], minlength=bins) for c in range(b.shape[1])]).astype(np.int64)


# --------------------------------------------------------------------------- optimisation


class _Exemplars(types.SimpleNamespace):
    """The views' exemplars of one level packed for the kernels."""


def _pack_exemplars(indices: Sequence[PatchIndex], lo, scale, bins) -> _Exemplars:
    offsets, flat, seen = [], [], {}
    start = 0
    for idx in indices:
        if id(idx) not in seen:
            seen[id(idx)] = start
            flat.append(idx.exemplar.reshape(-1, idx.exemplar.shape[2]))
            start += flat[-1].shape[0]
        offsets.append(seen[id(idx)])
    ex_flat = np.ascontiguousarray(np.concatenate(flat), dtype=np.float32)
    return _Exemplars(
        flat=ex_flat,
        bins=np.ascontiguousarray(channel_bins(ex_flat, lo, scale, bins)),
        offsets=np.array(offsets, dtype=np.int64),
        pwidth=np.array([idx.pwidth for idx in indices], dtype=np.int64),
        ewidth=np.array([idx.exemplar.shape[1] for idx in indices], dtype=np.int64),
    )


def optimisation_phase(volume: np.ndarray, assign: np.ndarray, omega: np.ndarray,
                       view_axes: np.ndarray, packed: _Exemplars, *, window: int, grid: int,
                       order: np.ndarray, hist: np.ndarray, hist_target: np.ndarray,
                       histogram_weight: float, lo: np.ndarray, scale: np.ndarray, bins: int,
                       bandwidth: float = 0.0, constraint=None, tau=None) -> float:
    """Set every voxel (in ``order``) to the re-weighted average of its exemplar texels.

    ``volume`` and ``hist`` (per-channel bin counts of ``volume``) are updated in place;
    ``hist_target`` holds the exemplar histograms as fractions. A contributing texel ``e`` has its
    weight divided by ``1 + histogram_weight * sum_c max(0, hist[c, b] - N * hist_target[c, b])``
    (``b = b_c(e)``, ``N`` voxels: both histograms as counts over the volume). Returns the mean
    absolute change per value.
    """
    n_views = assign.shape[0]
    cap = n_views * (-(-window // grid)) ** 2
    rows = np.empty((min(_SWEEP_CHUNK, order.size), cap), dtype=np.int64)
    weights = np.empty(rows.shape, dtype=np.float64)
    counts = np.empty(rows.shape[0], dtype=np.int64)
    n_voxels = volume.shape[0] * volume.shape[1] * volume.shape[2]
    use_constraint = constraint is not None
    if not use_constraint:
        constraint = np.zeros((1, 1, 1, volume.shape[3]), dtype=np.float32)
        tau = np.zeros((1, 1, 1), dtype=np.float32)
    change = 0.0
    for start in range(0, order.size, _SWEEP_CHUNK):
        chunk = order[start:start + _SWEEP_CHUNK]
        m = chunk.size
        _k.gather_texels(chunk, assign, omega, view_axes, packed.ewidth, window, grid, rows[:m],
                         weights[:m], counts[:m])
        change += _k.optimise_sweep(volume, chunk, rows[:m], weights[:m], counts[:m], packed.flat,
                                    packed.bins, hist, hist_target, float(histogram_weight) * n_voxels, lo,
                                    scale, bins, constraint, tau, use_constraint, float(bandwidth),
                                    _MEAN_SHIFT_ITERATIONS)
    return change / max(1, order.size * volume.shape[3])


def _upsample(volume: np.ndarray, mode: str, pixels: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The finer level's volume by :data:`npmrf3d.pyramid.UPSAMPLERS` ``mode``; ``1/8`` draws the
    7 new children uniformly from the level's exemplar ``pixels``."""
    shape = volume.shape[:3]
    parent = LevelState(volume=volume, labels_volume=np.zeros(shape, dtype=np.int32),
                        temps=np.zeros(shape, dtype=np.float32), inherited=np.zeros(shape, dtype=bool))
    freq = None if pixels is None else np.full(len(pixels), 1.0 / len(pixels))
    return np.ascontiguousarray(pyramid_upsample(parent, mode, pixels, freq, rng).volume, dtype=np.float32)


def _coarsen_constraint(t, tau, level):
    if t is None or level == 0:
        return t, tau
    f = 2 ** level
    n1, n2, n3 = (n // f for n in tau.shape)
    tw = tau.astype(np.float64).reshape(n1, f, n2, f, n3, f)
    wsum = tw.sum(axis=(1, 3, 5))
    tt = (t.astype(np.float64) * tau[..., None]).reshape(n1, f, n2, f, n3, f, -1).sum(axis=(1, 3, 5))
    tt = np.where(wsum[..., None] > 0, tt / np.maximum(wsum[..., None], 1e-300), 0.0)
    return np.ascontiguousarray(tt, dtype=np.float32), np.ascontiguousarray(wsum / f**3, dtype=np.float32)


# --------------------------------------------------------------------------- public


def kopf_synthesize(
    exemplar=None, *, size=DEFAULT_SIZE, window: int = KopfConfig.window,
    levels: int = KopfConfig.levels, views=KopfConfig.views, exemplars: Mapping | None = None,
    iterations=DEFAULT_ITERATIONS, r: float = KopfConfig.r, eps: float = KopfConfig.eps,
    variance: float = KopfConfig.variance, grid: int = KopfConfig.grid,
    histogram_bins: int = KopfConfig.histogram_bins,
    histogram_weight: float = KopfConfig.histogram_weight, mean_shift=KopfConfig.mean_shift,
    upsample: str = KopfConfig.upsample, constraint=None, constraint_weight=None, rng=None,
    progress: ProgressCallback | None = None, checkpoint=None,
) -> SynthesisResult:
    """Synthesize a solid texture with NP_K (Kopf et al. 2007; SPEC.md section 6).

    Parameters
    ----------
    exemplar : path, (H, W) or (H, W, C) array, or None
        The 2D sample (None: the bundled default). Used for every view without an entry in
        ``exemplars``.
    size : int or (N1, N2, N3)
        Output size, divisible by ``2**(levels - 1)``; the coarsest level needs at least
        ``window`` voxels per side.
    window : int >= 2
        Side of the square 2D neighbourhoods (the paper: 8). Even sizes are fine (windows are
        anchored at their top-left site).
    levels : int
        Resolution levels, coarse to fine (the paper: 3). The window must fit the exemplar
        box-averaged ``2**(levels - 1)`` times.
    views : sequence of {"front", "right", "top"} (or a comma-separated string)
        Views whose neighbourhoods enter the energy (2 or 3 in the paper; 1 is allowed). Axis
        mapping as in :mod:`npmrf3d.neighborhood`.
    exemplars : dict view -> exemplar, optional
        A different exemplar for some views (the paper's section 6.2).
    iterations : int or sequence of int
        Search + optimisation iterations per level (one number for all levels, or one per
        level, coarsest first).
    r : float in (0, 2]
        Exponent of the robust energy (IRLS weights ``||s - e||^(r - 2)``; 2 = least squares).
    eps : float >= 0
        Error bound of the approximate nearest-neighbour search (``cKDTree.query(eps=...)``);
        0 = exact search in the PCA space.
    variance : float in (0, 1]
        Fraction of the exemplar neighbourhoods' variance kept by the PCA projection.
    grid : int >= 1
        Spacing ``m`` of the sparse grid of searched neighbourhoods (1 = every voxel).
    histogram_bins : int >= 2
        Bins of each channel's histogram.
    histogram_weight : float >= 0
        Strength of the histogram re-weighting: weights are divided by
        ``1 + histogram_weight * sum_c max(0, H_s,c(b) - H_e,c(b))`` with histograms in voxel
        counts (the exemplar's scaled to the volume size); 0 = off, 1 = the paper's formula.
    mean_shift : None, float or (float, float)
        Mean-shift bandwidths (start, end) of each level as multiples of the exemplar's
        standard deviation; the bandwidth shrinks geometrically over the iterations of a level.
        None = plain weighted average (paper eq. 4).
    upsample : {"trilinear", "8/8", "1/8"}
        Initialisation of a finer level: trilinear interpolation (the paper), or the project's
        pyramid (:mod:`npmrf3d.pyramid`): copy the parent into all 8 children, or only into the
        child at the parent's position with random exemplar texels elsewhere.
    constraint : (N1, N2, N3, C) array, optional
        Target colours ``t_v`` of voxel constraints (the paper's section 6.2, eq. 6).
    constraint_weight : float or (N1, N2, N3) array, optional
        Constraint weights ``tau_v >= 0`` (0 = unconstrained voxel; default 1 everywhere when a
        constraint is given). Coarse levels use block averages of targets and weights.
    rng : None, int or numpy Generator
        Seed; the result depends on it only (not on the number of threads).
    progress : callable, optional
        Called as ``progress(level, iteration, iterations, energy)`` before the first iteration
        of each level (``iteration = 0``, energy nan) and after every iteration (energy = mean
        ``||s - e||^r`` of that iteration's search).
    checkpoint : path, optional
        A ``.npz`` file written after each level; if it exists and holds a checkpoint of the
        same configuration and exemplars, synthesis resumes after its last finished level.

    Returns
    -------
    SynthesisResult
        ``volume`` (N1, N2, N3, C) float32; ``history`` the mean energy of each iteration's
        search, one list per level (coarsest first); ``config`` a :class:`KopfConfig`;
        ``timings`` seconds (``setup``, ``level_<l>``, ``total``); ``labels`` an empty
        ``(0, C)`` array (NP_K works with continuous values, not a label set); ``stats`` per
        level: shape, iterations, queries, PCA dimensions and exemplar neighbourhoods per view,
        search and optimisation seconds, and the thread count.

    Examples
    --------
    >>> import numpy as np
    >>> stripes = np.tile(np.array([0, 0, 1, 1], dtype=np.uint8) * 255, (16, 4))
    >>> res = kopf_synthesize(stripes, size=8, window=4, levels=1, views="front", iterations=2, rng=0)
    >>> res.volume.shape
    (8, 8, 8, 1)
    """
    t_start = time.perf_counter()
    seed = rng if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) else None
    config = make_kopf_config(
        size=size, window=window, levels=levels, views=views, iterations=iterations, r=r, eps=eps,
        variance=variance, grid=grid, histogram_bins=histogram_bins,
        histogram_weight=histogram_weight, mean_shift=mean_shift, upsample=upsample,
        constrained=constraint is not None, seed=seed,
    )
    generator = check.rng(rng)
    per_view = resolve_exemplars(exemplar, exemplars, config.views, window=config.window,
                                 levels=config.levels)
    channels = next(iter(per_view.values())).shape[2]
    target, tau = _constraint_arrays(constraint, constraint_weight, config.size, channels)
    return run_kopf(config, per_view, generator, constraint=target, constraint_weight=tau,
                    progress=progress, checkpoint=checkpoint, t_start=t_start)


class _KopfLevels(Levels):
    """NP_K's side of :func:`npmrf3d.pyramid.run_pyramid`; the state is the volume itself."""

    def __init__(self, config: KopfConfig, per_view: Mapping[str, np.ndarray], constraint,
                 constraint_weight):
        self.config, self.per_view = config, per_view
        self.constraint, self.constraint_weight = constraint, constraint_weight
        self.size, self.levels = config.size, config.levels
        self.key = json.dumps(config.to_dict(), sort_keys=True, default=str)
        self.distinct = list({id(a): a for a in (per_view[v] for v in config.views)}.values())
        self.channels = self.distinct[0].shape[2]
        pooled = np.concatenate([a.reshape(-1, self.channels) for a in self.distinct]).astype(np.float64)
        self.lo = pooled.min(axis=0)
        span = pooled.max(axis=0) - self.lo
        self.scale = np.where(span > 0, config.histogram_bins / np.where(span > 0, span, 1.0), 0.0)
        self.sigma = float(pooled.std()) or 1.0
        self.view_axes = np.array([VIEW_AXES[v] for v in config.views], dtype=np.int64)
        # the volume's bytes depend on the exemplars and the constraint too
        self.fingerprint = {"exemplars": np.concatenate([a.ravel() for a in self.distinct])}
        if constraint is not None:
            self.fingerprint["constraint"] = constraint
            self.fingerprint["constraint_weight"] = constraint_weight

    def prepare(self, level, shape):
        config, views, per_view = self.config, self.config.views, self.per_view
        level_ex = {id(a): downsample_exemplar(a, level) for a in self.distinct}
        indices = {key: PatchIndex(ex, config.window, config.variance) for key, ex in level_ex.items()}
        self.view_index = [indices[id(per_view[v])] for v in views]
        self.pixels = np.concatenate([ex.reshape(-1, self.channels) for ex in level_ex.values()])
        self.hist_target = np.mean(
            [channel_histograms(level_ex[id(per_view[v])], self.lo, self.scale, config.histogram_bins)
             / (level_ex[id(per_view[v])].shape[0] * level_ex[id(per_view[v])].shape[1])
             for v in views], axis=0)
        self.packed = _pack_exemplars(self.view_index, self.lo, self.scale, config.histogram_bins)
        self.target, self.tau = _coarsen_constraint(self.constraint, self.constraint_weight, level)
        self.floor = 1e-3 * self.sigma * math.sqrt(config.window ** 2 * self.channels)
        self.n_iter = config.iterations[config.levels - 1 - level]

    def initial(self, shape, rng):
        return np.ascontiguousarray(self.pixels[rng.integers(0, len(self.pixels), size=shape)],
                                    dtype=np.float32)

    def upsample(self, state, rng):
        return _upsample(state, self.config.upsample, self.pixels, rng)

    def start(self, level, state):
        return self.n_iter, float("nan")

    def relax(self, level, volume, rng, on_step):
        config, views, n_iter = self.config, self.config.views, self.n_iter
        shape = volume.shape[:3]
        level_history = []
        t_search = t_opt = 0.0
        queries = 0
        for it in range(n_iter):
            ts = time.perf_counter()
            assign = np.empty((len(views), *shape), dtype=np.int32)
            omega = np.empty((len(views), *shape), dtype=np.float32)
            energy = 0.0
            for vi, view in enumerate(views):
                assign[vi], omega[vi], e, q = search_view(
                    volume, view, self.view_index[vi], grid=config.grid, eps=config.eps, r=config.r,
                    floor=self.floor, offset=int(self.packed.offsets[vi]))
                energy += e
                queries += q
            t_search += time.perf_counter() - ts
            ts = time.perf_counter()
            if config.mean_shift is None:
                bandwidth = 0.0
            else:
                h0, h1 = config.mean_shift
                frac = it / (n_iter - 1) if n_iter > 1 else 1.0
                bandwidth = self.sigma * h0 * (h1 / h0) ** frac
            order = rng.permutation(volume.shape[0] * volume.shape[1] * volume.shape[2]).astype(np.int64)
            hist = channel_histograms(volume, self.lo, self.scale, config.histogram_bins)
            optimisation_phase(volume, assign, omega, self.view_axes, self.packed,
                               window=config.window, grid=config.grid, order=order, hist=hist,
                               hist_target=self.hist_target, histogram_weight=config.histogram_weight,
                               lo=self.lo, scale=self.scale, bins=config.histogram_bins,
                               bandwidth=bandwidth, constraint=self.target, tau=self.tau)
            t_opt += time.perf_counter() - ts
            sites = sum(int((assign[vi] >= 0).sum()) for vi in range(len(views)))
            level_history.append(energy / max(1, sites))
            on_step(it + 1, level_history[-1])
        stats = {
            "shape": list(shape), "iterations": n_iter, "queries": queries,
            "search_seconds": t_search, "optimise_seconds": t_opt,
            "pca_dims": {v: self.view_index[vi].dims for vi, v in enumerate(views)},
            "patches": {v: int(self.view_index[vi].patches.shape[0]) for vi, v in enumerate(views)},
        }
        return volume, level_history, stats

    def to_arrays(self, volume):
        return {"volume": volume}

    def from_arrays(self, arrays):
        return np.ascontiguousarray(arrays["volume"], dtype=np.float32)


def run_kopf(config: KopfConfig, per_view: Mapping[str, np.ndarray], rng: np.random.Generator, *,
             constraint=None, constraint_weight=None, progress: ProgressCallback | None = None,
             checkpoint=None, t_start: float | None = None) -> SynthesisResult:
    """Run a validated configuration on validated exemplars (the body of :func:`kopf_synthesize`).

    ``checkpoint``: a ``.npz`` file written after each level, resumed from when it matches (as
    for :func:`npmrf3d.synthesize`).
    """
    t_start = time.perf_counter() if t_start is None else t_start
    levels = _KopfLevels(config, per_view, constraint, constraint_weight)
    out = run_pyramid(levels, rng, progress=progress, checkpoint=checkpoint,
                      timings={"setup": time.perf_counter() - t_start},
                      stats={"threads": _jit.thread_count()}, t_start=t_start)
    return SynthesisResult(volume=out.state, history=out.history, config=config,
                           timings=out.timings, labels=np.zeros((0, levels.channels), dtype=np.float32),
                           stats=out.stats)


def kopf_method(per_view: Mapping[str, np.ndarray], config: KopfConfig, rng: np.random.Generator, *,
                progress: ProgressCallback | None = None, checkpoint=None, constraint=None,
                constraint_weight=None, t_start: float | None = None) -> SynthesisResult:
    """NP_K in the common method signature (:data:`npmrf3d.methods.METHODS`); ``constraint``
    and ``constraint_weight`` are raw arrays, validated here."""
    channels = next(iter(per_view.values())).shape[2]
    target, tau = _constraint_arrays(constraint, constraint_weight, config.size, channels)
    return run_kopf(config, per_view, rng, constraint=target, constraint_weight=tau,
                    progress=progress, checkpoint=checkpoint, t_start=t_start)


#: The registry entry of NP_K.
METHOD = SynthesisMethod(
    name="kopf", run=kopf_method, make_config=make_kopf_config, config_class=KopfConfig,
    synthesize=kopf_synthesize,
    fit=lambda c: {"window": c.window, "levels": c.levels, "toroidal": False},
    description="NP_K, texture optimisation with histogram matching (Kopf et al. 2007)",
)
