"""The sweep body that ICM and annealing share: visit the colour classes in a random order.

For each class (in an order drawn from the run's Generator): draw what the class needs from the
Generator (before any parallel loop, so the volume does not depend on the thread count), work
out the histogram penalty from the current label counts, update the class with the serial or
the parallel kernel (by class size), then count the visited and changed voxels and keep the
label counts up to date.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..._kernels.relax import PARALLEL_MIN_SITES

__all__ = ["DISTANCES", "GEMM_MIN_CLASS_SITES", "GEMM_MIN_DIMENSION", "histogram_penalty",
           "label_counts", "mean_class_sites", "resolve_distances", "sweep"]

#: How the class kernels get the neighbour distances ``D_p`` (docs/model.md, section 2): ``gemm``
#: computes a block of sites at once as one float32 matrix product plus rank-one terms
#: (:mod:`npmrf3d._kernels.gemm`); ``direct`` sums the squared differences site by site
#: (:func:`npmrf3d._kernels.parzen.neighbour_distances`); ``auto`` (the default) picks ``gemm``
#: when the patch dimension ``C (w^2 - 1)`` is at least :data:`GEMM_MIN_DIMENSION` and the
#: colour classes hold at least :data:`GEMM_MIN_CLASS_SITES` sites on average. Same model;
#: the two round differently (they agree to float32 rounding, tests/test_gemm.py).
DISTANCES = ("auto", "gemm", "direct")
#: Measured (benchmarks/bench_icm.py, the Figure-4 job, after the label stage was vectorised;
#: AMD EPYC, 2 cores): grey 7x7 (d = 48) at 64^3 (4,096 sites per class) takes 58 s of level 0
#: with gemm against 66 s direct; at 16^3 (64 sites per class, fewer than one block of
#: :data:`npmrf3d._kernels.gemm.BLOCK` sites) 19 s against 9 s. The distance stage alone
#: (bench_parzen_blas.py): grey 5x5 (d = 24) 0.65-0.81x, grey 11x11 (120) 1.3-1.85x, colour 7x7
#: (144) 1.5-1.9x, colour 11x11 (360) 2.3-4.7x.
GEMM_MIN_DIMENSION = 48
#: Average sites per colour class below which ``auto`` keeps the direct loop (half-empty blocks).
GEMM_MIN_CLASS_SITES = 512


def resolve_distances(distances: str, models, *, class_sites: float | None = None) -> str:
    """``gemm`` or ``direct`` for ``distances`` (one of :data:`DISTANCES`), these view models and
    ``class_sites`` sites per colour class on average (``None``: not known, large assumed)."""
    if distances not in DISTANCES:
        raise ValueError(f"distances must be one of {', '.join(DISTANCES)}; got {distances!r}")
    if distances != "auto":
        return distances
    large = class_sites is None or class_sites >= GEMM_MIN_CLASS_SITES
    return "gemm" if models.patches_t.shape[1] >= GEMM_MIN_DIMENSION and large else "direct"


def mean_class_sites(classes: list[np.ndarray]) -> float:
    """Average number of sites per colour class."""
    return sum(len(c) for c in classes) / max(len(classes), 1)

#: ``update(sites, drawn, penalty, parallel, old, new)``: update one class in place; ``old`` and
#: ``new`` receive each site's label before and after (``old = -2``: site not visited).
ClassUpdate = Callable[[np.ndarray, tuple, np.ndarray, bool, np.ndarray, np.ndarray], None]


def histogram_penalty(counts: np.ndarray, exemplar_freq: np.ndarray, weight: float) -> np.ndarray:
    """``-weight * max(0, log(q_k / e_k))`` with pseudo-counts, ``q`` the volume's label share.

    Labels the volume over-uses relative to the exemplar are penalised; others are untouched.
    """
    if weight == 0.0:
        return np.zeros(len(exemplar_freq))
    total = max(int(counts.sum()), 1)
    delta = 1.0 / total
    ratio = (counts / total + delta) / (exemplar_freq + delta)
    return -weight * np.maximum(0.0, np.log(ratio))


def label_counts(labels_volume: np.ndarray, n_labels: int) -> np.ndarray:
    """int64 count of every label in the volume (voxels without a label, -1, are left out)."""
    return np.bincount(labels_volume[labels_volume >= 0].ravel(), minlength=n_labels).astype(np.int64)


def sweep(classes: list[np.ndarray], rng: np.random.Generator, *, draw: Callable[[np.ndarray], tuple],
          update: ClassUpdate, counts: np.ndarray, exemplar_freq: np.ndarray,
          histogram_weight: float) -> tuple[int, int]:
    """One sweep over every class; returns (visited voxels, voxels whose label changed).

    ``counts`` (label counts of the volume) is updated in place when ``histogram_weight`` is
    not 0 (without the penalty nobody reads it).
    """
    penalty = np.zeros(len(exemplar_freq))
    visited_total = changed_total = 0
    for c in rng.permutation(len(classes)):
        sites = classes[c]
        drawn = draw(sites)
        if histogram_weight:  # counts change with every class; without the term it stays 0
            penalty = histogram_penalty(counts, exemplar_freq, histogram_weight)
        old = np.empty(len(sites), dtype=np.int64)
        new = np.empty(len(sites), dtype=np.int64)
        update(sites, drawn, penalty, len(sites) >= PARALLEL_MIN_SITES, old, new)
        visited = old != -2
        moved = visited & (old != new)
        visited_total += int(visited.sum())
        changed_total += int(moved.sum())
        if histogram_weight and moved.any():
            counts -= np.bincount(old[moved & (old >= 0)], minlength=len(counts))
            counts += np.bincount(new[moved & (new >= 0)], minlength=len(counts))
    return visited_total, changed_total
