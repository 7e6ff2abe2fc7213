"""ICM with per-voxel temperatures (SPEC.md section 4), in a parallel random scan.

One sweep visits the colour classes of :func:`npmrf3d.neighborhood.colour_classes` in a random
order; the sites of a class never interact, so the compiled kernel updates them in parallel and
the sweep equals a sequential random scan. Every random number a class needs is drawn here,
before the parallel loop, from the run's Generator: the volume depends on the seed only, not on
the number of threads.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from .._kernels.relax import (
    PARALLEL_MIN_SITES,
    ViewModels,
    icm_update_class,
    icm_update_class_serial,
)


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


def relax_icm(
    volume: np.ndarray, labels_volume: np.ndarray, temps: np.ndarray, inherited: np.ndarray,
    models: ViewModels, classes: list[np.ndarray], *, heuristic: int, decision: int, tau: float,
    xi: float, stop: float, max_sweeps: int, resynth: bool, adaptive: float, min_two_h2: float,
    prune: float, histogram_weight: float, outlier: float, exemplar_freq: np.ndarray, rng: np.random.Generator,
    on_sweep: Callable[[int, float], None] | None = None,
) -> tuple[list[float], dict]:
    """Relax one level in place.

    Parameters
    ----------
    volume : (N1, N2, N3, C) float32, updated in place
    labels_volume : (N1, N2, N3) int32 label index of each voxel (-1: not a label)
    temps : (N1, N2, N3) float32 voxel temperatures, updated in place
    inherited : (N1, N2, N3) bool, voxels inherited from the coarser level
    models : ViewModels of this level
    classes : list of (S, 3) int64 site arrays (non-interacting colour classes)
    heuristic, decision : kernel codes (:mod:`npmrf3d.heuristics`)
    tau : temperature of the ``sample`` decision
    xi : cooling step (< 0)
    stop : stop once the global temperature fell by this fraction of its initial value
        (1.0: run until every voxel is at 0)
    max_sweeps : hard limit on sweeps
    resynth : inherited voxels are revisited (their temperature stays 0)
    adaptive, min_two_h2, prune : bandwidth options of the kernel
    histogram_weight : weight of the histogram penalty (0: off)
    outlier : weight of the uniform term in each view's LCPDF (0: off)
    exemplar_freq : (K,) label frequencies of the exemplar(s)
    rng : Generator for the class order and the decisions
    on_sweep : called as ``on_sweep(sweep, global_temperature)`` after each sweep

    Returns
    -------
    history : global temperature before the first sweep and after each sweep
    stats : ``sweeps``, ``updates`` (visited voxels), ``evaluations`` (voxel-view LCPDFs)
    """
    n_views = models.offsets.shape[0]
    initial = float(temps.sum(dtype=np.float64))
    history = [initial]
    target = (1.0 - stop) * initial
    counts = np.bincount(labels_volume[labels_volume >= 0].ravel(), minlength=len(exemplar_freq))
    counts = counts.astype(np.int64)
    penalty = np.zeros(len(exemplar_freq))
    updates = 0
    sweeps = 0
    while sweeps < max_sweeps and history[-1] > target:
        for c in rng.permutation(len(classes)):
            sites = classes[c]
            uniforms = rng.random(len(sites))
            if histogram_weight:  # counts change with every class; without the term it stays 0
                penalty = histogram_penalty(counts, exemplar_freq, histogram_weight)
            old = np.empty(len(sites), dtype=np.int64)
            new = np.empty(len(sites), dtype=np.int64)
            parallel = len(sites) >= PARALLEL_MIN_SITES
            update = icm_update_class if parallel else icm_update_class_serial
            update(volume, labels_volume, temps, inherited, sites, uniforms, models, heuristic,
                   decision, tau, xi, resynth, adaptive, min_two_h2, prune, penalty, outlier,
                   old, new)
            visited = old != -2
            updates += int(visited.sum())
            if histogram_weight:
                counts -= np.bincount(old[visited & (old >= 0)], minlength=len(counts))
                counts += np.bincount(new[visited & (new >= 0)], minlength=len(counts))
        sweeps += 1
        history.append(float(temps.sum(dtype=np.float64)))
        if on_sweep is not None:
            on_sweep(sweeps, history[-1])
    return history, {"sweeps": sweeps, "updates": updates, "evaluations": updates * n_views}
