"""Views, windows and the interaction colouring (docs/model.md, sections 1 and 6).

Axis mapping (fixed, used everywhere, and what makes anisotropic exemplars come out the right
way round): a volume is indexed ``volume[i, j, k]``; each view is a plane whose two axes map to
the exemplar's (row, column):

======  ===========  =======================  =====================
view    plane        exemplar row <- axis      exemplar column <- axis
======  ===========  =======================  =====================
front   (i, j), k    i (0)                     j (1)
right   (j, k), i    j (1)                     k (2)
top     (i, k), j    i (0)                     k (2)
======  ===========  =======================  =====================

So ``volume[:, :, k]`` is a front slice, ``volume[i]`` a right slice and ``volume[:, j]`` a top
slice, each shown as an image with the same orientation as the exemplar.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "VIEW_AXES",
    "VIEWS",
    "axis_colours",
    "colour_classes",
    "union_offsets",
    "view_offsets",
    "window_offsets",
]

VIEWS: tuple[str, ...] = ("front", "right", "top")
VIEW_AXES: dict[str, tuple[int, int]] = {"front": (0, 1), "right": (1, 2), "top": (0, 2)}


def window_offsets(window: int) -> np.ndarray:
    """Offsets ``(d_row, d_col)`` of a ``window x window`` square minus its centre.

    Returns
    -------
    (window**2 - 1, 2) int64 ndarray, row-major order.

    Examples
    --------
    >>> window_offsets(3).tolist()[:4]
    [[-1, -1], [-1, 0], [-1, 1], [0, -1]]
    """
    r = window // 2
    grid = [(a, b) for a in range(-r, r + 1) for b in range(-r, r + 1) if (a, b) != (0, 0)]
    return np.array(grid, dtype=np.int64)


def view_offsets(view: str, window: int) -> np.ndarray:
    """The 3D volume offsets of one view's window, in the order of :func:`window_offsets`.

    Returns
    -------
    (window**2 - 1, 3) int64 ndarray
    """
    plane = window_offsets(window)
    out = np.zeros((plane.shape[0], 3), dtype=np.int64)
    row_axis, col_axis = VIEW_AXES[view]
    out[:, row_axis] = plane[:, 0]
    out[:, col_axis] = plane[:, 1]
    return out


def union_offsets(views: tuple[str, ...], window: int) -> np.ndarray:
    """The 3D neighbourhood ``N_s``: distinct offsets of the union of the views' windows."""
    stacked = np.concatenate([view_offsets(v, window) for v in views])
    return np.unique(stacked, axis=0)


def axis_colours(n: int, period: int) -> np.ndarray:
    """Colour of each position of a ring of length ``n`` such that equal colours are more than
    ``period - 1`` apart on the ring (torus distance).

    Positions in the largest multiple of ``period`` get ``position % period``; the ``n % period``
    positions left over (they would touch block 0 across the wrap) get colours of their own.
    """
    rest = n % period
    full = n - rest
    colours = np.empty(n, dtype=np.int64)
    colours[:full] = np.arange(full) % period
    colours[full:] = period + np.arange(rest)
    return colours


def colour_classes(shape: tuple[int, int, int], window: int) -> list[np.ndarray]:
    """Partition the volume's sites into classes whose members never interact.

    Two sites interact if one lies in the other's 3D neighbourhood (any view's window). With
    ``r = window // 2`` and period ``r + 1`` per axis (:func:`axis_colours`), two distinct sites
    of one class are at least ``r + 1`` apart on the torus along some axis, so neither lies in
    the other's window: updating a class in parallel equals updating its sites one by one
    (docs/model.md, section 6).

    Returns
    -------
    list of (S, 3) int64 ndarrays, site coordinates of each class, classes in a fixed order.
    """
    period = window // 2 + 1
    cols = [axis_colours(n, period) for n in shape]
    counts = [int(c.max()) + 1 for c in cols]
    code = (cols[0][:, None, None] * counts[1] + cols[1][None, :, None]) * counts[2] + cols[2][None, None, :]
    flat = code.ravel()
    order = np.argsort(flat, kind="stable")
    boundaries = np.flatnonzero(np.diff(flat[order])) + 1
    coords = np.stack(np.unravel_index(order, shape), axis=1).astype(np.int64)
    return [np.ascontiguousarray(c) for c in np.split(coords, boundaries)]
