"""The exemplar model: loading, channels, label sets, decimation and patches.

An exemplar is a float32 ``(H, W, C)`` array: 8-bit images are scaled to ``[0, 1]``, 16-bit to
``[0, 1]``, float data keeps its units. Synthesis works on the exemplar's *label image*: every
pixel replaced by its label (its own value, a re-quantised grey level, or the nearest palette
colour), so each patch centre is a label and the label histogram identity of SPEC.md section 2
holds exactly.

Coarse levels (SPEC.md section 5) use **all** ``2^l x 2^l`` decimation phases of the exemplar
as samples: the level-``l`` exemplar is the set of images ``Y[a::2^l, b::2^l]``, and patches
are taken from each of them (never across phases). Same statistics, ``4^l`` times more samples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.cluster.vq import kmeans2, vq

from . import _validation as check
from .neighborhood import window_offsets

__all__ = ["decimation_phases", "extract_patches", "load_exemplar", "make_labels"]


def load_exemplar(source=None, *, name: str = "exemplar") -> np.ndarray:
    """Load an exemplar as a float32 ``(H, W, C)`` array.

    Parameters
    ----------
    source : str, Path, ndarray or None
        A PNG/JPEG/TIFF/``.npy`` file, an array ``(H, W)`` or ``(H, W, C)``, or None for the
        bundled default exemplar (:data:`npmrf3d.data.DEFAULT_EXEMPLAR`).
    name : str
        How the exemplar is called in error messages (e.g. ``"exemplar for view top"``).

    Returns
    -------
    (H, W, C) float32 ndarray
        uint8 data divided by 255, uint16 by 65535, bool as 0/1, floats unchanged.

    Examples
    --------
    >>> load_exemplar(np.zeros((8, 9), dtype=np.uint8)).shape
    (8, 9, 1)
    """
    if source is None:
        from . import data

        source = data.path(data.DEFAULT_EXEMPLAR)
    if isinstance(source, (str, Path)):
        from .io import read_array

        array = read_array(source, what="exemplar file")
        name = f"{name} '{source}'"
    else:
        array = np.asarray(source)
    return check.exemplar_array(array, name=name)


def make_labels(
    exemplars: list[np.ndarray], *, grey_levels: int | None = None, palette: int | None = None,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Build one label set shared by all exemplars and their label images.

    Parameters
    ----------
    exemplars : list of (H, W, C) float32 ndarrays (same C)
    grey_levels : int, optional
        Re-quantise every channel to this many evenly spaced levels between the pooled min and
        max before taking distinct values (e.g. 32, as in the paper's grey-level study).
    palette : int, optional
        Reduce to at most this many colours by k-means (``scipy.cluster.vq.kmeans2``, seeded
        by ``rng``); each pixel takes its nearest palette colour.
    rng : numpy Generator

    Returns
    -------
    labels : (K, C) float32 ndarray, sorted lexicographically
    label_images : list of (H, W) int32 ndarrays, one per exemplar
    """
    pixels = np.concatenate([e.reshape(-1, e.shape[2]) for e in exemplars]).astype(np.float64)
    if grey_levels is not None:
        lo, hi = pixels.min(), pixels.max()
        span = hi - lo if hi > lo else 1.0
        steps = np.rint((pixels - lo) / span * (grey_levels - 1))
        pixels = lo + steps * span / (grey_levels - 1)
    if palette is not None:
        distinct = np.unique(pixels, axis=0)
        if len(distinct) > palette:
            centres, _ = kmeans2(pixels, palette, minit="++", seed=rng)
            codes, _ = vq(pixels, centres)
            pixels = centres[codes]
    labels, inverse = np.unique(pixels.astype(np.float32), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1).astype(np.int32)
    images, start = [], 0
    for e in exemplars:
        size = e.shape[0] * e.shape[1]
        images.append(inverse[start:start + size].reshape(e.shape[:2]))
        start += size
    return labels.astype(np.float32), images


def decimation_phases(image: np.ndarray, level: int) -> list[np.ndarray]:
    """All ``4**level`` decimation phases ``image[a::2**level, b::2**level]``."""
    f = 2 ** level
    return [image[a::f, b::f] for a in range(f) for b in range(f)]


def extract_patches(
    label_image: np.ndarray, labels: np.ndarray, window: int, *, toroidal: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Neighbour vectors and centre labels of every exemplar patch.

    Parameters
    ----------
    label_image : (H, W) int ndarray
    labels : (K, C) float32 ndarray
    window : int, odd
    toroidal : bool
        If True every pixel is a patch centre (the exemplar wraps around); otherwise only pixels
        whose whole window lies inside: ``n = (H - w + 1)(W - w + 1)``.

    Returns
    -------
    patches : (n, (w*w - 1) * C) float32 ndarray, ``patches[p, m*C + c]`` is channel c of the
        m-th neighbour (order of :func:`npmrf3d.neighborhood.window_offsets`)
    centres : (n,) int32 ndarray, label index of each patch centre
    """
    r = window // 2
    values = labels[label_image]  # (H, W, C)
    h, w = label_image.shape
    if toroidal:
        rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    else:
        rows, cols = np.meshgrid(np.arange(r, h - r), np.arange(r, w - r), indexing="ij")
    rows, cols = rows.ravel(), cols.ravel()
    offsets = window_offsets(window)
    rr = (rows[:, None] + offsets[None, :, 0]) % h
    cc = (cols[:, None] + offsets[None, :, 1]) % w
    patches = values[rr, cc].reshape(len(rows), -1)
    return np.ascontiguousarray(patches, dtype=np.float32), label_image[rows, cols].astype(np.int32)
