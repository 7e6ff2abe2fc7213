"""How much of a copied volume repeats itself: the largest share of voxels whose exemplar
coordinate comes back at one far shift.

A method that copies exemplar voxels (``volume-lh``, ``npmrf-3d``) can lay whole blocks of the
exemplar side by side: the 128^3 volume is then the 64^3 exemplar repeated with its period,
which the phase fractions, surface area and two-point correlation of a crop do not see (they are
the exemplar's own). This statistic sees it: for every shift ``t`` (toroidal, ``max |t_i| >=
min_shift``) it counts the voxels ``p`` with ``S(p + t) == S(p)``, and reports the largest count
as a share of all voxels. A volume tiled by the exemplar scores near 1 at ``t`` = its period;
a volume that recombines the exemplar's parts scores near 0, since two far voxels copy the same
exemplar voxel by chance, each at its own shift.
"""

from __future__ import annotations

import numpy as np

from scipy import ndimage

from . import _validation as check

__all__ = ["copy_repetition"]

#: Half-width of the box of shifts summed: two copies of one exemplar block are seldom laid at
#: exactly one shift (the jitter of the finer levels moves each copy by a voxel or two).
TOLERANCE = 2

#: Voxels of one coordinate are paired with at most this many others (a volume that copies one
#: voxel this often has collapsed; its share is then a lower bound).
MAX_GROUP = 512

#: Shifts shorter than this (per axis, the largest component) are a patch's own coherence, not
#: repetition.
MIN_SHIFT = 16


def copy_repetition(coords: np.ndarray, *, min_shift: int = MIN_SHIFT, tolerance: int = TOLERANCE) -> dict:
    """The largest share of voxels whose exemplar coordinate recurs at one shift.

    Parameters
    ----------
    coords : ndarray, shape (N1, N2, N3, 3), int
        The exemplar coordinate each output voxel copies (toroidal output).
    min_shift : int
        Shifts ``t`` with ``max_i |t_i| < min_shift`` are ignored (16: a copied patch's own
        extent).
    tolerance : int
        The count at ``t`` sums the shifts within ``tolerance`` of it per axis (2: a box of
        5^3 shifts), so a copy moved by a voxel or two still counts as a repetition.

    Returns
    -------
    dict
        ``share``: the largest ``sum_d #{p : S(p + t + d) == S(p)} / N`` (``max |d_i| <=
        tolerance``) over the shifts counted — with ``tolerance=0`` the share of voxels
        repeated at ``t``; with a box it counts every match in it, and can exceed 1 where
        neighbouring voxels copy one coordinate (an up-sampling left uncorrected does) — and
        ``shift``: that ``t`` (components in ``[-N_i / 2, N_i / 2)``; ``None`` when no two voxels
        far apart copy the same voxel). Two voxels of one coordinate more than
        :data:`MAX_GROUP` places apart in raster order are not paired.

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
    shape = np.array(coords.shape[:3], dtype=np.int64)
    n = int(shape.prod())
    span = coords.reshape(-1, 3).astype(np.int64)
    span = span - span.min(axis=0)
    key = np.ravel_multi_index(tuple(span.T), tuple(span.max(axis=0) + 1))
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    pos = np.stack(np.unravel_index(order, tuple(shape)), axis=-1).astype(np.int32)
    del key, order
    counts = np.zeros(n, dtype=np.int64)
    group = np.diff(np.flatnonzero(np.diff(sorted_key, prepend=-1, append=-1)))
    reach = min(int(group.max()), MAX_GROUP)
    # pairs (i, i + d) of the sorted list share a coordinate when their keys are equal: every
    # pair of a group of m voxels comes once, at d = 1 .. m - 1, counted at its shift t here ...
    for d in range(1, reach):
        same = np.flatnonzero(sorted_key[d:] == sorted_key[:-d])
        if same.size == 0:
            break
        t = (pos[same + d] - pos[same]) % shape
        counts += np.bincount(np.ravel_multi_index(tuple(t.T), tuple(shape)), minlength=n)
    # ... and at -t: the second voxel of the pair sees the first there
    counts = counts.reshape(tuple(shape))
    counts += np.roll(np.flip(counts), 1, axis=(0, 1, 2))
    raw = counts.astype(np.float64)
    del counts
    box = 2 * tolerance + 1
    summed = ndimage.uniform_filter(raw, size=box, mode="wrap") * box ** 3 if tolerance else raw.copy()
    reach_of = np.meshgrid(*[np.minimum(np.arange(m), m - np.arange(m)) for m in shape], indexing="ij", sparse=True)
    summed[np.maximum(np.maximum(reach_of[0], reach_of[1]), reach_of[2]) < min_shift] = 0
    summed = np.rint(summed)
    if not summed.any():
        return {"share": 0.0, "shift": None}
    centre = np.array(np.unravel_index(int(np.argmax(summed)), tuple(shape)), dtype=np.int64)
    # the shift reported: the most frequent one in the winning box
    near = np.stack(np.meshgrid(*[np.arange(-tolerance, tolerance + 1)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    near = (centre + near) % shape
    t = near[int(np.argmax(raw[tuple(near.T)]))]
    t = np.where(t >= (shape + 1) // 2, t - shape, t)
    return {"share": float(summed[tuple(centre)]) / n, "shift": [int(x) for x in t]}
