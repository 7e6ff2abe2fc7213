"""``synthesize``: the multi-scale NP-MRF sampler behind one function (docs/model.md)."""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from .. import _validation as check
from .._kernels import _jit
from ..config import (DEFAULT_SIZE, DEFAULT_VARIANT, SEGMENTED_MODES, VARIANT_ALIASES, VARIANTS,
    SynthesisConfig, SynthesisMethod, SynthesisResult)
from ..model.exemplar import make_labels
from ..model.heuristics import DECISIONS, get_heuristic
from ..model.neighbourhood import VIEWS, colour_classes
from ..model.parzen import PRUNE, adaptive_floor, build_view_models
from ..model.pyramid import INHERIT, UPSAMPLING, Levels, LevelState, random_state, run_pyramid, upsample
from ..model.relax import RELAXATIONS
from ..model.relax.anneal import PROPOSALS, SAMPLERS, SCHEDULES
from ..model.relax.icm import expected_sweeps
from ..resources import coherent_estimate, npmrf_estimate, one_after_another
from . import npmrf_coherent
from ._api import prepare

__all__ = ["METHOD", "make_config", "npmrf_method", "npmrf_synthesize", "run"]

ProgressCallback = Callable[[int, int, int, float], None]


#: Up-sampling used when none is asked for: the paper's choice for each relaxation.
DEFAULT_UPSAMPLE = {"icm": "1/8", "anneal": "8/8"}


_C = SynthesisConfig  # every default below is a field default of the configuration


