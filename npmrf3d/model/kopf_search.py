"""The search phase of NP_K (Kopf et al. 2007; docs/kopf.md): the exemplar neighbourhoods'
PCA and approximate nearest-neighbour index, the volume's neighbourhoods on the sparse grid,
and the best exemplar neighbourhood and IRLS weight of each (:func:`search_view`).
:mod:`npmrf3d.methods.kopf` documents the method; :mod:`npmrf3d.model.kopf_levels` runs it.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from . import nearest
from .kcoherence import centre_patches
from .neighbourhood import VIEW_AXES

__all__ = ["CHUNK_BYTES", "QUERY_CHUNK", "NeighbourhoodIndex", "pca_basis", "search_view", "volume_neighbourhoods"]

#: Bytes of neighbourhood vectors gathered per k-d tree batch.
CHUNK_BYTES = 48 * 2**20
#: Queries per k-d tree call: 8x the level models' chunk, since NP_K queries share two threads
#: (``workers``) and its queries (eps = 2) are cheaper.
QUERY_CHUNK = 8 * nearest.QUERY_CHUNK


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


class NeighbourhoodIndex:
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


def search_view(volume: np.ndarray, view: str, index: NeighbourhoodIndex, *, grid: int, eps: float,
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
    step = max(1, CHUNK_BYTES // per_slice)
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
