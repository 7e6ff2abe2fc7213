"""``synthesize``: the multi-scale NP-MRF sampler behind one function (docs/model.md)."""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .._kernels import _jit
from ..config import DEFAULT_SIZE, SynthesisConfig, SynthesisMethod, SynthesisResult
from ..model.exemplar import make_labels
from ..model.heuristics import DECISIONS, get_heuristic
from ..model.neighbourhood import colour_classes
from ..model.parzen import PRUNE, adaptive_floor, build_view_models
from ..model.pyramid import ArraySpec, Levels, LevelState, random_state, run_pyramid, upsample
from ..model.relax import RELAXATIONS
from ..model.relax.icm import expected_sweeps
from ..options import shared
from ..resources import coherent_estimate, npmrf_estimate, one_after_another
from . import npmrf_coherent
from ._api import prepare
from .npmrf_options import BASE_LEVELS, coherent_grid, make_config, settle

__all__ = ["METHOD", "make_config", "npmrf_method", "npmrf_synthesize", "run"]

ProgressCallback = Callable[[int, int, int, float], None]


def npmrf_synthesize(exemplar=None, *, size=DEFAULT_SIZE, rng=None, progress: ProgressCallback | None = None,
                     checkpoint: str | Path | None = None, exemplars: dict | None = None,
                     **options) -> SynthesisResult:
    """Synthesize a solid texture whose constrained slices look like the exemplar.

    Parameters
    ----------
    exemplar : path, (H, W) or (H, W, C) array, or None
        The 2D sample (None: the bundled default). Used for every constrained view that has no
        entry in ``exemplars``.
    size : int or (N1, N2, N3)
        Output size, divisible by ``2**(levels - 1)``.
    window : odd int in [3, 15]
        Side of each view's square neighbourhood.
    levels : int or None
        Number of pyramid levels (the paper's "scales"). None (the default): 3, and one more for
        each doubling of both the exemplars' and the volume's smallest side beyond 64
        (:func:`npmrf3d.methods.npmrf_options.pyramid_levels`); the result's ``config`` holds
        the count that ran.
    support : {"coherent", "full"} or None
        Which exemplar neighbourhoods each view's Parzen estimate sums over (docs/model.md,
        section 8). ``coherent`` (None, the default, chosen by measurement: docs/quality.md):
        the coherent candidates of every neighbourhood containing the voxel
        (:mod:`npmrf3d.methods.npmrf_coherent`), the voxel copies the best exemplar texel,
        ``window`` at every level, ``history`` the mean patch energy per iteration. ``full``:
        every exemplar patch (Urs et al. 2014), with the decision rule ``preset``.
    heuristic : {"ML_H1a", "ML_H1b", "ML_H2a", "ML_H2b"}
        How the views' estimates combine (docs/model.md, section 3); support ``coherent``
        ranks its candidates by ML_H2b or ML_H2a.
    relaxation : {"icm", "anneal"}
        ICM, or simulated annealing with one global temperature (needs ML_H2a or ML_H2b). With
        support ``full`` ICM has per-voxel temperatures (``xi``, ``stop``, ``max_sweeps``); with
        support ``coherent`` it re-decides every voxel in each of a level's iterations.
    preset : {"tuned", "paper"} or None
        Support ``full``: the decision rule (:data:`npmrf3d.config.PRESETS`); ``paper`` is Urs
        et al. 2014 word for word, ``tuned`` (None) the rule chosen by measurement.
    variant : {"coherent", "sharp", "literal"} or None
        The older single name of a support and a preset (:data:`npmrf3d.config.VARIANTS`):
        ``sharp`` (also ``default``) is support ``full`` with preset ``tuned``, ``literal`` with
        ``paper``.
    views : sequence of {"front", "right", "top"} (or a comma-separated string)
        Constrained views; see :mod:`npmrf3d.model.neighbourhood` for the axis mapping.
    exemplars : dict view -> exemplar, optional
        A different exemplar for some views.
    upsample : {"1/8", "8/8"} or None
        How a level initialises the next finer one (docs/model.md, section 7). None: ``8/8``
        for support ``coherent`` (every child copies its parent's shifted sources, the only
        choice there); for support ``full`` the paper's choice, ``1/8`` for ICM and ``8/8`` for
        annealing.
    inherit : {"resynth", "fixed"}
        Support ``full``: whether inherited voxels may still change (temperature 0 either way).
    xi : float < 0
        Support ``full``, ICM: the cooling step.
    stop : float in (0, 1]
        Support ``full``, ICM: stop a level once the global temperature fell by this fraction.
    max_sweeps : int
        Support ``full``, ICM: hard limit of sweeps per level.
    sampler : {"heat-bath", "metropolis"}
        Annealing: a heat-bath draw from the tempered objective (the default; support
        ``coherent`` draws among its candidates), or the paper's Metropolis proposals
        (support ``full``).
    schedule : {"geometric", "linear"}
        Annealing: how the global temperature falls from ``t0`` to ``t_end`` within a level.
    t0, t_end : float
        Annealing: first and last temperature of each level (``0 < t_end <= t0``; ``t_end = 0``
        allowed for the linear schedule).
    proposals : int
        Annealing: proposals per voxel per level (one per voxel per sweep; with support
        ``coherent`` the level's iterations).
    proposal : {"exemplar", "labels"}
        Support ``full``, Metropolis: candidates drawn from the exemplar's values (the paper) or
        uniformly from the label set.
    segmented : {"auto", "yes", "no"}
        Support ``coherent``: its preset for segmented exemplars (:data:`npmrf3d.methods.npmrf_coherent.SEGMENTED`:
        window 5 at every level, histogram vote weighting 8, and two pyramids, ``levels`` and
        one fewer, of which :func:`npmrf3d.methods.npmrf_coherent.best_of_pyramids` keeps the one nearer the
        exemplars' two-point correlation; about twice the time). "auto": when the exemplars hold
        at most :data:`npmrf3d.methods.npmrf_coherent.SEGMENTED_MAX_VALUES` grey values together; "no":
        ``window`` and ``levels`` as given. The result's ``stats`` say what ran (docs/segmented.md).
    bandwidth, adaptive, decision, tau, histogram_weight : optional
        Support ``full``: override single fields of the preset (:class:`npmrf3d.config.DecisionRule`).
    centre_bandwidth, outlier : optional
        Override the support's centre bandwidth and outlier share.
    grey_levels : int, optional
        Re-quantise the exemplar to this many levels per channel.
    palette : int, optional
        Reduce the exemplar to at most this many colours (k-means).
    toroidal_exemplar : bool
        Support ``full``: let exemplar patches wrap around its borders.

    An option set away from its default where the chosen combination cannot use it is refused
    with one line (:mod:`npmrf3d.methods.npmrf_options`).
    rng : None, int or numpy Generator
        Seed; the result depends on it only (not on the number of threads).
    progress : callable, optional
        Called as ``progress(level, sweep, expected_sweeps, global_temperature)`` before the
        first sweep of each level (``sweep = 0``) and after every sweep; for ICM
        ``expected_sweeps`` is the sweeps the stop rule will need, corrected as it goes
        (:func:`npmrf3d.model.relax.icm.expected_sweeps`), for annealing ``proposals``.
    checkpoint : path, optional
        A ``.npz`` file written after each level; if it exists and holds a checkpoint of the
        same configuration, synthesis resumes after its last finished level.

    Returns
    -------
    SynthesisResult

    Examples
    --------
    >>> import numpy as np
    >>> stripes = np.tile(np.array([0, 0, 1, 1], dtype=np.uint8) * 255, (16, 4))
    >>> res = npmrf_synthesize(stripes, size=8, window=3, levels=1, views="front", rng=0)
    >>> res.volume.shape
    (8, 8, 8, 1)
    """
    t_start = time.perf_counter()
    config, generator, per_view = prepare(METHOD, exemplar, exemplars, size=size, rng=rng,
                                          progress=progress, checkpoint=checkpoint, options=options)
    return npmrf_method(per_view, config, generator, progress=progress, checkpoint=checkpoint,
                        t_start=t_start)