def make_config(
    *, size=DEFAULT_SIZE, window=_C.window, levels=_C.levels, heuristic=_C.heuristic,
    relaxation=_C.relaxation, views=_C.views, upsample=None, inherit=_C.inherit, xi=_C.xi,
    stop=_C.stop, max_sweeps=_C.max_sweeps, sampler=_C.sampler, schedule=_C.schedule, t0=_C.t0,
    t_end=_C.t_end, proposals=_C.proposals, proposal=_C.proposal, variant=None,
    segmented=_C.segmented, bandwidth=None, centre_bandwidth=None, adaptive=None, decision=None, tau=None,
    histogram_weight=None, outlier=None, grey_levels=None, palette=None, toroidal_exemplar=False,
    seed=None,
) -> SynthesisConfig:
    """Validate plain keyword arguments into a frozen :class:`SynthesisConfig`.

    ``variant`` names a preset of :data:`npmrf3d.config.VARIANTS`; the seven rule arguments
    (``bandwidth`` ... ``outlier``) override single fields of it when not None.
    """
    levels = check.integer("levels", levels, low=1, high=8)
    window = check.window(window)
    dims = check.size(size, levels=levels, window=window)
    heuristic = get_heuristic(heuristic).name
    relaxation = check.choice("relaxation", relaxation, RELAXATIONS)
    views = check.views(views, VIEWS)
    if relaxation == "anneal" and not get_heuristic(heuristic).objective:
        check.fail(f"heuristic {heuristic} cannot drive annealing: the Metropolis rule compares "
                   f"objective values, and {heuristic} is defined by per-view argmax searches "
                   f"with no objective; use ML_H2a or ML_H2b, or relaxation 'icm'")
    upsample = DEFAULT_UPSAMPLE[relaxation] if upsample is None else upsample
    upsample = check.choice("upsample", upsample, UPSAMPLING)
    inherit = check.choice("inherit", inherit, INHERIT)
    xi = check.real("xi", xi, high=0.0, high_open=True)
    stop = check.real("stop", stop, low=0.0, high=1.0, low_open=True)
    max_sweeps = check.integer("max_sweeps", max_sweeps, low=1)
    sampler = check.choice("sampler", sampler, SAMPLERS)
    schedule = check.choice("schedule", schedule, SCHEDULES)
    t0 = check.real("t0", t0, low=0.0, low_open=True)
    t_end = check.real("t_end", t_end, low=0.0, low_open=schedule == "geometric", high=t0)
    proposals = check.integer("proposals", proposals, low=1)
    proposal = check.choice("proposal", proposal, PROPOSALS)
    variant = DEFAULT_VARIANT[relaxation] if variant is None else VARIANT_ALIASES.get(variant, variant)
    variant = check.choice("variant", variant, VARIANTS)
    segmented = check.choice("segmented", segmented, SEGMENTED_MODES)
    if variant == "coherent":
        if heuristic not in npmrf_coherent.CANDIDATE_HEURISTICS:
            check.fail(f"variant 'coherent' ranks candidates by an objective: use heuristic ML_H2b or "
                       f"ML_H2a, or variant 'sharp' or 'literal' for {heuristic}")
        if toroidal_exemplar:
            check.fail("variant 'coherent' does not wrap exemplar patches; drop toroidal_exemplar or "
                       "use variant 'sharp' or 'literal'")
    rule = VARIANTS[variant]
    overrides = {}
    for name, value, low in (("bandwidth", bandwidth, 0.0), ("centre_bandwidth", centre_bandwidth, 0.0),
                             ("tau", tau, 0.0)):
        if value is not None:
            overrides[name] = check.real(name, value, low=low, low_open=True)
    for name, value in (("adaptive", adaptive), ("histogram_weight", histogram_weight)):
        if value is not None:
            overrides[name] = check.real(name, value, low=0.0)
    if outlier is not None:
        overrides["outlier"] = check.real("outlier", outlier, low=0.0, high=1.0, high_open=True)
    if decision is not None:
        overrides["decision"] = check.choice("decision", decision, DECISIONS)
    rule = dataclasses.replace(rule, **overrides)
    if rule.decision == "sample" and heuristic in ("ML_H1a", "ML_H1b"):
        check.fail(f"decision 'sample' needs a heuristic with an objective (ML_H2a, ML_H2b); "
                   f"{heuristic} is defined by per-view argmax searches: use decision='argmax'")
    if grey_levels is not None:
        grey_levels = check.integer("grey_levels", grey_levels, low=2, high=65536)
    if palette is not None:
        palette = check.integer("palette", palette, low=2, high=65536)
    if seed is not None:
        seed = check.integer("seed", seed, low=0)
    return SynthesisConfig(
        size=dims, window=window, levels=levels, heuristic=heuristic, relaxation=relaxation,
        views=views, upsample=upsample, inherit=inherit, xi=xi, stop=stop, max_sweeps=max_sweeps,
        sampler=sampler, schedule=schedule, t0=t0, t_end=t_end, proposals=proposals,
        proposal=proposal, variant=variant, segmented=segmented, rule=rule, grey_levels=grey_levels,
        palette=palette, toroidal_exemplar=bool(toroidal_exemplar), seed=seed,
    )


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
    levels : int
        Number of pyramid levels (the paper's "scales").
    heuristic : {"ML_H1a", "ML_H1b", "ML_H2a", "ML_H2b"}
    relaxation : {"icm", "anneal"}
        ICM with per-voxel temperatures, or simulated annealing with one global temperature
        (:mod:`npmrf3d.model.relax.anneal`; needs ML_H2a or ML_H2b).
    views : sequence of {"front", "right", "top"} (or a comma-separated string)
        Constrained views; see :mod:`npmrf3d.model.neighbourhood` for the axis mapping.
    exemplars : dict view -> exemplar, optional
        A different exemplar for some views.
    upsample : {"1/8", "8/8"} or None
        How a level initialises the next finer one (docs/model.md, section 7); None: the paper's
        choice, ``1/8`` for ICM and ``8/8`` for annealing.
    inherit : {"resynth", "fixed"}
        Whether inherited voxels may still change (their temperature stays 0 either way).
    xi : float < 0
        ICM cooling step.
    stop : float in (0, 1]
        Stop a level once the global temperature fell by this fraction (1: down to 0).
    max_sweeps : int
        Hard limit of sweeps per level.
    sampler : {"heat-bath", "metropolis"}
        Annealing: a heat-bath draw from the tempered objective over all labels (this
        project's addition, the default: better volumes for the same number of sweeps, see
        docs/quality.md), or the paper's Metropolis proposals.
    schedule : {"geometric", "linear"}
        Annealing: how the global temperature falls from ``t0`` to ``t_end`` within a level.
    t0, t_end : float
        Annealing: first and last temperature of each level (``0 < t_end <= t0``; ``t_end = 0``
        allowed for the linear schedule).
    proposals : int
        Annealing: proposals per voxel per level (one per voxel per sweep).
    proposal : {"exemplar", "labels"}
        Annealing (Metropolis): candidates drawn from the exemplar's values (the paper) or
        uniformly from the label set.
    variant : {"coherent", "sharp", "literal"} or None
        How a voxel decides (:data:`npmrf3d.config.VARIANTS`). None: ``coherent`` for ICM, ``sharp``
        for annealing. ``coherent`` (:mod:`npmrf3d.methods.npmrf_coherent`; docs/model.md, section
        8): each view's Parzen estimate sums over the coherent candidates of every neighbourhood
        containing the voxel, and the voxel copies the best exemplar texel (``window`` at every
        level; the ICM options are not used; ``history`` holds the mean patch energy per iteration).
        With ``relaxation="anneal"`` it draws among its candidates with probability proportional to
        ``exp(score / T)``, ``T`` from ``t0`` to ``t_end`` by ``schedule`` over each level's
        iterations (``sampler``, ``proposals``, ``proposal`` are not used). ``sharp`` (also selected
        by ``default``): the full-Parzen rule chosen by measurement (docs/quality.md, "The levers,
        measured"). ``literal``: the paper word for word.
    segmented : {"auto", "yes", "no"}
        The ``coherent`` variant's preset for segmented exemplars (:data:`npmrf3d.methods.npmrf_coherent.SEGMENTED`:
        window 5 at every level, histogram vote weighting 8, and two pyramids, ``levels`` and
        one fewer, of which :func:`npmrf3d.methods.npmrf_coherent.best_of_pyramids` keeps the one nearer the
        exemplars' two-point correlation; about twice the time). "auto": when the exemplars hold
        at most :data:`npmrf3d.methods.npmrf_coherent.SEGMENTED_MAX_VALUES` grey values together; "no":
        ``window`` and ``levels`` as given. The result's ``stats`` say what ran (docs/volume.md).
    bandwidth, centre_bandwidth, adaptive, decision, tau, histogram_weight, outlier : optional
        Override single fields of the preset (:class:`npmrf3d.config.DecisionRule`).
    grey_levels : int, optional
        Re-quantise the exemplar to this many levels per channel.
    palette : int, optional
        Reduce the exemplar to at most this many colours (k-means).
    toroidal_exemplar : bool
        Let exemplar patches wrap around its borders.
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
    config, generator, per_view = prepare(METHOD, exemplar, exemplars, size=size, rng=rng, options=options)
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


def run(config: SynthesisConfig, per_view: dict[str, np.ndarray], rng: np.random.Generator, *,
        progress: ProgressCallback | None = None, checkpoint: str | Path | None = None,
        t_start: float | None = None) -> SynthesisResult:
    """Run a validated configuration on validated exemplars (the body of :func:`synthesize`).

    This is the ``npmrf`` entry of :data:`npmrf3d.methods.METHODS`.
    """
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
                 t_start: float | None = None) -> SynthesisResult:
    """The NP-MRF sampler in the common method signature (:data:`npmrf3d.methods.METHODS`).

    ``t_start`` (optional, every method accepts it): ``time.perf_counter()`` when the caller
    started, so that ``timings["setup"]`` includes loading the exemplars.
    """
    if config.variant == "coherent":
        return _run_coherent(per_view, config, rng, progress=progress, checkpoint=checkpoint,
                             t_start=t_start)
    return run(config, per_view, rng, progress=progress, checkpoint=checkpoint, t_start=t_start)


def segmented(config: SynthesisConfig, per_view) -> bool:
    """Whether a ``coherent``-variant run uses :data:`npmrf3d.methods.npmrf_coherent.SEGMENTED`: ``segmented``
    "yes", or "auto" and the exemplars (``per_view``: view -> array, before any palette or grey
    levels) are segmented (:func:`npmrf3d.methods.npmrf_coherent.is_segmented`)."""
    if config.segmented == "auto":
        return npmrf_coherent.is_segmented({id(a): a for a in per_view.values()}.values())
    return config.segmented == "yes"


def _coherent_options(config: SynthesisConfig, phases: bool, levels: int) -> npmrf_coherent.CoherentConfig:
    """The coherent sampler's options for a ``coherent``-variant configuration: its window at
    every level (:data:`npmrf3d.methods.npmrf_coherent.SEGMENTED`'s window and histogram vote weighting for a
    segmented exemplar, ``phases`` = :func:`segmented`), ``levels`` levels, its views,
    heuristic, centre bandwidth and outlier share; with relaxation ``anneal`` its temperatures
    ``t0`` to ``t_end`` by ``schedule`` over each level's iterations (a heat-bath draw among
    the candidates; ``sampler``, ``proposals`` and ``proposal`` belong to the full-Parzen
    annealer and are not used)."""
    anneal = config.relaxation == "anneal"
    window = npmrf_coherent.SEGMENTED.window if phases else config.window
    value_weight = npmrf_coherent.SEGMENTED.value_weight if phases else npmrf_coherent.DEFAULTS.value_weight
    return npmrf_coherent.make_coherent_config(
        size=config.size, window=(window,) * levels, levels=levels,
        views=config.views, heuristic=config.heuristic, centre_bandwidth=config.rule.centre_bandwidth,
        outlier=config.rule.outlier, value_weight=value_weight, t0=config.t0 if anneal else 0.0,
        t_end=config.t_end, schedule=config.schedule, seed=config.seed)


def _coherent_runs(config: SynthesisConfig, phases: bool) -> list[npmrf_coherent.CoherentConfig]:
    """The coherent sampler's runs: one, or the segmented preset's pyramids, deepest first."""
    levels = npmrf_coherent.SEGMENTED.pyramids(config.levels) if phases else (config.levels,)
    return [_coherent_options(config, phases, n) for n in levels]


def npmrf_resources(config: SynthesisConfig, per_view):
    """The memory estimate of a run: the coherent sampler's (its pyramids') for the ``coherent``
    variant, the full-Parzen sampler's otherwise."""
    if config.variant == "coherent":
        runs = _coherent_runs(config, segmented(config, per_view))
        return one_after_another(coherent_estimate(options, per_view) for options in runs)
    return npmrf_estimate(config, per_view)


def _run_coherent(per_view, config: SynthesisConfig, rng, *, progress, checkpoint, t_start) -> SynthesisResult:
    """The ``coherent`` variant: :mod:`npmrf3d.methods.npmrf_coherent` with the options of :func:`_coherent_options`
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
    result = npmrf_coherent.best_of_pyramids(per_view, _coherent_runs(config, phases), rng, progress=progress,
                                       checkpoint=checkpoint, t_start=t_start)
    return dataclasses.replace(result, config=config, stats={**result.stats, "segmented": phases})


#: The registry entry of the NP-MRF sampler.
METHOD = SynthesisMethod(
    name="npmrf", run=npmrf_method, make_config=make_config, config_class=SynthesisConfig,
    synthesize=npmrf_synthesize,
    fit=lambda c: {"window": c.window, "levels": c.levels, "toroidal": c.toroidal_exemplar},
    resources=npmrf_resources,
    description="the NP-MRF sampler (Urs, Da Costa and Germain 2014): Parzen LCPDFs of three 2D views, "
                "four heuristics, ICM or annealing",
)
