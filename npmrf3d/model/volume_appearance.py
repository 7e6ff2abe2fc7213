"""The 3D exemplar's model of the volume-lh method: each level's appearance space (the exemplar
Gaussian-smoothed for the level's spacing, every voxel's neighbourhood projected by PCA) and the
similarity sets searched in it (the vector-field deformation method, IET Image Processing 2012;
:mod:`npmrf3d.methods.volume_lh` documents the method, ``docs/volume.md`` the choices).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from .._kernels import _jit
from .._kernels import volume_lh as _k

__all__ = ["PCA_SAMPLES", "SET_QUERY", "SET_STRIDE", "appearance_space", "similarity_sets", "smoothed",
           "valid_box"]

#: Exemplar voxels sampled to compute the PCA of each level.
PCA_SAMPLES = 20000
#: Stride of the lattice the similarity sets are searched in, and the neighbours queried.
SET_STRIDE = 2
SET_QUERY = 48


def smoothed(exemplar: np.ndarray, level: int) -> np.ndarray:
    """The exemplar of a level: Gaussian-smoothed by ``sigma = 2**level / 2`` (none at level 0),
    float64, borders by nearest values (as :func:`appearance_space` sees it)."""
    h = 2 ** level
    ex = exemplar.astype(np.float64)
    if h > 1:
        ex = ndimage.gaussian_filter(ex, sigma=(h / 2, h / 2, h / 2, 0), mode="nearest")
    return np.ascontiguousarray(ex)


def appearance_space(exemplar: np.ndarray, level: int, window: int, dims: int,
                     rng: np.random.Generator) -> np.ndarray:
    """The appearance-space exemplar of one level: ``(D, H, W, dims)`` float64.

    Each voxel's ``window^3`` neighbourhood, sampled every ``h = 2**level`` voxels in the exemplar
    smoothed by a Gaussian of ``sigma = h / 2`` (none at level 0), borders clamped, projected on
    the ``dims`` leading principal directions of :data:`PCA_SAMPLES` random voxels' vectors
    (the scatter matrix a product of two copies of the centred vectors: not
    :func:`npmrf3d.model.kcoherence.pca_project`, whose one-array product differs in the last
    bits).
    """
    h = 2 ** level
    ex = smoothed(exemplar, level)
    shape = ex.shape[:3]
    r = window // 2
    offsets = [(a, b, c) for a in range(-r, r + 1) for b in range(-r, r + 1) for c in range(-r, r + 1)]
    n = shape[0] * shape[1] * shape[2]
    sample = np.sort(rng.choice(n, size=min(n, PCA_SAMPLES), replace=False))
    pos = np.stack(np.unravel_index(sample, shape), axis=1)
    vectors = np.concatenate([ex[tuple(np.clip(pos[:, a] + h * o[a], 0, shape[a] - 1) for a in range(3))]
                              for o in offsets], axis=1)
    mean = vectors.mean(axis=0)
    _, vecs = np.linalg.eigh((vectors - mean).T @ (vectors - mean))
    basis = vecs[:, ::-1][:, :min(dims, vectors.shape[1])]
    out = np.empty(shape + (basis.shape[1],))
    _k.project(np.ascontiguousarray(ex), h, r, mean, np.ascontiguousarray(basis), out)
    return out


def similarity_sets(feat: np.ndarray, lo: np.ndarray, hi: np.ndarray, k: int, exclude: int) -> np.ndarray:
    """``(D * H * W, k)`` int64 flat indices: row ``q`` is the similarity set of valid voxel ``q``
    (itself first; rows of voxels outside the valid box hold the voxel itself).

    The sets are searched for the valid voxels of a lattice of stride :data:`SET_STRIDE` (exact
    ``cKDTree`` over the lattice, :data:`SET_QUERY` nearest, then the exclusion rule,
    :func:`npmrf3d._kernels.volume_lh.similarity_sets`); every other valid voxel takes its lattice
    voxel's set shifted by its offset from it (a coherent shift), clamped to the valid box.
    """
    shape = feat.shape[:3]
    flat_all = np.arange(shape[0] * shape[1] * shape[2], dtype=np.int64)
    out = np.repeat(flat_all[:, None], k, axis=1)
    if k == 1:
        return out
    axes = [np.arange(lo[a], hi[a] + 1) for a in range(3)]
    lattice = np.stack(np.meshgrid(*[x[::SET_STRIDE] for x in axes], indexing="ij"), axis=-1).reshape(-1, 3)
    points = feat[tuple(lattice.T)]
    m = min(len(lattice), SET_QUERY)
    _, idx = cKDTree(points).query(points, k=m, workers=_jit.thread_count())
    idx = np.asarray(idx, dtype=np.int64).reshape(len(lattice), m)
    # a point's own row first (exact duplicates could come back in another order)
    own = np.arange(len(lattice))
    idx = np.concatenate([own[:, None], np.where(idx == own[:, None], own[:, None], idx)], axis=1)
    sets = np.empty((len(lattice), k), dtype=np.int64)
    _k.similarity_sets(idx, lattice.astype(np.int64), k, exclude, sets)
    members = lattice[sets]  # (L, k, 3) positions
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    rep = lo + (grid - lo) // SET_STRIDE * SET_STRIDE
    steps = [len(x[::SET_STRIDE]) for x in axes]
    row = np.ravel_multi_index(tuple(((rep - lo) // SET_STRIDE).T), steps)
    shifted = np.clip(members[row] + (grid - rep)[:, None, :], lo, hi)
    shifted[:, 0] = grid
    out[np.ravel_multi_index(tuple(grid.T), shape)] = np.ravel_multi_index(
        tuple(shifted.reshape(-1, 3).T), shape).reshape(-1, k)
    return out


def valid_box(shape, window: int) -> tuple[np.ndarray, np.ndarray]:
    """The box ``[lo, hi]`` of exemplar coordinates whose ``window``-sided neighbourhoods lie
    inside an exemplar of ``shape`` (``window // 2`` voxels from its faces)."""
    r = window // 2
    return np.full(3, r, dtype=np.int64), np.array([n - 1 - r for n in shape], dtype=np.int64)
