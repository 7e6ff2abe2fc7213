"""The minority phase's detached pieces: what the smoothness prior of a segmented exemplar reads.

One slice of a scan shows a phase's pieces but not how they connect through the third
dimension; a volume made from it keeps the phase's share and shape and loses its connections
(Berea from one slice: a sixth of the pore space in pieces apart from the pore network, against
a fortieth in the scan). :func:`attached_view` gives the smoothness prior
(:mod:`npmrf3d._kernels.smoothness`) the volume with those pieces seen as the majority phase, so
the prior draws the phase's voxels towards its largest piece and away from the detached ones;
the phase control then puts the phase's share back where the network can take it.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def minority_below(exemplars, lo: np.ndarray, span: np.ndarray) -> bool:
    """Whether the exemplars' minority phase lies below the middle of their value range (the
    grey level: the mean over channels)."""
    middle = float(np.mean(lo + span / 2.0))
    values = np.concatenate([np.asarray(e, dtype=np.float64).mean(axis=-1).ravel() for e in exemplars])
    return bool((values < middle).mean() <= 0.5)


def attached_view(volume: np.ndarray, lo: np.ndarray, span: np.ndarray, below: bool) -> np.ndarray:
    """``volume`` (N1, N2, N3, C) with every voxel of the minority phase outside its largest
    face-connected piece (toroidal, as the volume is) given the majority phase's extreme colour.
    The phase: grey level below the middle of the value range (``below``) or above it.

    >>> v = np.zeros((6, 6, 6, 1), dtype=np.float32); v[:, 0, 0] = 1; v[0, 3, 3] = 1
    >>> out = attached_view(v, np.zeros(1), np.ones(1), below=False)
    >>> float(out[:, 0, 0].sum()), float(out[0, 3, 3, 0])
    (6.0, 0.0)
    """
    middle = lo + span / 2.0
    grey = volume.mean(axis=-1)
    phase = grey < float(np.mean(middle)) if below else grey > float(np.mean(middle))
    labels, count = ndimage.label(phase)
    if count <= 1:
        return volume
    for axis in range(3):  # join the pieces that meet across the volume's faces
        first, last = np.take(labels, 0, axis=axis), np.take(labels, -1, axis=axis)
        both = (first > 0) & (last > 0)
        _join(labels, first[both], last[both])
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    detached = phase & (labels != np.argmax(sizes))
    out = volume.copy()
    out[detached] = (lo + span if below else lo).astype(volume.dtype)
    return out


def _join(labels: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """Relabel ``labels`` in place so that each pair ``a[i], b[i]`` has one label (the smaller of
    their groups')."""
    if a.size == 0:
        return
    parent = np.arange(labels.max() + 1)

    def root(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for x, y in set(zip(a.tolist(), b.tolist())):
        rx, ry = root(x), root(y)
        if rx != ry:
            parent[max(rx, ry)] = min(rx, ry)
    roots = np.array([root(x) for x in range(parent.size)])
    labels[...] = roots[labels]