class _NpmrfLevels(Levels):
    """The NP-MRF sampler's side of :func:`npmrf3d.model.pyramid.run_pyramid` (docs/model.md,
    sections 2-7)."""

    def __init__(self, config: SynthesisConfig, label_images: dict, labels: np.ndarray,
                 label_freq: np.ndarray):
        self.config, self.label_images, self.labels, self.label_freq = config, label_images, labels, label_freq
        self.size, self.levels = config.size, config.levels
        self.key = _config_key(config)
        self.fingerprint = {"labels": labels}
        self.heuristic = get_heuristic(config.heuristic)
        relaxation = RELAXATIONS[config.relaxation]
        self.relax_level = relaxation.run
        self.options = config.relaxation_options
        self.models = self.info = self.classes = None

    def prepare(self, level, shape):
        self.models, self.info = build_view_models(
            self.label_images, self.labels, window=self.config.window, level=level,
            rule=self.config.rule, toroidal=self.config.toroidal_exemplar)
        self.classes = colour_classes(shape, self.config.window)

    def initial(self, shape, rng):
        return random_state(shape, self.labels, self.label_freq, rng)

    def upsample(self, state, rng):
        return upsample(state, self.config.upsample, self.labels, self.label_freq, rng)

    def start(self, level, state):
        if self.config.relaxation == "anneal":
            return self.options.proposals, self.options.t0
        initial = float(state.temps.sum(dtype=np.float64))
        return self._expected([initial], state), initial

    def _expected(self, history, state):
        """ICM: the sweeps the stop rule will need (corrected after every sweep)."""
        o = self.options
        return expected_sweeps(history, n_voxels=state.temps.size, xi=o.xi, stop=o.stop,
                               max_sweeps=o.max_sweeps, n_union=self.models.union_offsets.shape[0])

    def relax(self, level, state, rng, on_step):
        config, rule = self.config, self.config.rule
        specific = dataclasses.asdict(self.options)
        if config.relaxation == "icm":
            specific.update(decision=DECISIONS[rule.decision], tau=rule.tau)
            seen = [float(state.temps.sum(dtype=np.float64))]

            def on_sweep(sweep, value, report=on_step):
                seen.append(value)
                report(sweep, value, self._expected(seen, state))

            on_step = on_sweep
        history, stats = self.relax_level(
            state.volume, state.labels_volume, state.temps, state.inherited, self.models,
            self.classes, heuristic=self.heuristic.code, resynth=config.inherit == "resynth",
            adaptive=rule.adaptive, min_two_h2=adaptive_floor(self.info), prune=PRUNE,
            histogram_weight=rule.histogram_weight, outlier=rule.outlier,
            exemplar_freq=self.label_freq, rng=rng, on_sweep=on_step, **specific,
        )
        shape = state.labels_volume.shape
        return state, history, {**stats, "shape": list(shape), "classes": len(self.classes),
                                "views": self.info}

    def to_arrays(self, state):
        return {"volume": state.volume, "labels_volume": state.labels_volume, "temps": state.temps,
                "inherited": state.inherited}

    def from_arrays(self, arrays):
        return LevelState(arrays["volume"], arrays["labels_volume"], arrays["temps"], arrays["inherited"])

    def array_specs(self, level, shape):
        return {"volume": ArraySpec((*shape, self.labels.shape[1]), np.float32),
                "labels_volume": ArraySpec(shape, np.int32, 0, len(self.labels) - 1),
                "temps": ArraySpec(shape, np.float32, 0.0), "inherited": ArraySpec(shape, np.bool_)}


