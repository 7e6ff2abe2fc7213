"""k-coherence machinery: per-level exemplar models, source maps, candidates and matches.

The model layer of Chen & Wang 2010 ("High quality solid texture synthesis using position and
index histogram matching"), kept apart from the method so that other samplers can reuse it; the
engine that runs it level by level, with the solver's histograms, is
:mod:`npmrf3d.model.kcoherence_engine`:

* :func:`build_level_model` -- one exemplar at one level: its neighbourhoods (one per *valid
  centre*, the pixels whose window lies inside the exemplar), their PCA projection to about 20
  dimensions, and each valid centre's **k-coherence set** (its ``k`` most similar valid centres
  in the PCA space; a k-d tree bounded on repeated patches, :class:`~.nearest.PatchIndex`).
* **source maps** -- for every voxel and view the exemplar pixel it was copied from (flat index
  ``row * W + col``): :func:`random_sources`, :func:`upsample_sources` (``2 * parent + offset``).
* **candidate sets** -- :func:`candidate_set`, the union over a site's 3 x 3 in-plane neighbours
  of their coherent shifts and the shifts' k-coherence sets.
* **global matches** -- :func:`global_matches`: the worst-matched sites of a view also search
  all exemplar neighbourhoods (``cKDTree``) and take the global match where it is clearly better
  than the coherent one (Hertzmann et al. 2001's coherence rule), so that a structure no
  coherent candidate proposes -- a sparse bright spot -- can still be matched.
* **the histogram factor** -- :func:`histogram_factor` (``1 + strength * max(0, H / even -
  1)``, the paper's eq. 4 and 6 in units of the even share) of the position and index histograms.

Window geometry: a window of side ``w`` (odd or even) at site/pixel ``u`` covers
``u - a .. u - a + w - 1`` along both plane axes, ``a = (w - 1) // 2`` (:func:`anchor`); the
volume is toroidal, the exemplar is not. Views and axes as in :mod:`npmrf3d.model.neighbourhood`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .._kernels import kcoherence as _k
from .nearest import PatchIndex, nearest_others
from .neighbourhood import VIEW_AXES

__all__ = [
    "LevelModel",
    "anchor",
    "build_level_model",
    "candidate_set",
    "centre_patches",
    "downsample_exemplar",
    "global_matches",
    "histogram_factor",
    "k_coherence_sets",
    "pca_project",
    "random_sources",
    "search_exemplar",
    "upsample_sources",
    "valid_centres",
]


class LevelModel(NamedTuple):
    """One exemplar at one pyramid level, ready for the kernels.

    Attributes
    ----------
    exemplar : (H, W, C) float32 ndarray
    window, anchor : int
        Window side and anchor ``a`` (window of pixel ``p`` covers ``p - a .. p - a + w - 1``).
    bounds : (lo_r, hi_r, lo_c, hi_c)
        The valid centres are rows ``lo_r..hi_r`` and columns ``lo_c..hi_c`` (inclusive).
    mean : (d,) float64 ndarray
        Mean neighbourhood, ``d = window**2 * C`` in (row, column, channel) order.
    basis : (d, D) float64 ndarray
        Orthonormal principal directions (``D <= dims``).
    proj : (H * W, D) float64 ndarray
        Projection of the neighbourhood of every valid centre (rows of other pixels are 0).
    kcoh : (H * W, k) int32 ndarray
        k-coherence set of every valid centre, most similar first (rows of other pixels -1).
    valid : (n,) int64 ndarray
        Flat indices of the valid centres, row-major.
    tree : npmrf3d.model.nearest.PatchIndex
        The valid centres' projections (rows of ``proj[valid]``), for global searches
        (:func:`global_matches`); ``tree.distinct`` is the number of vectors its k-d tree holds.
    """

    exemplar: np.ndarray
    window: int
    anchor: int
    bounds: tuple[int, int, int, int]
    mean: np.ndarray
    basis: np.ndarray
    proj: np.ndarray
    kcoh: np.ndarray
    valid: np.ndarray
    tree: PatchIndex

    @property
    def pixels(self) -> int:
        return self.exemplar.shape[0] * self.exemplar.shape[1]

    @property
    def centres(self) -> int:
        lo_r, hi_r, lo_c, hi_c = self.bounds
        return (hi_r - lo_r + 1) * (hi_c - lo_c + 1)


def anchor(window: int) -> int:
    """Offset of a window's reference pixel from its top-left corner: ``(window - 1) // 2``.

    >>> anchor(8), anchor(7)
    (3, 3)
    """
    return (int(window) - 1) // 2


def downsample_exemplar(exemplar: np.ndarray, level: int) -> np.ndarray:
    """Box average over ``2^level x 2^level`` blocks, ``(H // 2^level, W // 2^level, C)`` float32.

    Pixel ``(r, c)`` of level ``l`` averages pixels ``2r..2r+1, 2c..2c+1`` of level ``l - 1``,
    which is what makes ``2 * parent + offset`` the right source up-sampling.

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


def valid_centres(shape: tuple[int, ...], window: int) -> tuple[int, int, int, int]:
    """``(lo_r, hi_r, lo_c, hi_c)``: the pixels whose window lies inside an ``H x W`` exemplar.

    >>> valid_centres((10, 12), 4)
    (1, 7, 1, 9)
    """
    a = anchor(window)
    return a, shape[0] - window + a, a, shape[1] - window + a


def centre_patches(exemplar: np.ndarray, window: int) -> np.ndarray:
    """Neighbourhoods of the valid centres (every ``window x window`` window that lies inside the
    exemplar), ``(n, window**2 * C)`` float32, ``n = (H - window + 1)(W - window + 1)``: row
    ``p = pr * (W - window + 1) + pc`` is ``exemplar[pr:pr + window, pc:pc + window]`` flattened
    in (row, column, channel) order (NP_K's patches too, :mod:`npmrf3d.methods.kopf`)."""
    view = sliding_window_view(exemplar, (window, window), axis=(0, 1))  # (H', W', C, w, w)
    view = view.transpose(0, 1, 3, 4, 2)
    return np.ascontiguousarray(view, dtype=np.float32).reshape(-1, window * window * exemplar.shape[2])


def pca_project(patches: np.ndarray, dims: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project the rows of ``patches`` on their ``dims`` leading principal directions.

    Returns
    -------
    mean : (d,) float64 ndarray
    basis : (d, D) float64 ndarray, ``D = min(dims, d)``, orthonormal columns (eigenvectors of the
        scatter matrix, largest eigenvalue first; signs as returned by ``numpy.linalg.eigh``)
    projected : (n, D) float64 ndarray, ``(patches - mean) @ basis``

    float64 because the search kernel computes in float64: float32 tables cost it 1.5x in
    conversions (measured, 64^3 search of one view).

    The two other PCAs are not this one: NP_K's (:func:`npmrf3d.model.kopf_search.pca_basis`)
    keeps a share of the variance by an SVD and a float32 basis, and the 3D appearance space's
    (:func:`npmrf3d.methods.volume_lh.appearance_space`) multiplies two copies of the centred
    vectors (a general product, where ``x.T @ x`` of one array is numpy's symmetric one), which
    differs in the last bits: sharing one would change the volumes.

    Examples
    --------
    >>> x = np.random.default_rng(0).normal(size=(200, 5))
    >>> [a.shape for a in pca_project(x, 3)]
    [(5,), (5, 3), (200, 3)]
    """
    x = patches.astype(np.float64)
    mean = x.mean(axis=0)
    x = x - mean
    _, vecs = np.linalg.eigh(x.T @ x)
    take = min(int(dims), x.shape[1])
    basis = np.ascontiguousarray(vecs[:, ::-1][:, :take])
    return mean, basis, np.ascontiguousarray(x @ basis)


def k_coherence_sets(points: np.ndarray, k: int = 5, *, exclude: float = 0.0,
                     coords: np.ndarray | None = None, tree: PatchIndex | None = None) -> np.ndarray:
    """Indices of the ``k`` nearest other points of every point (:class:`~.nearest.PatchIndex`).

    Parameters
    ----------
    points : (n, D) ndarray
    k : int
        Set size; requires more than ``k`` eligible points.
    exclude : float
        If > 0, points whose ``coords`` lie within this Chebyshev distance of the query point
        (its own shifted copies) are skipped, so the sets point to other places of the exemplar.
    coords : (n, 2) ndarray, optional
        Pixel coordinates of the points (needed with ``exclude``).
    tree : PatchIndex, optional
        An index of ``points`` already built.

    Returns
    -------
    (n, k) int64 ndarray, nearest first; a point is never in its own set. Ties are broken as
    ``cKDTree.query`` breaks them (exact Euclidean distances); when the index keeps only the
    distinct vectors (many repeated patches), identical points rank by their index
    (:func:`npmrf3d.model.nearest.nearest_others`).

    (The 3D method's similarity sets follow another rule: :func:`npmrf3d.methods.volume_lh.similarity_sets`.)
    """
    if tree is None:
        tree = PatchIndex(points)
    if tree.deduplicated:
        return nearest_others(tree, k, exclude=exclude, coords=coords)
    n = len(points)
    want = min(n, k + 1 if exclude <= 0 else max(4 * k, k + 1 + int((2 * exclude + 1) ** 2)))
    out = np.empty((n, k), dtype=np.int64)
    todo = np.arange(n)
    while todo.size:
        _, idx = tree.query(points[todo], want)
        ok = idx != todo[:, None]
        if exclude > 0:
            cheb = np.abs(coords[idx] - coords[todo][:, None, :]).max(axis=2)
            ok &= cheb > exclude
        enough = ok.sum(axis=1) >= k
        if want >= n:
            enough[:] = True
        for row in np.flatnonzero(enough):
            sel = idx[row][ok[row]][:k]
            if sel.size < k:  # fewer eligible points than k: repeat the last one
                sel = np.concatenate([sel, np.repeat(sel[-1:] if sel.size else todo[row:row + 1], k - sel.size)])
            out[todo[row]] = sel
        todo = todo[~enough]
        want = min(n, 2 * want)
    return out


def build_level_model(exemplar: np.ndarray, window: int, *, dims: int = 20, k: int = 5,
                      exclude: float = 0.0) -> LevelModel:
    """PCA-reduced neighbourhoods and k-coherence sets of one exemplar at one level.

    Parameters
    ----------
    exemplar : (H, W, C) float32 ndarray, at least ``window`` pixels per side
    window : int >= 2
    dims : int
        PCA dimensions kept (the paper: about 20; fewer if ``window**2 * C`` is smaller).
    k : int
        Size of the k-coherence sets (the paper: 5).
    exclude : float
        See :func:`k_coherence_sets` (0 = plain k nearest other centres).

    Returns
    -------
    LevelModel
    """
    exemplar = np.ascontiguousarray(exemplar, dtype=np.float32)
    h, w = exemplar.shape[:2]
    bounds = valid_centres(exemplar.shape, window)
    lo_r, hi_r, lo_c, hi_c = bounds
    patches = centre_patches(exemplar, window)
    mean, basis, projected = pca_project(patches, dims)
    rows, cols = np.meshgrid(np.arange(lo_r, hi_r + 1), np.arange(lo_c, hi_c + 1), indexing="ij")
    flat = (rows * w + cols).ravel()
    k_eff = min(k, len(flat) - 1) if len(flat) > 1 else 0
    proj = np.zeros((h * w, basis.shape[1]), dtype=np.float64)
    proj[flat] = projected
    kcoh = np.full((h * w, k), -1, dtype=np.int32)
    tree = PatchIndex(projected)
    if k_eff > 0:
        sets = k_coherence_sets(projected, k_eff, exclude=exclude,
                                coords=np.stack([rows.ravel(), cols.ravel()], axis=1), tree=tree)
        sets = flat[sets]
        if k_eff < k:
            sets = np.concatenate([sets, np.repeat(sets[:, -1:], k - k_eff, axis=1)], axis=1)
        kcoh[flat] = sets
    else:
        kcoh[flat] = flat[:, None]
    return LevelModel(exemplar, int(window), anchor(window), bounds, mean, basis, proj, kcoh,
                      flat.astype(np.int64), tree)


def search_exemplar(model: LevelModel) -> _k.SearchExemplar:
    """The model as the compiled search reads it (:func:`npmrf3d._kernels.kcoherence.search_view`)."""
    (lo_r, hi_r, lo_c, hi_c), ex = (int(b) for b in model.bounds), np.asarray(model.exemplar, dtype=np.float32)
    return _k.SearchExemplar(int(model.window), int(model.anchor), int(ex.shape[1]), lo_r, hi_r, lo_c, hi_c,
                             model.mean, model.basis, model.proj, model.kcoh, ex.reshape(-1, ex.shape[2]))


# --------------------------------------------------------------------------- source maps


def random_sources(shape: tuple[int, int, int], exemplar_shape: tuple[int, ...],
                   rng: np.random.Generator) -> np.ndarray:
    """Uniformly random source pixels, ``shape`` int32 flat indices into an ``H x W`` exemplar."""
    return rng.integers(0, exemplar_shape[0] * exemplar_shape[1], size=shape).astype(np.int32)


def upsample_sources(src: np.ndarray, view: str, coarse_width: int, fine_shape: tuple[int, ...]) -> np.ndarray:
    """Source map of the next finer level: child ``2 * x + o`` gets source ``2 * parent + offset``.

    Parameters
    ----------
    src : (N1, N2, N3) int32, flat sources into the coarse exemplar (width ``coarse_width``)
    view : the view whose plane axes ``(ra, ca)`` carry the offset
    fine_shape : (H, W, ...) of the finer exemplar

    Returns
    -------
    (2 N1, 2 N2, 2 N3) int32: for child offset ``o`` (in ``{0, 1}^3``), source row
    ``2 * parent_row + o[ra]`` and column ``2 * parent_col + o[ca]``, clipped into the finer
    exemplar (only needed when its side is odd... never for box-averaged levels).
    """
    ra, ca = VIEW_AXES[view]
    out = np.empty(tuple(2 * n for n in src.shape), dtype=np.int32)
    _k.upsample_sources(np.ascontiguousarray(src, dtype=np.int32), ra, ca, int(coarse_width), int(fine_shape[0]),
                        int(fine_shape[1]), out)
    return out


def candidate_set(src_v: np.ndarray, view: str, site: tuple[int, int, int], model: LevelModel) -> np.ndarray:
    """The k-coherence candidate set of one site of one view (sorted, distinct).

    Union over the in-plane neighbours ``u + delta`` (``delta`` in ``{-1, 0, 1}^2``, the site
    included) of the coherent shift ``source(u + delta) - delta`` (clamped to the valid centres)
    and its k-coherence set. The compiled search enumerates the same list (with repeats).

    Returns
    -------
    (m,) int64 ndarray of flat exemplar indices
    """
    ra, ca = VIEW_AXES[view]
    out = np.empty(9 * (1 + model.kcoh.shape[1]), dtype=np.int64)
    count = _k.candidates(np.ascontiguousarray(src_v, dtype=np.int32), ra, ca, *map(int, site),
                          search_exemplar(model), out)
    return np.unique(out[:count])


def global_matches(volume: np.ndarray, view: str, model: LevelModel, assign_v: np.ndarray,
                   omega_v: np.ndarray, index_hist: np.ndarray, *, share: float, bias: float,
                   phi: float, index_weight: float, r: float, floor: float) -> tuple[int, float]:
    """Give the worst-matched sites of one view a global search; update their matches in place.

    The ``ceil(share * sites)`` sites with the largest match distance (ties: the lower flat
    index first) project their neighbourhoods (:func:`npmrf3d._kernels.kcoherence.project_sites`)
    and query the ``min(4, centres)`` nearest valid centres in the PCA space (``model.tree``);
    among those the one with the smallest distance times the index-histogram factor
    ``1 + index_weight * max(0, index_hist / phi - 1)`` is the global match (the first on ties).
    It replaces the coherent match when its distance times ``1 + bias`` is below the coherent
    distance (Hertzmann et al. 2001, "Image analogies": keep the coherent match unless the
    global one is clearly better). Replaced sites get the new centre in ``assign_v``, the IRLS
    weight ``max(dist, floor) ** (r - 2)`` in ``omega_v`` and their counts moved in
    ``index_hist``.

    Parameters
    ----------
    volume : (N1, N2, N3, C) float32
    view : the view of ``assign_v`` (its plane axes)
    model : the view's exemplar at this level
    assign_v : (N1, N2, N3) int32, the centre matched at every site (-1 where no site)
    omega_v : (N1, N2, N3) float32, IRLS weights ``max(dist, floor) ** (r - 2)`` of the matches
    index_hist : (H * W,) float64 counts of sites per centre
    share : float in [0, 1]
    bias, phi, index_weight, r, floor : as above; ``r < 2``

    Returns
    -------
    (replaced, energy_change) : the number of sites re-matched and the change of ``sum dist ** r``
    (distances below ``floor`` count as ``floor``)
    """
    sites = np.flatnonzero(assign_v.ravel() >= 0).astype(np.int64)
    take = min(len(sites), int(np.ceil(share * len(sites))))
    if take == 0:
        return 0, 0.0
    weights = omega_v.ravel()[sites].astype(np.float64)
    worst = sites[np.argsort(weights, kind="stable")[:take]]  # lowest weight = largest distance
    old_dist = omega_v.ravel()[worst].astype(np.float64) ** (1.0 / (r - 2.0))
    ra, ca = VIEW_AXES[view]
    y = np.empty((take, model.basis.shape[1]), dtype=np.float64)
    _k.project_sites(volume, ra, ca, model.window, model.anchor, model.mean, model.basis, worst, y)
    nearest = min(4, len(model.valid))
    dist, idx = model.tree.query(y, nearest)
    centres = model.valid[idx]
    excess = index_hist[centres] / phi - 1.0
    cost = dist ** 2 * np.where(excess > 0.0, 1.0 + index_weight * excess, 1.0)
    pick = np.argmin(cost, axis=1)
    new_centre = centres[np.arange(take), pick]
    new_dist = np.maximum(dist[np.arange(take), pick], floor)
    better = new_dist * (1.0 + bias) < old_dist
    if not better.any():
        return 0, 0.0
    chosen = worst[better]
    flat_assign = assign_v.reshape(-1)
    np.subtract.at(index_hist, flat_assign[chosen].astype(np.int64), 1.0)
    np.add.at(index_hist, new_centre[better], 1.0)
    flat_assign[chosen] = new_centre[better]
    omega_v.reshape(-1)[chosen] = (new_dist[better] ** (r - 2.0)).astype(np.float32)
    change = float((new_dist[better] ** r - old_dist[better] ** r).sum())
    return int(better.sum()), change


# --------------------------------------------------------------------------- histograms


def histogram_factor(counts: np.ndarray, even: float, strength: float = 1.0) -> np.ndarray:
    """The histogram re-weighting factor ``1 + strength * max(0, counts / even - 1)``.

    ``even`` is the count every bin would have if all were used equally (the paper's theta for
    positions, phi for indices). The paper divides IRLS weights by this factor (eq. 4, position
    histogram) and multiplies search distances by it (eq. 6, index histogram); it writes the
    excess in counts, ``1 + max(0, H - theta)``, which is ``strength = even`` here.

    >>> histogram_factor(np.array([0.0, 2.0, 6.0]), 2.0).tolist()
    [1.0, 1.0, 3.0]
    """
    return 1.0 + strength * np.maximum(0.0, np.asarray(counts, dtype=np.float64) / even - 1.0)
