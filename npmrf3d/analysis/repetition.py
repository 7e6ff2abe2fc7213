"""How much of a copied volume repeats itself: the largest share of voxels whose exemplar
coordinate comes back at one far shift.

A method that copies exemplar voxels (``volume-lh``, ``npmrf-3d``) can lay whole blocks of the
exemplar side by side: the 128^3 volume is then the 64^3 exemplar repeated with its period,
which the phase fractions, surface area and two-point correlation of a crop do not see (they are
the exemplar's own). This statistic sees it: for a shift ``t`` (toroidal, ``max |t_i| >=
min_shift``) it counts the voxels ``p`` whose coordinate at ``p + t`` is within ``tolerance`` of
their own, ``max_i |S(p + t)_i - S(p)_i| <= tolerance``, and reports the largest count as a share
of all voxels. A volume tiled by the exemplar scores near 1 at ``t`` = its period (a copy moved
by the jitter by a voxel or two still counts); a volume that recombines the exemplar's parts
scores near 0, since two far voxels copy nearby exemplar voxels by chance, each at its own shift.
Every voxel counts at most once per shift, so a flat region that copies one exemplar voxel many
times (a collapse) scores its true share and not a multiple of it (docs/volume.md, "The
repetition statistic": a box sum over shifts would count it up to 125 times, 0.20 on a Berea
volume whose share is 0.02).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .. import _validation as check

__all__ = ["copy_repetition"]

#: Coordinates within this many voxels per axis count as one: two copies of one exemplar block
#: are seldom laid at exactly one shift (the jitter of the finer levels moves each by a voxel or
#: two).
TOLERANCE = 2

#: A coordinate copied by more voxels than this is a collapse (a flat region copying one voxel),
#: left out of the search for the shift; its voxels still count in the share of every shift.
SEARCH_GROUP = 64

#: The shifts whose share is counted: the largest local maxima of the exact-copy histogram.
CANDIDATES = 16

#: Shifts shorter than this (per axis, the largest component) are a patch's own coherence, not
#: repetition.
MIN_SHIFT = 16


def copy_repetition(coords: np.ndarray, *, min_shift: int = MIN_SHIFT, tolerance: int = TOLERANCE,
                    candidates: int | None = CANDIDATES) -> dict:
    """The largest share of voxels whose exemplar coordinate recurs at one shift.

    Parameters
    ----------
    coords : ndarray, shape (N1, N2, N3, 3), int
        The exemplar coordinate each output voxel copies (toroidal output).
    min_shift : int
        Shifts ``t`` with ``max_i |t_i| < min_shift`` are ignored (16: a copied patch's own
        extent).
    tolerance : int
        A voxel counts at ``t`` when ``max_i |S(p + t)_i - S(p)_i| <= tolerance`` (2: a copy
        moved by a voxel or two still counts).
    candidates : int or None
        The shifts counted: in the boxes (``2 tolerance + 1`` shifts per axis) of the
        ``candidates`` largest local maxima of the box-summed histogram of the shifts between
        voxels that copy one coordinate, the most frequent shift of each box (coordinates copied
        more than :data:`SEARCH_GROUP` times left out of that histogram);
        ``None``: every shift (exact, slow beyond 32^3). A repetition is a peak of that
        histogram, so the default finds it; it cannot report more than the exact maximum. The
        shortest far shift along each axis is always counted too (a flat region copying one
        voxel scores there).

    Returns
    -------
    dict
        ``share``: the largest ``#{p : max_i |S(p + t)_i - S(p)_i| <= tolerance} / N`` over the
        shifts counted (at most 1), and ``shift``: that ``t`` (components in ``[-N_i / 2,
        N_i / 2)``; ``None`` when no shift is counted).

    Examples
    --------
    >>> import numpy as np
    >>> grid = np.stack(np.meshgrid(*[np.arange(32) % 16] * 3, indexing="ij"), axis=-1)
    >>> copy_repetition(grid)["share"]   # the exemplar's 16^3 laid twice along each axis
    1.0
    """
    coords = np.asarray(coords)
    if coords.ndim != 4 or coords.shape[3] != 3 or not np.issubdtype(coords.dtype, np.integer):
        check.fail(f"coords must be an integer array (N1, N2, N3, 3); got {coords.dtype} {coords.shape}")
    min_shift = check.integer("min_shift", min_shift, low=1)
    tolerance = check.integer("tolerance", tolerance, low=0, high=8)
    if candidates is not None:
        candidates = check.integer("candidates", candidates, low=1)
    shape = np.array(coords.shape[:3], dtype=np.int64)
    span = coords.reshape(-1, 3).astype(np.int64)
    span = (span - span.min(axis=0)).astype(np.int32)
    reach_of = np.meshgrid(*[np.minimum(np.arange(m), m - np.arange(m)) for m in shape], indexing="ij", sparse=True)
    far = np.maximum(np.maximum(reach_of[0], reach_of[1]), reach_of[2]) >= min_shift
    if candidates is None:
        shifts = np.argwhere(far)
    else:  # and the shortest far shift along each axis, where a collapsed region scores
        shortest = np.diag(np.minimum(min_shift, shape // 2))
        shifts = np.concatenate([_peaks(span, shape, far, tolerance, candidates), shortest[far[tuple(shortest.T)]]])
    field = [np.ascontiguousarray(span[:, a].reshape(tuple(shape))) for a in range(3)]
    best, best_t = 0, None
    for t in shifts:
        near = np.ones(tuple(shape), dtype=bool)
        for component in field:  # moved[p] = S(p + t)_a
            moved = np.roll(component, shift=tuple(int(-x) for x in t), axis=(0, 1, 2))
            near &= np.abs(moved - component) <= tolerance
        count = int(near.sum())
        if count > best or best_t is None:
            best, best_t = count, t
    if best_t is None:
        return {"share": 0.0, "shift": None}
    t = np.where(best_t >= (shape + 1) // 2, best_t - shape, best_t)
    return {"share": best / int(shape.prod()), "shift": [int(x) for x in t]}


def _peaks(span: np.ndarray, shape: np.ndarray, far: np.ndarray, tolerance: int, candidates: int) -> np.ndarray:
    """The ``candidates`` far shifts where the box-summed count of voxel pairs that copy one
    coordinate has its largest local maxima (``(K, 3)`` int, raster order within ties)."""
    n = int(shape.prod())
    key = np.ravel_multi_index(tuple(span.T), tuple(span.max(axis=0).astype(np.int64) + 1))
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    pos = np.stack(np.unravel_index(order, tuple(shape)), axis=-1).astype(np.int32)
    bounds = np.flatnonzero(np.diff(sorted_key, prepend=-1, append=-1))
    group = np.repeat(np.diff(bounds), np.diff(bounds))  # the group size of every sorted voxel
    del key, order
    counts = np.zeros(n, dtype=np.int64)
    reach = min(int(group.max()), SEARCH_GROUP)
    # pairs (i, i + d) of the sorted list share a coordinate when their keys are equal: every
    # pair of a group of m voxels comes once, at d = 1 .. m - 1, counted at its shift t here ...
    for d in range(1, reach):
        equal = sorted_key[d:] == sorted_key[:-d]
        if not equal.any():  # the groups are runs of the sorted list: none is longer than d
            break
        same = np.flatnonzero(equal & (group[d:] <= SEARCH_GROUP))
        t = (pos[same + d] - pos[same]) % shape
        counts += np.bincount(np.ravel_multi_index(tuple(t.T), tuple(shape)), minlength=n)
    # ... and at -t: the second voxel of the pair sees the first there
    counts = counts.reshape(tuple(shape))
    counts += np.roll(np.flip(counts), 1, axis=(0, 1, 2))
    box = 2 * tolerance + 1
    summed = ndimage.uniform_filter(counts.astype(np.float64), size=box, mode="wrap") * box ** 3
    summed = np.rint(summed)
    summed[~far] = 0
    peak = (summed > 0) & (summed == ndimage.maximum_filter(summed, size=box, mode="wrap"))
    at = np.flatnonzero(peak.ravel())
    at = at[np.argsort(-summed.ravel()[at], kind="stable")[:candidates]]
    # a box sum is flat around a lone spike: each peak stands for the most frequent shift in its box
    centres = np.stack(np.unravel_index(at, tuple(shape)), axis=-1)
    near = np.stack(np.meshgrid(*[np.arange(-tolerance, tolerance + 1)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    boxes = (centres[:, None, :] + near[None]) % shape  # (K, box^3, 3)
    raw = np.where(far, counts, -1)[tuple(np.moveaxis(boxes, -1, 0))]
    return np.unique(boxes[np.arange(len(centres)), np.argmax(raw, axis=1)], axis=0)