def run(per_view: dict[str, np.ndarray], config: SynthesisConfig, rng: np.random.Generator, *,
        progress: ProgressCallback | None = None, checkpoint: str | Path | None = None,
        t_start: float | None = None) -> SynthesisResult:
    """The full support: run a validated configuration on validated exemplars (the body of
    :func:`npmrf_synthesize` for ``support="full"``; :func:`npmrf_method`, the registered
    method, chooses between it and the coherent support)."""
    t_start = time.perf_counter() if t_start is None else t_start
    distinct = {id(a): a for a in per_view.values()}
    labels, images = make_labels(list(distinct.values()), grey_levels=config.grey_levels,
                                 palette=config.palette, rng=rng)
    image_of = dict(zip(distinct, images))
    label_images = {v: image_of[id(a)] for v, a in per_view.items()}
    label_freq = np.bincount(np.concatenate([im.ravel() for im in images]), minlength=len(labels))
    label_freq = label_freq / label_freq.sum()
    levels = _NpmrfLevels(config, label_images, labels, label_freq)
    out = run_pyramid(levels, rng, progress=progress, checkpoint=checkpoint,
                      timings={"setup": time.perf_counter() - t_start},
                      stats={"threads": _jit.thread_count()}, t_start=t_start)
    return SynthesisResult(volume=out.state.volume, history=out.history, config=config,
                           timings=out.timings, labels=labels, stats=out.stats)


