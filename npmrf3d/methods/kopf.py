"""NP_K: solid texture synthesis by texture optimisation with histogram matching.

This module is the method's documentation (the paper's equations and every choice where the
paper is silent), configuration, validation and registry entry. The steps are in
:mod:`npmrf3d.model`: the search (:mod:`~npmrf3d.model.kopf_search`), the optimisation
(:mod:`~npmrf3d.model.kopf_optimise`), the voxel constraints
(:mod:`~npmrf3d.model.kopf_constraints`) and the level loop's side
(:mod:`~npmrf3d.model.kopf_levels`).

The baseline the NP-MRF paper compares with (Kopf et al. 2007, "Solid texture synthesis from
2D exemplars"; docs/kopf.md). The volume minimises

    E = sum_v sum_{i in views} ||s_{v,i} - e_{v,i}||^r,        r = 0.8,

over the ``window x window`` neighbourhoods ``s_{v,i}`` of the axis-orthogonal slices through
the voxels of a sparse grid, ``e_{v,i}`` being the closest exemplar neighbourhood. Each
iteration alternates

* **search**: every neighbourhood on the sparse grid (every ``grid``-th position along both
  plane axes, every slice) is projected on the exemplar's principal components that keep
  ``variance`` of the variance and matched with ``scipy.spatial.cKDTree.query(eps=eps)``
  (approximate nearest neighbour within a factor ``1 + eps`` of the exact distance);
* **optimisation** (IRLS): each voxel becomes the weighted average of the exemplar texels that
  the overlapping neighbourhoods assign to it (paper eq. 4), with weights
  ``omega = ||s - e||^(r - 2)`` divided by ``1 + histogram_weight * sum_c max(0, H_s,c(b) -
  H_e,c(b))`` (paper eq. 5; ``H`` are per-channel histograms with ``histogram_bins`` bins,
  in voxel counts, kept up to date while voxels change in a random order) and, for voxel
  constraints, by ``1 + tau_v ||e - t_v||`` (paper eq. 6). Optionally only the dominant
  mean-shift cluster of the texels is averaged, with a bandwidth that shrinks over the
  iterations of a level (less blur).

Levels run coarse to fine; a level's volume initialises the next finer one by trilinear
up-sampling (the paper) or by the project's ``8/8`` / ``1/8`` pyramid (:mod:`npmrf3d.model.pyramid`).

Choices where the paper is silent (also in ``docs/kopf.md``)
-------------------------------------------------------------
* Neighbourhood geometry: the views and axes of :mod:`npmrf3d.model.neighbourhood` (front = plane
  ``(i, j)`` -> exemplar (row, column), right = ``(j, k)``, top = ``(i, k)``). A window is
  anchored at its top-left sparse-grid site ``u`` and covers ``u .. u + window - 1`` along both
  plane axes (toroidal volume), so even sizes such as the paper's 8x8 have no centre problem.
  Exemplar neighbourhoods are the windows that lie fully inside the exemplar.
* Coarse levels: the exemplar is box-averaged over ``2^l x 2^l`` blocks (the mean of its
  decimation phases); the volume of level ``l`` has ``size / 2^l`` voxels per side.
* Histograms: bins span each channel's range over all (full-resolution) exemplars; the target is
  the mean of the views' exemplar histograms at the current level, scaled to the volume's voxel
  count. ``H`` are bin *counts* (the paper's "value of bin b"), so ``histogram_weight = 1`` is
  the paper's formula; with fractions (``histogram_weight = 1 / N``) the re-weighting is too
  weak to counter the averaging's narrowing of the histogram (measured, ``docs/kopf.md``).
* IRLS weights use the exact (full-dimensional) distance of the chosen exemplar neighbourhood,
  floored at ``1e-3 * sigma * sqrt(d)`` (``sigma`` the exemplar standard deviation) so an exact
  match does not get an infinite weight.
* Mean-shift: Gaussian kernel; modes are sought from the heaviest contributors and from their
  weighted mean, the densest mode wins, and the texels within one bandwidth of it are averaged.
  Clusters are formed with the IRLS weights; the histogram and constraint re-weighting applies to
  the members (it must run in the sequential random-order pass).
* Determinism: voxel orders are drawn from ``rng`` before any parallel loop; KD-tree queries and
  the parallel gather are per-query/per-voxel, and the order-dependent pass is sequential, so the
  volume depends on the seed only, not on the thread count.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass

import numpy as np

from .. import _validation as check
from .._kernels import _jit
from ..config import DEFAULT_SIZE, SynthesisMethod, SynthesisResult
from ..model.kopf_constraints import constraint_arrays
from ..model.kopf_levels import KopfLevels
from ..model.neighbourhood import VIEWS
from ..model.pyramid import run_pyramid
from ..options import option, refusing
from ..resources import kopf_estimate
from ._api import prepare

__all__ = ["METHOD", "KopfConfig", "UPSAMPLING", "kopf_synthesize", "make_kopf_config", "run"]

#: Up-sampling between levels: the paper's trilinear interpolation, or the project's pyramid
#: (names of :data:`npmrf3d.model.pyramid.UPSAMPLERS`, the paper's first).
UPSAMPLING = ("trilinear", "8/8", "1/8")
#: Default mean-shift bandwidths (start, end) of each level, as multiples of the exemplar's
#: standard deviation (pooled over channels).
DEFAULT_MEAN_SHIFT = (1.0, 0.25)
#: Default strength of the histogram re-weighting (1 = the paper's formula with bin counts).
DEFAULT_HISTOGRAM_WEIGHT = 1.0
#: Default search + optimisation iterations of every level.
DEFAULT_ITERATIONS = 5

ProgressCallback = Callable[[int, int, int, float], None]


@dataclass(frozen=True)
class KopfConfig:
    """A validated NP_K run (see :func:`kopf_synthesize` for the meaning of each field)."""

    size: tuple[int, int, int] = option(help="output size", kind="own")
    window: int = option(8, "side of the square 2D neighbourhoods (the paper: 8)", kind="int", low=2, high=64,
                         metavar="W", group="volume and pyramid")
    levels: int = option(3, "resolution levels, coarse to fine (the paper: 3)", kind="int", low=1, high=8,
                         metavar="L", group="volume and pyramid")
    views: tuple[str, ...] = option(VIEWS, "views in the energy", kind="own")
    iterations: tuple[int, ...] = option((DEFAULT_ITERATIONS,) * 3, "search + optimisation iterations per "
                                         "level: one number, or one per level (coarsest first)",
                                         kind="levels", low=1, group="volume and pyramid")
    r: float = option(0.8, "exponent of the robust energy ||s - e||^r", kind="real", low=0.0, high=2.0,
                      low_open=True, metavar="R", group="energy and search")
    eps: float = option(2.0, "error bound of the approximate nearest-neighbour search (0 = exact in the "
                        "PCA space)", kind="real", low=0.0, metavar="E", group="energy and search")
    variance: float = option(0.95, "share of the neighbourhood variance the PCA keeps", kind="real", low=0.0,
                             high=1.0, low_open=True, metavar="F", group="energy and search")
    grid: int = option(2, "spacing of the sparse grid of searched neighbourhoods (1 = all)", kind="int",
                       low=1, metavar="M", group="energy and search")
    histogram_bins: int = option(16, "bins of each channel's histogram", kind="int", low=2, high=4096,
                                 metavar="B", group="energy and search",
                                 applies=lambda config: config.histogram_weight > 0,
                                 needs="histogram_weight is above 0")
    histogram_weight: float = option(DEFAULT_HISTOGRAM_WEIGHT, "strength of the histogram re-weighting (0 = "
                                     "off, 1 = the paper's formula)", kind="real", low=0.0, metavar="W",
                                     group="energy and search")
    mean_shift: tuple[float, float] | None = option(
        DEFAULT_MEAN_SHIFT, "mean-shift bandwidths at the start and end of each level, multiples of the "
        "exemplar's standard deviation; one number: fixed; 'none': the weighted average", kind="own")
    upsample: str = option("trilinear", "a finer level starts by trilinear interpolation (the paper) or "
                           "the pyramid's 8/8 or 1/8", kind="choice", choices=UPSAMPLING,
                           group="volume and pyramid")
    constrained: bool = option(False, "voxel constraints given", kind="own")
    seed: int | None = option(None, "random seed", kind="own")

    def to_dict(self) -> dict:
        """Plain JSON-able dictionary."""
        return asdict(self)


# --------------------------------------------------------------------------- validation


def make_kopf_config(
    *, size=DEFAULT_SIZE, window=KopfConfig.window, levels=KopfConfig.levels, views=KopfConfig.views,
    iterations=DEFAULT_ITERATIONS, r=KopfConfig.r, eps=KopfConfig.eps, variance=KopfConfig.variance,
    grid=KopfConfig.grid, histogram_bins=KopfConfig.histogram_bins,
    histogram_weight=KopfConfig.histogram_weight, mean_shift=KopfConfig.mean_shift,
    upsample=KopfConfig.upsample, constrained=False, seed=None,
) -> KopfConfig:
    """Validate plain keyword arguments into a frozen :class:`KopfConfig`."""
    levels = check.integer("levels", levels, low=1, high=8)
    window = check.integer("window", window, low=2, high=64)
    dims = check.size(size, levels=levels, window=1)
    f = 2 ** (levels - 1)
    grid = check.integer("grid", grid, low=1, high=window)
    for n in dims:
        if (n // f) % grid:
            check.fail(f"size {n} does not suit grid {grid} with {levels} levels: every level's size "
                       f"must be a multiple of grid, the coarsest is {n // f}; choose a multiple of "
                       f"{f * grid}")
        if n // f < window:
            check.fail(f"size {n} is too small for window {window} with {levels} levels: the "
                       f"coarsest level has {n // f} voxels per side, needs at least {window}; "
                       f"use a larger size, a smaller window or fewer levels")
    iterations = check.per_level("iterations", iterations, levels, low=1)
    r = check.real("r", r, low=0.0, high=2.0, low_open=True)
    eps = check.real("eps", eps, low=0.0)
    variance = check.real("variance", variance, low=0.0, high=1.0, low_open=True)
    histogram_bins = check.integer("histogram_bins", histogram_bins, low=2, high=4096)
    histogram_weight = check.real("histogram_weight", histogram_weight, low=0.0)
    if mean_shift is not None:
        if isinstance(mean_shift, (int, float, np.integer, np.floating)) and not isinstance(mean_shift, bool):
            mean_shift = (mean_shift, mean_shift)
        try:
            pair = tuple(mean_shift)
        except TypeError:
            check.fail(f"mean_shift must be None, a bandwidth or a pair (start, end); got {mean_shift!r}")
        if len(pair) != 2:
            check.fail(f"mean_shift must be None, a bandwidth or a pair (start, end); got {mean_shift!r}")
        mean_shift = tuple(check.real("mean_shift", h, low=0.0, low_open=True) for h in pair)
    upsample = check.choice("upsample", upsample, UPSAMPLING)
    views = check.views(views, VIEWS)
    if seed is not None:
        seed = check.integer("seed", seed, low=0)
    return KopfConfig(size=dims, window=window, levels=levels, views=views, iterations=iterations,
                      r=r, eps=eps, variance=variance, grid=grid, histogram_bins=histogram_bins,
                      histogram_weight=histogram_weight, mean_shift=mean_shift, upsample=upsample,
                      constrained=bool(constrained), seed=seed)


# --------------------------------------------------------------------------- public


def kopf_synthesize(exemplar=None, *, size=DEFAULT_SIZE, rng=None, progress: ProgressCallback | None = None,
                   checkpoint=None, exemplars: Mapping | None = None, constraint=None,
                   constraint_weight=None, **options) -> SynthesisResult:
    """Synthesize a solid texture with NP_K (Kopf et al. 2007; docs/kopf.md).

    Parameters
    ----------
    exemplar : path, (H, W) or (H, W, C) array, or None
        The 2D sample (None: the bundled default). Used for every view without an entry in
        ``exemplars``.
    size : int or (N1, N2, N3)
        Output size, divisible by ``2**(levels - 1)``; the coarsest level needs at least
        ``window`` voxels per side.
    window : int >= 2
        Side of the square 2D neighbourhoods (the paper: 8). Even sizes are fine (windows are
        anchored at their top-left site).
    levels : int
        Resolution levels, coarse to fine (the paper: 3). The window must fit the exemplar
        box-averaged ``2**(levels - 1)`` times.
    views : sequence of {"front", "right", "top"} (or a comma-separated string)
        Views whose neighbourhoods enter the energy (2 or 3 in the paper; 1 is allowed). Axis
        mapping as in :mod:`npmrf3d.model.neighbourhood`.
    exemplars : dict view -> exemplar, optional
        A different exemplar for some views (the paper's section 6.2).
    iterations : int or sequence of int
        Search + optimisation iterations per level (one number for all levels, or one per
        level, coarsest first).
    r : float in (0, 2]
        Exponent of the robust energy (IRLS weights ``||s - e||^(r - 2)``; 2 = least squares).
    eps : float >= 0
        Error bound of the approximate nearest-neighbour search (``cKDTree.query(eps=...)``);
        0 = exact search in the PCA space.
    variance : float in (0, 1]
        Fraction of the exemplar neighbourhoods' variance kept by the PCA projection.
    grid : int >= 1
        Spacing ``m`` of the sparse grid of searched neighbourhoods (1 = every voxel).
    histogram_bins : int >= 2
        Bins of each channel's histogram.
    histogram_weight : float >= 0
        Strength of the histogram re-weighting: weights are divided by
        ``1 + histogram_weight * sum_c max(0, H_s,c(b) - H_e,c(b))`` with histograms in voxel
        counts (the exemplar's scaled to the volume size); 0 = off, 1 = the paper's formula.
    mean_shift : None, float or (float, float)
        Mean-shift bandwidths (start, end) of each level as multiples of the exemplar's
        standard deviation; the bandwidth shrinks geometrically over the iterations of a level.
        None = plain weighted average (paper eq. 4).
    upsample : {"trilinear", "8/8", "1/8"}
        Initialisation of a finer level: trilinear interpolation (the paper), or the project's
        pyramid (:mod:`npmrf3d.model.pyramid`): copy the parent into all 8 children, or only into the
        child at the parent's position with random exemplar texels elsewhere.
    constraint : (N1, N2, N3, C) array, optional
        Target colours ``t_v`` of voxel constraints (the paper's section 6.2, eq. 6).
    constraint_weight : float or (N1, N2, N3) array, optional
        Constraint weights ``tau_v >= 0`` (0 = unconstrained voxel; default 1 everywhere when a
        constraint is given). Coarse levels use block averages of targets and weights.
    rng : None, int or numpy Generator
        Seed; the result depends on it only (not on the number of threads).
    progress : callable, optional
        Called as ``progress(level, iteration, iterations, energy)`` before the first iteration
        of each level (``iteration = 0``, energy nan) and after every iteration (energy = mean
        ``||s - e||^r`` of that iteration's search).
    checkpoint : path, optional
        A ``.npz`` file written after each level; if it exists and holds a checkpoint of the
        same configuration and exemplars, synthesis resumes after its last finished level.

    Returns
    -------
    SynthesisResult
        ``volume`` (N1, N2, N3, C) float32; ``history`` the mean energy of each iteration's
        search, one list per level (coarsest first); ``config`` a :class:`KopfConfig`;
        ``timings`` seconds (``setup``, ``level_<l>``, ``total``); ``labels`` an empty
        ``(0, C)`` array (NP_K works with continuous values, not a label set); ``stats`` per
        level: shape, iterations, queries, PCA dimensions and exemplar neighbourhoods per view,
        search and optimisation seconds, and the thread count.

    Examples
    --------
    >>> import numpy as np
    >>> stripes = np.tile(np.array([0, 0, 1, 1], dtype=np.uint8) * 255, (16, 4))
    >>> res = kopf_synthesize(stripes, size=8, window=4, levels=1, views="front", iterations=2, rng=0)
    >>> res.volume.shape
    (8, 8, 8, 1)
    """
    t_start = time.perf_counter()
    config, generator, per_view = prepare(METHOD, exemplar, exemplars, size=size, rng=rng,
                                          progress=progress, checkpoint=checkpoint,
                                          options={**options, "constrained": constraint is not None})
    return run(per_view, config, generator, constraint=constraint, constraint_weight=constraint_weight,
               progress=progress, checkpoint=checkpoint, t_start=t_start)


def run(per_view: Mapping[str, np.ndarray], config: KopfConfig, rng: np.random.Generator, *,
        progress: ProgressCallback | None = None, checkpoint=None, constraint=None,
        constraint_weight=None, t_start: float | None = None) -> SynthesisResult:
    """Run a validated configuration on validated exemplars (the body of :func:`kopf_synthesize`
    and the registered method, :data:`npmrf3d.methods.METHODS`); ``constraint`` and
    ``constraint_weight`` are raw arrays, validated here.

    ``checkpoint``: a ``.npz`` file written after each level, resumed from when it matches (as
    for :func:`npmrf3d.synthesize`).
    """
    t_start = time.perf_counter() if t_start is None else t_start
    channels = next(iter(per_view.values())).shape[2]
    target, tau = constraint_arrays(constraint, constraint_weight, config.size, channels)
    levels = KopfLevels(config, per_view, target, tau)
    out = run_pyramid(levels, rng, progress=progress, checkpoint=checkpoint,
                      timings={"setup": time.perf_counter() - t_start},
                      stats={"threads": _jit.thread_count()}, t_start=t_start)
    return SynthesisResult(volume=out.state, history=out.history, config=config,
                           timings=out.timings, labels=np.zeros((0, levels.channels), dtype=np.float32),
                           stats=out.stats)


#: The registry entry of NP_K.
METHOD = SynthesisMethod(
    name="kopf", run=run, make_config=refusing(make_kopf_config, KopfConfig), config_class=KopfConfig,
    synthesize=kopf_synthesize,
    fit=lambda c: {"window": c.window, "levels": c.levels, "toroidal": False},
    resources=kopf_estimate,
    description="NP_K, texture optimisation with histogram matching (Kopf et al. 2007)",
)
