"""Chen & Wang 2010: k-coherence search, discrete solver, position and index histograms.

"High quality solid texture synthesis using position and index histogram matching" (The Visual
Computer 26(4), 2010). Like NP_K (:mod:`npmrf3d.methods.kopf`) the volume minimises

    E = sum_v sum_{i in views} ||s_{v,i} - e_{v,i}||^r,        r = 0.8,

over the 2D neighbourhoods of the axis-orthogonal slices, coarse to fine, alternating a search
and an optimisation phase; three things differ:

* **search** (paper section 4.3): every voxel keeps, per view, the exemplar pixel it was copied
  from (its *source*). A site's candidates are the coherent shifts of its 3 x 3 in-plane
  neighbours' sources and their k-coherence sets (:func:`npmrf3d.model.kcoherence.candidate_set`);
  distances are measured between PCA-reduced neighbourhoods (about 20 dimensions) and multiplied
  by the **index-histogram** factor ``1 + index_weight * max(0, H_i(e) / phi - 1)`` (eq. 5-6),
  ``H_i`` counting the sites matched with each exemplar centre, ``phi`` its even share.
* **discrete solver** (section 4.2): every voxel *copies* one exemplar texel, colour and source:
  among the texels voted by all overlapping neighbourhoods of all views (a neighbourhood at ``u``
  matched with centre ``e`` votes for ``e + (x - u)``), the one nearest to their weighted mean
  (``solver="mean"``, the paper's practice) or, by default, a weighted medoid of the votes
  (``solver="medoid"``: the paper's practice is mean-seeking and drifts to mid values, measured
  in ``docs/chen_wang.md``).
  Votes carry the IRLS weight ``||s - e||^(r - 2)`` divided by the **position-histogram** factor
  ``1 + position_weight * max(0, H_p(texel) / theta - 1)`` (eq. 4), ``H_p`` counting the voxels
  that copy each exemplar pixel. The volume's colours are therefore exemplar colours.
* **windows per level** (section 5): 8, 8, 6 or 8, 6, 4 from coarse to fine.

The engine -- search, solver, histograms, its side of the level loop -- is the model's
(:mod:`npmrf3d.model.kcoherence_engine`, shared with the coherent NP-MRF sampler); this module
holds Chen–Wang's configuration and method.

Choices where the paper is silent (also in ``docs/chen_wang.md``)
-----------------------------------------------------------------
* Geometry: views and axes of :mod:`npmrf3d.model.neighbourhood`; a window at ``u`` covers
  ``u - a .. u - a + w - 1``, ``a = (w - 1) // 2``; the volume is toroidal, exemplar windows lie
  inside the exemplar (valid centres). Coarse exemplars are 2 x 2 box averages, so sources
  up-sample as ``2 * parent + offset``. A coherent shift that leaves the valid centres is
  clamped back.
* Candidates: the 3 x 3 in-plane neighbours (the site included), ``k = 5``; k-coherence sets in
  the PCA space, optionally skipping centres within ``coherence_exclude`` pixels of the query.
* Sources per view: the chosen texel is the source of the view that voted for it; every other
  view takes its own voted texel nearest (in colour) to the copied one. Initial volume: every
  voxel a uniformly random pixel of the first view's exemplar (colour and source), other distinct
  exemplars drawn independently. Up-sampled colours are read at the first view's source.
* Histograms are counts with strengths relative to the even share (``H / even - 1``), see
  :func:`npmrf3d.model.kcoherence.histogram_factor`. The index histogram is updated between batches of
  slices (``batches`` interleaved groups along the view's normal axis), the position histogram
  between batches of a random voxel order; within a batch they are frozen, so the parallel loops
  write only their own site or voxel and results do not depend on the thread count.
* IRLS distances are the PCA-space distances of the match, floored at
  ``1e-3 * sigma * sqrt(d)``.
* This project's additions (defaults chosen by measurement, 0 = the paper): ``position_boost``
  (votes for under-used pixels weigh more), ``random_candidates`` (hashed random valid
  centres join each candidate set, so the index histogram can reach parts of the exemplar the
  coherent candidates never propose), ``value_weight`` and ``value_prior`` (histogram matching
  of the voxel values, after Kopf et al. 2007: votes for over-used value bins weigh less and
  under-used values get a prior, so sparse bright spots survive; the position histogram, spread
  over thousands of pixels, cannot see that 1 % of the exemplar is missing) and
  ``global_share`` (the worst-matched sites also get a global k-d tree search; off by default).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .. import _validation as check
from ..options import made_from, option, options_of, refusing, validate
from ..config import DEFAULT_SIZE, SynthesisMethod, SynthesisResult
from ..model.kcoherence_engine import KCoherenceLevels
from ..model.neighbourhood import VIEWS
from ..model.kcoherence_engine import block_aprons
from ..model.pyramid import run_pyramid
from ..resources import coherent_estimate
from ._api import prepare

__all__ = ["ChenWangConfig", "chen_wang_synthesize", "make_chen_wang_config", "run"]

ProgressCallback = Callable[[int, int, int, float], None]

#: How a voxel picks among its voted texels: ``mean`` = nearest to their weighted mean (the
#: paper's practice), ``medoid`` = a weighted medoid (``sum_q w_q ||e_p - e_q||``).
SOLVERS = ("mean", "medoid")


def _blockwise(config) -> bool:
    return config.blockwise


def _global_matches(config) -> bool:
    return config.global_share > 0


def _value_prior(config) -> bool:
    return config.value_prior > 0


@dataclass(frozen=True)
class ChenWangConfig:
    """A validated Chen–Wang run; every option and its default is a field here (see
    :func:`chen_wang_synthesize` and :mod:`npmrf3d.options`)."""

    size: tuple[int, int, int] = option((DEFAULT_SIZE,) * 3, "output size", kind="own")
    window: tuple[int, ...] = option(
        (8, 6, 4), "window side per level, coarsest first: one number or one per level (the paper: "
        "8,8,6 or 8,6,4)", kind="levels", low=2, high=32, group="volume and pyramid")
    levels: int = option(3, "resolution levels, coarse to fine", kind="int", low=1, high=8,
                         metavar="L", group="volume and pyramid")
    views: tuple[str, ...] = option(VIEWS, "constrained views", kind="own")
    iterations: tuple[int, ...] = option(
        (4, 4, 3), "search + solve iterations per level: one number or one per level, coarsest first",
        kind="levels", low=1, group="volume and pyramid")
    k: int = option(5, "size of the k-coherence sets", kind="int", low=1, high=64)
    pca_dims: int = option(20, "dimensions of the PCA-reduced neighbourhoods", kind="int", low=1)
    r: float = option(0.8, "exponent of the robust energy ||s - e||^r; IRLS weights ||s - e||^(r-2)",
                      kind="real", low=0.0, high=2.0, low_open=True)
    grid: int = option(1, "search sites every GRID voxels along both plane axes (1 = every voxel, the "
                       "paper)", kind="int", low=1, group="volume and pyramid")
    index_weight: float = option(8.0, "strength of the index-histogram penalty on the search distance "
                                 "(0 = off)", kind="real", low=0.0)
    position_weight: float = option(32.0, "strength of the position-histogram re-weighting of the votes "
                                    "(0 = off)", kind="real", low=0.0)
    position_boost: float = option(16.0, "votes for under-used exemplar pixels weigh up to 1 + B times "
                                   "more (0 = the paper)", kind="real", low=0.0)
    coherence_exclude: float = option(0.0, "k-coherence sets skip centres within this many pixels of the "
                                      "query (0 = off)", kind="real", low=0.0)
    random_candidates: int = option(8, "random valid centres added to each site's candidates (0 = the "
                                    "paper)", kind="int", low=0, high=256)
    global_share: float = option(0.0, "share of each view's worst-matched sites that also search every "
                                 "exemplar neighbourhood (k-d tree; 0 = the paper)", kind="real",
                                 low=0.0, high=1.0)
    coherence_bias: float = option(0.0, "a global match replaces the coherent one only if its distance "
                                   "times 1 + B is smaller", kind="real", low=0.0,
                                   applies=_global_matches, needs="global_share is above 0")
    value_weight: float = option(32.0, "votes for texels whose value bins the volume over-uses weigh "
                                 "1 + W * excess less (0 = the paper)", kind="real", low=0.0)
    value_prior: float = option(3.0, "strength of the histogram prior log(exemplar share / volume share) "
                                "on each candidate's score (0 = off)", kind="real", low=0.0)
    value_bins: int = option(16, "bins per channel of the value histograms", kind="int", low=2, high=256)
    phase_weight: float = option(0.0, "phase control: a candidate of the phase (split at the exemplar's "
                                 "Otsu threshold) the volume over-uses loses W times that phase's price "
                                 "(0 = off)", kind="real", low=0.0, applies=_value_prior,
                                 needs="value_prior is above 0")
    batches: int = option(8, "histogram updates per pass (more follow the histograms closer, fewer run "
                          "more in parallel)", kind="int", low=1, high=1024)
    solver: str = option("medoid", "how a voxel picks among its voted texels: medoid (chosen by "
                         "measurement) or mean (the paper's practice)", kind="choice", choices=SOLVERS)
    balance_views: bool = option(False, "give every view's votes the same total weight at each voxel",
                                 kind="flag")
    # block-local runs: the levels up to whole_voxels whole, the finer ones reading the histograms of a
    # pilot region and random numbers hashed from grid positions, so any block can be made alone
    # (model.regions, model.kcoherence_histograms.PilotHistograms)
    blockwise: bool = option(False, "the block-local sampler, whose volume can be made in blocks "
                             "(--out VOL.zarr): bit for bit the volume made at once", kind="flag",
                             group="blocks")
    # the pilot's block side at the finest level (its cone at the coarser ones)
    pilot: int = option(64, "side of the pilot block whose live histograms every block reads", kind="int",
                        low=8, group="blocks", applies=_blockwise, needs="blockwise is set")
    # levels of at most this many voxels run whole, once for all blocks, with every histogram
    # (256^3: at 512^3 the two coarsest levels, whose cones per block of 128 would repeat the
    # 256^3 level 8.8 times over)
    whole_voxels: int = option(2 ** 24, "levels of at most N voxels (and the coarsest) run whole, once "
                               "for all blocks", kind="int", low=1, group="blocks", applies=_blockwise,
                               needs="blockwise is set")
    seed: int | None = option(None, "random seed", kind="own")

    def to_dict(self) -> dict:
        """Plain JSON-able dictionary."""
        return asdict(self)


DEFAULTS = ChenWangConfig()


@made_from(ChenWangConfig)
def make_chen_wang_config(values: dict) -> ChenWangConfig:
    """Validate plain keyword arguments into a frozen :class:`ChenWangConfig`.

    ``window`` and ``iterations`` take one integer or one per level (coarsest first); when the
    default per-level tuples meet another level count, the last ``levels`` entries are used.
    ``blockwise``: the coarsest level, and every level of at most ``whole_voxels`` voxels, runs
    whole with every histogram, once for all blocks; the finer ones in blocks
    that read, batch by batch, the position and value histograms of a pilot block of side
    ``pilot`` made once with its histograms live, and no index histogram
    (:class:`npmrf3d.model.kcoherence_histograms.PilotHistograms`); the global search, which
    reads the whole volume, is off (``global_share`` recorded as 0).
    """
    levels = validate(ChenWangConfig, "levels", values["levels"])
    window, iterations, grid = values["window"], values["iterations"], values["grid"]
    if window is DEFAULTS.window and levels != len(DEFAULTS.window):
        window = (DEFAULTS.window * levels)[-levels:] if levels > 3 else DEFAULTS.window[-levels:]
    if iterations is DEFAULTS.iterations and levels != len(DEFAULTS.iterations):
        iterations = (DEFAULTS.iterations * levels)[-levels:] if levels > 3 else DEFAULTS.iterations[-levels:]
    window = validate(ChenWangConfig, "window", window, levels=levels)
    dims = check.size(values["size"], levels=levels, window=1)
    grid = check.integer("grid", grid, low=1, high=min(window))
    for li, w in enumerate(window):
        level = levels - 1 - li
        for n in dims:
            side = n // 2 ** level
            if side < w:
                check.fail(f"size {n} is too small for window {w} at level {level}: that level has "
                           f"{side} voxels per side, needs at least {w}; use a larger size, smaller "
                           f"windows or fewer levels")
            if side % grid:
                check.fail(f"size {n} does not suit grid {grid} with {levels} levels: level {level} "
                           f"has {side} voxels per side, not a multiple of {grid}")
    own = {"size": dims, "window": window, "levels": levels, "grid": grid,
           "iterations": validate(ChenWangConfig, "iterations", iterations, levels=levels),
           "views": check.views(values["views"], VIEWS),
           "seed": None if values["seed"] is None else check.integer("seed", values["seed"], low=0)}
    options = {name: validate(ChenWangConfig, name, values[name])
               for name in options_of(ChenWangConfig) if name not in own}
    if options["blockwise"]:
        options["global_share"] = 0.0
    return ChenWangConfig(**own, **options)


def _check_exemplar_levels(config: ChenWangConfig, per_view: Mapping[str, np.ndarray]) -> None:
    for v, a in per_view.items():
        for li, w in enumerate(config.window):
            level = config.levels - 1 - li
            h, wd = a.shape[0] // 2 ** level, a.shape[1] // 2 ** level
            if min(h, wd) < w + 1:
                check.fail(f"exemplar for view {v} of size {a.shape[0]}x{a.shape[1]} is too small "
                           f"for window {w} at level {level}: that level sees {h}x{wd} pixels, "
                           f"needs at least {w + 1} per side; use a larger exemplar, smaller "
                           f"windows or fewer levels")


# --------------------------------------------------------------------------- public


def chen_wang_synthesize(exemplar=None, *, size=DEFAULT_SIZE, rng=None, progress: ProgressCallback | None = None,
                         checkpoint: str | Path | None = None, exemplars: Mapping | None = None,
                         **options) -> SynthesisResult:
    """Synthesize a solid texture with Chen & Wang's method (2010).

    Parameters
    ----------
    exemplar : path, (H, W) or (H, W, C) array, or None
        The 2D sample (None: the bundled default); used for every view without an entry in
        ``exemplars``. Any channel count.
    size : int or (N1, N2, N3)
        Output size, divisible by ``2**(levels - 1)``; every level needs at least its window
        in voxels per side.
    window : int or sequence of int
        Window side per level, coarsest first (the paper: ``(8, 8, 6)`` or ``(8, 6, 4)``).
    levels : int
        Resolution levels (the paper: 3).
    views : sequence of {"front", "right", "top"} (or a comma-separated string)
        Constrained views (1 to 3).
    exemplars : dict view -> exemplar, optional
        A different exemplar for some views (same channel count).
    iterations : int or sequence of int
        Search + solve iterations per level, coarsest first (the paper: about 5).
    k : int
        Size of the k-coherence sets (the paper: 5).
    pca_dims : int
        Dimensions of the PCA-reduced neighbourhoods (the paper: about 20).
    r : float in (0, 2]
        Exponent of the robust energy; IRLS weights ``||s - e||^(r - 2)``.
    grid : int
        Sites searched every ``grid`` voxels along both plane axes (1: every voxel, the paper).
    index_weight, position_weight : float >= 0
        Strengths of the index- and position-histogram factors ``1 + w * max(0, H / even - 1)``
        (0 = off; see :func:`npmrf3d.model.kcoherence.histogram_factor`).
    position_boost : float >= 0
        This project's addition: votes for under-used exemplar pixels get their weight
        multiplied by ``1 + position_boost * (1 - H_p / theta)`` (0 = off, the paper).
    coherence_exclude : float >= 0
        k-coherence sets skip centres within this many pixels of the query (0 = off).
    random_candidates : int >= 0
        This project's addition: that many uniformly random valid centres join every site's
        candidate set (drawn per site from a hash of the seed, so thread-independent; 0 = the
        paper). They let the index histogram reach exemplar parts the coherent candidates miss.
    global_share : float in [0, 1]
        This project's addition: after each view's search, that share of its sites -- the worst
        matched -- also search all exemplar neighbourhoods (``cKDTree``), and take the global
        match where it is clearly better (:func:`npmrf3d.model.kcoherence.global_matches`; 0 = the
        paper). A structure that no coherent candidate proposes (a sparse bright spot) can then
        be matched, so it survives.
    coherence_bias : float >= 0
        A global match replaces the coherent one only if its distance times
        ``1 + coherence_bias`` is smaller (Hertzmann et al. 2001's coherence parameter).
    value_weight : float >= 0
        This project's addition after Kopf et al. 2007's histogram matching: the solver divides
        each vote's weight by ``1 + value_weight * sum_c max(0, H_c(b) - T_c(b))``, ``H_c`` the
        volume's histogram of channel ``c`` and ``T_c`` the exemplars' (``value_bins`` bins over
        the exemplars' range, in units of an even bin's share), ``b`` the voted texel's bin; the
        histogram follows the solver between batches. It keeps the exemplar's share of rare
        values (sparse bright spots) that the position histogram, spread over thousands of
        pixels, cannot see (0 = off, the paper).
    value_prior : float >= 0
        The histogram prior ``P = value_prior * sum_c log(T_c(b) / H_c(b))`` of each candidate
        texel, positive for under-represented values and zero once the histograms agree: the
        medoid solver divides a candidate's energy by ``exp(P)``, the coherent NP-MRF decision
        (:mod:`npmrf3d.methods.npmrf_coherent`) adds ``P`` to its ML_H2b log-score (0 = off; the mean solver
        ignores it).
    value_bins : int
        Bins per channel of those histograms.
    phase_weight : float >= 0
        A phase control through the histogram prior (this project's addition, docs/segmented.md, "Phase control (`phase_weight`)"): each
        channel's value bins split at the Otsu threshold of the exemplars' histogram into two
        phases, and after every iteration a :class:`npmrf3d.model.phases.PhaseControl` per
        channel prices the phase the volume over-uses; a candidate's prior loses
        ``phase_weight`` times its phase's cost (excess plus the integral of the error, times
        the control's gain). It restores a thin minority phase that the plain prior lets erode
        (0 = off; acts only with ``value_prior > 0``).
    batches : int
        Histogram updates per pass (search: interleaved slice groups; solver: parts of a random
        voxel order). More batches track the histograms more closely, fewer run more in parallel.
    solver : {"mean", "medoid"}
        How a voxel picks among its voted texels: the one nearest to their weighted mean (the
        paper's practice, section 4.2), or a weighted medoid: among the texels of the 8 heaviest
        votes, the one ``p`` minimising ``sum_q w_q ||e_p - e_q||`` over all votes
        (mode-seeking: keeps the exemplar's contrast, docs/chen_wang.md).
    balance_views : bool
        Scale each view's votes of a voxel to the same total weight, so no view's (coherent,
        heavily weighted) neighbourhoods outvote the others (the paper: off).
    rng : None, int or numpy Generator
        Seed; the result depends on it only (not on the number of threads).
    progress : callable, optional
        ``progress(level, iteration, iterations, energy)`` before the first iteration of each
        level (``iteration = 0``, energy nan) and after each (energy = mean ``||s - e||^r``).
    checkpoint : path, optional
        ``.npz`` file written after each level; if it exists and holds a checkpoint of the same
        configuration and exemplars, synthesis resumes after its last finished level.

    Returns
    -------
    SynthesisResult
        ``volume`` (N1, N2, N3, C) float32, every voxel an exemplar texel of its level;
        ``history`` the mean energy per iteration, one list per level (coarsest first);
        ``config`` a :class:`ChenWangConfig`; ``timings``; ``labels`` the distinct colours of the
        exemplars; ``stats`` per level: shape, window, candidates per site, PCA dimensions,
        search and solve seconds, changed voxels per iteration, position-histogram spread, and
        the thread count.

    Examples
    --------
    >>> import numpy as np
    >>> stripes = np.tile(np.array([0, 0, 1, 1], dtype=np.uint8) * 255, (16, 4))
    >>> res = chen_wang_synthesize(stripes, size=8, window=4, levels=1, iterations=2, rng=0)
    >>> res.volume.shape, sorted(np.unique(res.volume).tolist())
    ((8, 8, 8, 1), [0.0, 1.0])
    """
    t_start = time.perf_counter()
    config, generator, per_view = prepare(METHOD, exemplar, exemplars, size=size, rng=rng,
                                          progress=progress, checkpoint=checkpoint, options=options)
    return run(per_view, config, generator, progress=progress, checkpoint=checkpoint, t_start=t_start)


# --------------------------------------------------------------------------- the method


def run(per_view: Mapping[str, np.ndarray], config: ChenWangConfig, rng: np.random.Generator, *,
        progress: ProgressCallback | None = None, checkpoint: str | Path | None = None,
        t_start: float | None = None, region=None) -> SynthesisResult:
    """Run a validated configuration on validated float32 ``(H, W, C)`` exemplars (one per view,
    each checked against every level's window): the k-coherence engine
    (:class:`npmrf3d.model.kcoherence_engine.KCoherenceLevels`) with its own solver. The body of
    :func:`chen_wang_synthesize` and the registered method (:data:`npmrf3d.methods.METHODS`);
    ``region`` (a ``blockwise`` configuration): one block from its dependency cone."""
    t_start = time.perf_counter() if t_start is None else t_start
    _check_exemplar_levels(config, per_view)
    levels = KCoherenceLevels("chen-wang", config, per_view)
    out = run_pyramid(levels, rng, progress=progress, checkpoint=checkpoint, t_start=t_start, region=region)
    return SynthesisResult(volume=out.state.volume, history=out.history, config=config,
                           timings=out.timings, labels=levels.labels, stats=out.stats)


def _fit(config) -> dict:
    """What every exemplar must fit: the coarsest window, the level count (then
    :func:`_check_exemplar_levels` checks each level's window)."""
    return {"window": max(config.window), "levels": config.levels, "toroidal": False}


METHOD = SynthesisMethod(
    name="chen-wang", run=run, make_config=refusing(make_chen_wang_config, ChenWangConfig),
    config_class=ChenWangConfig, synthesize=chen_wang_synthesize, fit=_fit,
    description="Chen & Wang 2010: k-coherence search, discrete solver, position and index histograms",
    resources=coherent_estimate,
    aprons=lambda config, per_view: block_aprons(config),
)