def _config_key(config: SynthesisConfig) -> str:
    return json.dumps(config.to_dict(), sort_keys=True, default=str)


def npmrf_method(per_view: dict[str, np.ndarray], config: SynthesisConfig, rng: np.random.Generator, *,
                 progress: ProgressCallback | None = None, checkpoint: str | Path | None = None,
                 t_start: float | None = None, region=None) -> SynthesisResult:
    """The registered NP-MRF sampler (:data:`npmrf3d.methods.METHODS`): the coherent support
    (:mod:`npmrf3d.methods.npmrf_coherent`) or the full one (:func:`run`), by ``config.support``.

    ``t_start`` (optional, every method accepts it): ``time.perf_counter()`` when the caller
    started, so that ``timings["setup"]`` includes loading the exemplars. ``region`` (a
    ``blockwise`` configuration): one block from its dependency cone
    (:mod:`npmrf3d.methods.blocks`). A configuration that leaves its levels to the run is
    settled on ``per_view`` first (:func:`npmrf3d.methods.npmrf_options.settle`).
    """
    config = settle(config, per_view)
    if config.support == "coherent":
        return _run_coherent(per_view, config, rng, progress=progress, checkpoint=checkpoint,
                             t_start=t_start, region=region)
    return run(per_view, config, rng, progress=progress, checkpoint=checkpoint, t_start=t_start)


def segmented(config: SynthesisConfig, per_view) -> bool:
    """Whether a ``coherent``-support run uses :data:`npmrf3d.methods.npmrf_coherent.SEGMENTED`: ``segmented``
    "yes", or "auto" and the exemplars (``per_view``: view -> array, before any palette or grey
    levels) are segmented (:func:`npmrf3d.methods.npmrf_coherent.is_segmented`)."""
    if config.segmented == "auto":
        return npmrf_coherent.is_segmented({id(a): a for a in per_view.values()}.values())
    return config.segmented == "yes"


def _coherent_options(config: SynthesisConfig, phases: bool, levels: int) -> npmrf_coherent.CoherentConfig:
    """The coherent sampler's options for a ``coherent``-support configuration: every option the
    two configurations share by name as it is (:func:`npmrf3d.options.shared`), with ``levels``
    levels and the site spacing of :func:`coherent_grid`; with relaxation ``anneal`` its
    ``proposals`` as the iterations of every level (else ``t0`` 0: the highest score decides);
    ``temperatures`` as its per-voxel ICM; for a segmented exemplar (``phases`` =
    :func:`segmented`) the preset's changes (:meth:`npmrf3d.methods.npmrf_coherent.SegmentedPreset.changes`)."""
    anneal = config.relaxation == "anneal"
    run = {"levels": levels, "icm": config.temperatures, "grid": coherent_grid(config, phases, levels),
           "t0": config.t0 if anneal else 0.0, **({"iterations": config.proposals} if anneal else {})}
    preset = npmrf_coherent.SEGMENTED.changes() if phases else {}
    return npmrf_coherent.make_coherent_config(**{**shared(config, npmrf_coherent.CoherentConfig), **run, **preset})


