"""ICM with per-voxel temperatures (docs/model.md, section 4), in a parallel random scan.

One sweep visits the colour classes of :func:`npmrf3d.model.neighbourhood.colour_classes` in a random
order; the sites of a class never interact, so the compiled kernel updates them in parallel and
the sweep equals a sequential random scan. Every random number a class needs is drawn here,
before the parallel loop, from the run's Generator: the volume depends on the seed only, not on
the number of threads.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..._kernels._jit import single_threaded_blas
from ..._kernels.gemm import make_gemm_operands
from ..._kernels.parzen import LcpdfOptions
from ..._kernels.relax import IcmRule, LevelArrays, ViewModels, icm_update_class
from ._sweep import histogram_penalty, label_counts, mean_class_sites, resolve_distances, sweep

__all__ = ["IcmOptions", "expected_sweeps", "histogram_penalty", "relax_icm"]


@dataclass(frozen=True)
class IcmOptions:
    """Options of ICM with per-voxel temperatures (the one place their defaults are written).

    Attributes
    ----------
    xi : float < 0
        Cooling step.
    stop : float in (0, 1]
        Stop a level once the global temperature fell by this fraction (1: down to 0).
    max_sweeps : int >= 1
        Hard limit of sweeps per level.
    """

    xi: float = -3.0
    stop: float = 0.95
    max_sweeps: int = 30


#: How much faster than the mean-field rate ``|xi| / |N_s|`` a random scan cools (sites see
#: neighbours cooled earlier in the same sweep); measured on the bundled exemplars.
SCAN_SPEEDUP = 1.7


def expected_sweeps(history: list[float], *, n_voxels: int, xi: float, stop: float,
                    max_sweeps: int, n_union: int) -> int:
    """The sweeps the stop rule will need on one level, for progress bars.

    Before the first sweep (``history`` = [initial global temperature]) the mean temperature is
    assumed to fall by ``SCAN_SPEEDUP * |xi| / |N_s|`` per sweep (the cooling step spread over
    the 3D neighbourhood); after each sweep the estimate is corrected by extrapolating the last
    drops linearly. Always between the sweeps done (+1 while not stopped) and ``max_sweeps``.

    >>> expected_sweeps([1000.0], n_voxels=1000, xi=-3.0, stop=0.95, max_sweeps=30, n_union=60)
    12
    >>> expected_sweeps([1000.0, 800.0, 620.0], n_voxels=1000, xi=-3.0, stop=0.95, max_sweeps=30,
    ...                 n_union=60)
    5
    """
    initial, done = float(history[0]), len(history) - 1
    target = (1.0 - stop) * initial
    if initial <= 0 or history[-1] <= target:
        return max(done, 1) if done else 1
    if done == 0:
        drop = SCAN_SPEEDUP * abs(xi) / max(1, n_union) * n_voxels
    else:
        recent = [history[i - 1] - history[i] for i in range(max(1, done - 1), done + 1)]
        drop = sum(recent) / len(recent)
    if drop <= 0:
        return max_sweeps
    remaining = math.ceil((history[-1] - target) / drop - 1e-9)
    return int(min(max_sweeps, max(done + 1, done + remaining)))


def relax_icm(
    volume: np.ndarray, labels_volume: np.ndarray, temps: np.ndarray, inherited: np.ndarray,
    models: ViewModels, classes: list[np.ndarray], *, heuristic: int, decision: int, tau: float,
    xi: float, stop: float, max_sweeps: int, resynth: bool, adaptive: float, min_two_h2: float,
    prune: float, histogram_weight: float, outlier: float, exemplar_freq: np.ndarray, rng: np.random.Generator,
    on_sweep: Callable[[int, float], None] | None = None, distances: str = "auto",
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
    heuristic, decision : kernel codes (:mod:`npmrf3d.model.heuristics`)
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
    distances : one of :data:`npmrf3d.model.relax._sweep.DISTANCES` (how ``D_p`` is computed)

    Returns
    -------
    history : global temperature before the first sweep and after each sweep
    stats : ``sweeps``, ``updates`` (visited voxels), ``evaluations`` (voxel-view LCPDFs)
    """
    n_views = models.offsets.shape[0]
    initial = float(temps.sum(dtype=np.float64))
    history = [initial]
    target = (1.0 - stop) * initial
    counts = label_counts(labels_volume, len(exemplar_freq))
    updates = 0
    sweeps = 0

    distances = resolve_distances(distances, models, class_sites=mean_class_sites(classes))
    ops = (make_gemm_operands(models.patches_t, models.n_patches, models.labels.shape[1])
           if distances == "gemm" else None)

    level = LevelArrays(volume, labels_volume, temps, inherited)
    lcpdf = LcpdfOptions(float(adaptive), float(min_two_h2), float(prune), float(outlier))
    rule = IcmRule(int(heuristic), int(decision), float(tau), float(xi), bool(resynth),
                   np.zeros(0))

    def update(sites, drawn, penalty, parallel, old, new):
        kernel = icm_update_class.parallel if parallel else icm_update_class.serial
        kernel(level, sites, drawn[0], models, ops, lcpdf, rule._replace(penalty=penalty), old, new)

    with single_threaded_blas():
        while sweeps < max_sweeps and history[-1] > target:
            visited, _ = sweep(classes, rng, draw=lambda sites: (rng.random(len(sites)),),
                               update=update, counts=counts, exemplar_freq=exemplar_freq,
                               histogram_weight=histogram_weight)
            updates += visited
            sweeps += 1
            history.append(float(temps.sum(dtype=np.float64)))
            if on_sweep is not None:
                on_sweep(sweeps, history[-1])
    return history, {"sweeps": sweeps, "updates": updates, "evaluations": updates * n_views}
