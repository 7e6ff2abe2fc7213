"""Otsu's threshold (Otsu 1979): the split of a value histogram into two phases that maximises
the between-class variance. The phase histograms of the methods (:mod:`npmrf3d.model.phases`)
and the ground-truth statistics of scans (:mod:`npmrf3d.analysis.materials`) split by it; tested
against ``skimage.filters.threshold_otsu``."""

from __future__ import annotations

import numpy as np

from .. import _validation as check

__all__ = ["otsu_split", "otsu_threshold"]


def otsu_threshold(values, *, bins: int = 256) -> float:
    """Otsu's threshold: the bin edge maximising the between-class variance of a ``bins``-bin
    histogram (the centre of the bin below the split, as scikit-image returns it).

    >>> otsu_threshold(np.r_[np.zeros(50), np.ones(50)]) < 1
    True
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    counts, edges = np.histogram(v, bins=bins)
    centres = (edges[:-1] + edges[1:]) / 2
    return float(centres[otsu_split(counts)])


def otsu_split(counts) -> int:
    """Otsu's split of a histogram of evenly spaced bins: the last bin of the lower class (the
    bins ``<=`` it against those above), maximising the between-class variance.

    >>> otsu_split([5, 4, 0, 0, 1, 6])
    1
    """
    counts = np.asarray(counts, dtype=np.float64).ravel()
    if counts.size < 2:
        check.fail(f"Otsu's split needs at least two bins; got {counts.size}")
    centres = np.arange(counts.size, dtype=np.float64)
    w0 = np.cumsum(counts)[:-1]
    w1 = np.cumsum(counts[::-1])[::-1][1:]
    m0 = np.cumsum(counts * centres)[:-1] / np.maximum(w0, 1e-300)
    m1 = (np.cumsum((counts * centres)[::-1])[::-1][1:]) / np.maximum(w1, 1e-300)
    return int(np.argmax(w0 * w1 * (m0 - m1) ** 2))
