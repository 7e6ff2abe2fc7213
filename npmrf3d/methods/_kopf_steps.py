"""NP_K's building blocks: exemplar pyramid, PCA + kd-tree search, IRLS optimisation with
histogram matching, up-sampling and voxel constraints (Kopf et al. 2007; docs/kopf.md).

Private to :mod:`npmrf3d.methods.kopf`, which documents the method, validates the inputs and
drives these steps level by level (:func:`npmrf3d.model.pyramid.run_pyramid`). The compiled loops are
in :mod:`npmrf3d._kernels.kopf`.
"""

from __future__ import annotations

import types
from collections.abc import Sequence

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .. import _validation as check
from .._kernels import kopf as _k
from ..model import nearest
from ..model.exemplar import pack_rows
from ..model.kcoherence import (
    centre_patches,
    downsample_exemplar,  # noqa: F401 (one box-average pyramid for every method; kopf.py re-exports it)
)
from ..model.neighbourhood import VIEW_AXES
from ..model.pyramid import LevelState
from ..model.pyramid import upsample as pyramid_upsample

_MEAN_SHIFT_ITERATIONS = 8
_CHUNK_BYTES = 48 * 2**20  # neighbourhood vectors gathered per KD-tree batch
_SWEEP_CHUNK = 1 << 15  # voxels gathered per optimisation batch
#: Queries per k-d tree call: 8x the level models' chunk, since NP_K queries share two threads
#: (``workers``) and its queries (eps = 2) are cheaper.
QUERY_CHUNK = 8 * nearest.QUERY_CHUNK


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
    ``scipy.spatial.cKDTree`` over the projected neighbourhoods, queried with error bound ``eps``
    (through :class:`npmrf3d.model.nearest.PatchIndex`: identical neighbourhoods, as many as a
    constant exemplar has, are searched once, and a search gives way to a signal every
    :data:`QUERY_CHUNK` queries).

    Parameters
    ----------
    exemplar : (H, W, C) float32 ndarray
    window : int
    variance : float in (0, 1]
    """

    def __init__(self, exemplar: np.ndarray, window: int, variance: float = 0.95):
        self.exemplar = np.ascontiguousarray(exemplar, dtype=np.float32)
        self.window = window
        self.patches = centre_patches(self.exemplar, window)
        self.mean, self.basis, self.kept = pca_basis(self.patches, variance)
        self.projected = self.project(self.patches)
        self.tree = nearest.PatchIndex(self.projected, chunk=QUERY_CHUNK)
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
        index = self.tree.query(self.project(vectors), 1, eps=eps, workers=workers)[1][:, 0]
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
        and likewise for the column axis, flattened like
        :func:`npmrf3d.model.kcoherence.centre_patches`.
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
    ex_flat, offsets = pack_rows([idx.exemplar for idx in indices])
    return _Exemplars(
        flat=ex_flat,
        bins=np.ascontiguousarray(channel_bins(ex_flat, lo, scale, bins)),
        offsets=offsets,
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
    """The finer level's volume by :data:`npmrf3d.model.pyramid.UPSAMPLERS` ``mode``; ``1/8`` draws the
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
