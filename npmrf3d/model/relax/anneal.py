"""Simulated annealing with one global temperature per level (docs/model.md, section 5).

A level runs ``proposals`` sweeps; sweep ``s`` uses the temperature ``T_s`` of a schedule
from :data:`SCHEDULES` that falls from ``t0`` to ``t_end``. Every sweep gives every voxel one
update, class by class (the colour classes of :func:`npmrf3d.model.neighbourhood.colour_classes`, in
random order, each class updated in parallel: equivalent to a sequential random scan).

Two samplers (:data:`SAMPLERS`):

``metropolis`` (the paper)
    A proposal draws a new label for the site — from the exemplar's values (a label drawn with
    the exemplar's label frequencies, ``proposal="exemplar"``, the paper) or uniformly from the
    label set (``proposal="labels"``) — and is accepted if it raises the heuristic's objective
    ``log F`` (ML_H2a: min over views, normalised LCPDFs; ML_H2b: sum, where normalisers cancel),
    otherwise with probability ``exp((log F_new - log F_old) / T)``. With exemplar proposals
    this plain Metropolis rule (no Hastings correction) samples ``F**(1/T) * q`` with ``q`` the
    exemplar's label frequencies at a fixed temperature: a histogram prior that the paper's
    rule implies; with ``labels`` proposals it samples ``F**(1/T)``.
``heat-bath`` (this project's addition, not the paper's)
    The neighbourhood weights are computed once per site anyway; the new label is drawn directly
    from ``exp(log F / T) / Z`` over the whole label set (a Gibbs step at temperature ``T``).
    One heat-bath update does what many Metropolis proposals at the same site would.

All random numbers of a class are drawn here before the parallel loop, so the volume depends on
the seed only, not on the number of threads.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..._kernels._jit import single_threaded_blas
from ..._kernels.gemm import make_gemm_operands
from ..._kernels.parzen import LcpdfOptions
from ..._kernels.relax import AnnealRule, LevelArrays, ViewModels, anneal_update_class
from ._sweep import label_counts, mean_class_sites, resolve_distances, sweep

__all__ = ["AnnealOptions", "SAMPLERS", "SCHEDULES", "PROPOSALS", "geometric_schedule",
           "linear_schedule", "relax_anneal"]


def geometric_schedule(t0: float, t_end: float, steps: int) -> np.ndarray:
    """``T_s = t0 * (t_end / t0) ** (s / (steps - 1))`` for ``s = 0 .. steps - 1``.

    Examples
    --------
    >>> geometric_schedule(1.0, 0.01, 3).round(6).tolist()
    [1.0, 0.1, 0.01]
    """
    if steps == 1:
        return np.array([float(t_end)])
    return float(t0) * (float(t_end) / float(t0)) ** (np.arange(steps) / (steps - 1))


def linear_schedule(t0: float, t_end: float, steps: int) -> np.ndarray:
    """``T_s`` evenly spaced from ``t0`` to ``t_end`` (``steps`` values).

    Examples
    --------
    >>> linear_schedule(1.0, 0.0, 3).tolist()
    [1.0, 0.5, 0.0]
    """
    if steps == 1:
        return np.array([float(t_end)])
    return np.linspace(float(t0), float(t_end), steps)


#: Temperature schedules by name: ``f(t0, t_end, steps) -> (steps,) temperatures``.
SCHEDULES: dict[str, Callable[[float, float, int], np.ndarray]] = {
    "geometric": geometric_schedule,
    "linear": linear_schedule,
}
#: Samplers by name.
SAMPLERS = ("metropolis", "heat-bath")
#: Where Metropolis proposals come from.
PROPOSALS = ("exemplar", "labels")


@dataclass(frozen=True)
class AnnealOptions:
    """Options of simulated annealing (the one place their defaults are written).

    Attributes
    ----------
    sampler : name in :data:`SAMPLERS`
    schedule : name in :data:`SCHEDULES`
    t0, t_end : float
        First and last temperature of each level.
    proposals : int >= 1
        Proposals (sweeps) per voxel per level.
    proposal : name in :data:`PROPOSALS`
    """

    sampler: str = "heat-bath"
    schedule: str = "geometric"
    t0: float = 1.0
    t_end: float = 0.05
    proposals: int = 10
    proposal: str = "exemplar"


def relax_anneal(
    volume: np.ndarray, labels_volume: np.ndarray, temps: np.ndarray, inherited: np.ndarray,
    models: ViewModels, classes: list[np.ndarray], *, heuristic: int, sampler: str,
    schedule: str, t0: float, t_end: float, proposals: int, proposal: str, resynth: bool,
    adaptive: float, min_two_h2: float, prune: float, histogram_weight: float, outlier: float,
    exemplar_freq: np.ndarray, rng: np.random.Generator,
    on_sweep: Callable[[int, float], None] | None = None, distances: str = "auto",
) -> tuple[list[float], dict]:
    """Anneal one level in place.

    Parameters
    ----------
    volume, labels_volume, inherited, models, classes :
        As for :func:`npmrf3d.model.relax.icm.relax_icm`; every voxel must hold a label (>= 0).
    temps : (N1, N2, N3) float32
        Set to 0 here: annealing has no voxel temperatures, every neighbour is trusted.
    heuristic : kernel code of ML_H2a or ML_H2b (the heuristics with an objective)
    sampler : {"metropolis", "heat-bath"}
    schedule : name in :data:`SCHEDULES`
    t0, t_end : first and last temperature of the schedule
    proposals : sweeps (proposals per voxel) in this level
    proposal : {"exemplar", "labels"}, where Metropolis candidates come from
    resynth : inherited voxels may change (else they stay fixed)
    adaptive, min_two_h2, prune, histogram_weight, outlier, exemplar_freq :
        As for :func:`npmrf3d.model.relax.icm.relax_icm`.
    rng : Generator for the class order, the candidates and the uniforms
    on_sweep : called as ``on_sweep(sweep, temperature)`` after each sweep
    distances : one of :data:`npmrf3d.model.relax._sweep.DISTANCES` (how ``D_p`` is computed)

    Returns
    -------
    history : the temperature of each sweep, preceded by ``t0``
    stats : ``sweeps``, ``updates`` (voxel updates), ``evaluations`` (voxel-view LCPDFs),
        ``changed`` (updates that changed the label), ``acceptance`` (share of changes per sweep)
    """
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}; got {sampler!r}")
    temps[...] = 0.0
    n_views = models.offsets.shape[0]
    n_labels = len(exemplar_freq)
    temperatures = SCHEDULES[schedule](t0, t_end, proposals)
    cumulative = np.cumsum(exemplar_freq)
    cumulative /= cumulative[-1]
    counts = label_counts(labels_volume, n_labels)
    history = [float(temperatures[0])]
    acceptance: list[float] = []
    updates = changed = 0

    def draw(sites):
        if proposal == "exemplar":
            candidates = np.searchsorted(cumulative, rng.random(len(sites)), side="right")
            candidates = np.minimum(candidates, n_labels - 1).astype(np.int64)
        else:
            candidates = rng.integers(0, n_labels, size=len(sites), dtype=np.int64)
        return candidates, rng.random(len(sites))

    distances = resolve_distances(distances, models, class_sites=mean_class_sites(classes))
    ops = (make_gemm_operands(models.patches_t, models.n_patches, models.labels.shape[1])
           if distances == "gemm" else None)

    level = LevelArrays(volume, labels_volume, temps, inherited)
    lcpdf = LcpdfOptions(float(adaptive), float(min_two_h2), float(prune), float(outlier))

    def update(sites, drawn, penalty, parallel, old, new, temperature):
        kernel = anneal_update_class.parallel if parallel else anneal_update_class.serial
        candidates = drawn[0] if sampler == "metropolis" else None  # heat-bath: no proposals
        rule = AnnealRule(int(heuristic), temperature, bool(resynth), penalty)
        kernel(level, sites, candidates, drawn[1], models, ops, lcpdf, rule, old, new)

    with single_threaded_blas():
        for step, temperature in enumerate(temperatures, start=1):
            sweep_updates, sweep_changed = sweep(
                classes, rng, draw=draw, counts=counts, exemplar_freq=exemplar_freq,
                histogram_weight=histogram_weight,
                update=lambda *a, t=float(temperature): update(*a, t))
            updates += sweep_updates
            changed += sweep_changed
            acceptance.append(sweep_changed / max(sweep_updates, 1))
            history.append(float(temperature))
            if on_sweep is not None:
                on_sweep(step, float(temperature))
    return history, {"sweeps": int(proposals), "updates": updates, "evaluations": updates * n_views,
                     "changed": changed, "acceptance": acceptance}