@functools.lru_cache(maxsize=32)
def _coherent_runs(config: SynthesisConfig, phases: bool) -> tuple[npmrf_coherent.CoherentConfig, ...]:
    """The coherent sampler's runs: one, or the segmented preset's pyramids, deepest first (a
    ``blockwise`` run: the deepest only, since the choice between them reads the whole volume);
    made once for a configuration, which its memory estimate, block aprons and run all read."""
    levels = npmrf_coherent.SEGMENTED.pyramids(config.levels) if phases else (config.levels,)
    if config.blockwise:
        levels = levels[:1]
    return tuple(_coherent_options(config, phases, n) for n in levels)


def npmrf_aprons(config: SynthesisConfig, per_view) -> tuple[int, ...] | None:
    """Per level, how far a ``blockwise`` run reaches (:func:`npmrf3d.methods.npmrf_coherent.coherent_aprons`);
    None for any other run."""
    if not config.blockwise or config.support != "coherent":
        return None
    return npmrf_coherent.coherent_aprons(_coherent_runs(config, segmented(config, per_view))[0])


def npmrf_resources(config: SynthesisConfig, per_view):
    """The memory estimate of a run: the coherent sampler's (its pyramids') for the ``coherent``
    support, the full-Parzen sampler's otherwise."""
    if config.support == "coherent":
        runs = _coherent_runs(config, segmented(config, per_view))
        return one_after_another(coherent_estimate(options, per_view) for options in runs)
    return npmrf_estimate(config, per_view)


def _run_coherent(per_view, config: SynthesisConfig, rng, *, progress, checkpoint, t_start,
                  region=None) -> SynthesisResult:
    """The ``coherent`` support: :mod:`npmrf3d.methods.npmrf_coherent` with the options of :func:`_coherent_options`
    (decided on the exemplars as given); the exemplars reduced to ``grey_levels`` or a
    ``palette`` first when asked. ``stats["segmented"]`` says whether the segmented preset ran;
    the preset runs two pyramids and keeps the better (:func:`npmrf3d.methods.npmrf_coherent.best_of_pyramids`)."""
    phases = segmented(config, per_view)  # counted once, on the exemplars as given
    if config.grey_levels is not None or config.palette is not None:
        distinct = {id(a): a for a in per_view.values()}
        labels, images = make_labels(list(distinct.values()), grey_levels=config.grey_levels,
                                     palette=config.palette, rng=rng)
        reduced = {key: labels[image] for key, image in zip(distinct, images)}
        per_view = {v: reduced[id(a)] for v, a in per_view.items()}
    runs = _coherent_runs(config, phases)
    if region is not None:
        result = npmrf_coherent.run(per_view, runs[0], rng, progress=progress, t_start=t_start, region=region)
    else:
        result = npmrf_coherent.best_of_pyramids(per_view, runs, rng, progress=progress,
                                                 checkpoint=checkpoint, t_start=t_start)
    return dataclasses.replace(result, config=config, stats={**result.stats, "segmented": phases})


#: The registry entry of the NP-MRF sampler.
METHOD = SynthesisMethod(
    name="npmrf", run=npmrf_method, make_config=make_config, config_class=SynthesisConfig,
    synthesize=npmrf_synthesize,
    fit=lambda c: {"window": c.window, "levels": c.levels or BASE_LEVELS, "toroidal": c.toroidal_exemplar},
    resources=npmrf_resources,
    aprons=npmrf_aprons,
    settle=settle,
    description="the NP-MRF sampler (Urs, Da Costa and Germain 2014): Parzen LCPDFs of three 2D views, "
                "four heuristics, ICM or annealing",
)
