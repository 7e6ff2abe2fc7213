"""The coherent NP-MRF sampler: the NP-MRF likelihood decided over coherent candidates.

Why one module of over 400 lines: the sampler's configuration (every option a field), its preset
for segmented exemplars and the runs of both belong together.

The paper's model (docs/model.md, sections 2-3) sums each view's Parzen estimate over *all*
exemplar patches; measured on real photographs that makes speckle or blobs (docs/quality.md). Here each
view's estimate sums over the **coherent candidates** instead: every voxel keeps, per view, the
exemplar position it was copied from (:mod:`npmrf3d.model.kcoherence`); each view's neighbourhoods find
their best match among the neighbours' coherent shifts and k-coherence sets (Tong et al. 2002;
Chen and Wang 2010); and every voxel is decided by **all overlapping neighbourhoods that contain
it** -- each votes, through its match, for the texel it would put there, weighted by its IRLS
weight and the position histogram. Among the texels of the heaviest votes the voxel takes the
one with the highest NP-MRF score: per view the Parzen estimate of that colour from the view's
votes (centre kernel ``centre_bandwidth`` times the exemplar's standard deviation, mixed with an
``outlier`` share), combined over views by the heuristic (ML_H2b: product; ML_H2a: minimum).
Urs et al. 2014's per-view argmax heuristics are there too, ICM only: ML_H1a (each view picks
its best candidate; the least confident view's pick is copied) and ML_H1b (the voxel takes the
mean of the views' picks -- a colour the exemplar generally does not have, the averaging
artefact the paper shows; the only rule whose colours are not exemplar colours).

With ``t0 > 0`` the decision is **annealed**: by default (``sampler="heat-bath"``) each voxel
draws among its candidates with probability proportional to ``exp(score / T)`` (``score`` the
ML_H2b log-score with the histogram prior, or the log of ML_H2a's); with
``sampler="metropolis"`` it proposes one candidate uniformly and accepts it if its score is at
least the current colour's, else with probability ``exp((score_new - score_current) / T)``
(docs/model.md, section 5). ``T`` falls from ``t0`` to ``t_end`` over each level's iterations;
``T -> 0`` is the highest score again.

With ``icm=True`` a level runs ICM with per-voxel temperatures instead of ``iterations`` (Urs et
al. 2014; :mod:`npmrf3d.model.kcoherence_icm`): trust-weighted search and votes, only warm
voxels re-decided, cooling by ``xi`` until ``stop`` or ``max_sweeps``, ``upsample`` 1/8 or 8/8 and
``inherit`` as the NP-MRF sampler's.

The search, votes, histograms and level loop are Chen–Wang's (the k-coherence engine,
:mod:`npmrf3d.model.kcoherence_engine`); only the decision differs
(:class:`npmrf3d.model.kcoherence_engine.CandidateDecision`), so a voxel copies an exemplar
texel (colour and source) and the volume's colours are exemplar colours (except ML_H1b's).
Results depend only on the seed, never on the thread count.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .. import _validation as check
from ..analysis.metrics import two_point_shape_error
from ..io.checkpoints import exemplar_digest
from ..config import DEFAULT_SIZE, SynthesisMethod, SynthesisResult
from ..model.kcoherence_engine import (
    CANDIDATE_HEURISTICS,
    CANDIDATE_SAMPLERS,
    COHERENT_HEURISTICS,
    PER_VIEW_HEURISTICS,
    CandidateDecision,
    KCoherenceLevels,
    block_aprons,
)
from ..model.kcoherence_icm import IcmSchedule
from ..model.pyramid import INHERIT, LABEL_UPSAMPLING, run_pyramid
from ..model.relax.anneal import SCHEDULES
from ..resources import coherent_estimate
from . import chen_wang
from ..options import made_from, option, options_of, refusing, same_option, validate
from ._api import prepare

__all__ = ["CANDIDATE_HEURISTICS", "CANDIDATE_SAMPLERS", "COHERENT_HEURISTICS", "METHOD", "SEGMENTED",
           "SEGMENTED_MAX_VALUES", "CoherentConfig", "SegmentedPreset",
           "best_of_pyramids", "coherent_levels", "coherent_synthesize", "icm_schedule", "is_segmented", "make_coherent_config", "run",
           "temperatures", "trial_checkpoint"]

#: An exemplar with at most this many distinct grey values is segmented (a phase image: a
#: thresholded micro-CT slice, a label map; also a 2x2x2-averaged binary scan, 9 values).
SEGMENTED_MAX_VALUES = 16


@dataclass(frozen=True)
class SegmentedPreset:
    """What ``synth``'s coherent default changes for a segmented exemplar (docs/segmented.md,
    "The segmented preset"): chosen on a micro-CT slice (Berea), where the
    photographs' default lost a third to a half of the pores, and checked on five held-out
    slices of four scans (the phase fraction and the 3D correlation shape improve on all).

    ``window``: at every level (the photographs' 7 covers half of the coarsest level's 16 x 16
    exemplar of a 64 x 64 slice); ``value_weight``: the histogram vote weighting (:class:`CoherentConfig`),
    which keeps the phase fractions; ``fewer_levels``: a second run
    with this many fewer pyramid levels (when one level at least is left; 0 = none), and the
    volume kept is the one whose two-point correlation shape is nearer the exemplars'
    (:func:`npmrf3d.analysis.metrics.two_point_shape_error`): the coarsest level builds the large pores
    of one slice and smears the small throats of another, and only the exemplar can tell which
    (docs/segmented.md, "Two pyramids, the better kept"). The preset searches every site
    (:func:`npmrf3d.methods.npmrf_options.coherent_grid`; docs/segmented.md, "The segmented preset").

    ``smoothness``, ``attached``: the smoothness prior (:class:`CoherentConfig`), which joins a
    phase that one slice shows apart into a network through the third dimension (Berea's pore
    diffusivity from one slice: 5-71 % under the scan's crops without it; benchmarks/bench_materials.py).
    """

    window: int = 5
    value_weight: float = 8.0
    fewer_levels: int = 1
    smoothness: float = 3.0
    attached: bool = True

    def changes(self) -> dict:
        """What the preset sets of the coherent sampler's options: its fields named as options of
        :class:`CoherentConfig`.

        >>> SEGMENTED.changes()
        {'window': 5, 'value_weight': 8.0, 'smoothness': 3.0, 'attached': True}
        """
        names = options_of(CoherentConfig)
        return {name: value for name, value in asdict(self).items() if name in names}

    def pyramids(self, levels: int) -> tuple[int, ...]:
        """The level counts the preset runs, in order: ``levels``, and ``levels - fewer_levels``
        when at least one level is left.

        >>> SEGMENTED.pyramids(3), SEGMENTED.pyramids(1)
        ((3, 2), (1,))
        """
        fewer = levels - self.fewer_levels
        return (levels, fewer) if self.fewer_levels and fewer >= 1 else (levels,)


SEGMENTED = SegmentedPreset()


def is_segmented(exemplars) -> bool:
    """Whether the exemplars (arrays ``(H, W[, C])``) hold at most :data:`SEGMENTED_MAX_VALUES`
    distinct grey values (the mean over channels) together. Each exemplar's values are counted
    once (:func:`_grey_values`), however often a run asks.

    >>> is_segmented([np.tile([0.0, 1.0], (4, 2))]), is_segmented([np.linspace(0, 1, 64).reshape(8, 8)])
    (True, False)
    """
    counted = [_grey_values(a) for a in exemplars]
    return None not in counted and len(frozenset().union(*counted)) <= SEGMENTED_MAX_VALUES


#: The distinct grey values of the exemplars counted lately, by :func:`exemplar_digest` (a run
#: asks for its memory estimate, the command line's window check and the run itself).
_COUNTED: dict[str, frozenset | None] = {}


def _grey_values(a) -> frozenset | None:
    """The distinct grey values of exemplar ``a``; None above :data:`SEGMENTED_MAX_VALUES`."""
    a = np.asarray(a, dtype=np.float32)
    key = exemplar_digest(a)
    if key not in _COUNTED:
        grey = np.unique(a.mean(axis=-1) if a.ndim == 3 else a)
        if len(_COUNTED) >= 16:
            del _COUNTED[next(iter(_COUNTED))]
        _COUNTED[key] = frozenset(grey.tolist()) if len(grey) <= SEGMENTED_MAX_VALUES else None
    return _COUNTED[key]


def _annealed(config) -> bool:
    return config.t0 > 0


def _icm(config) -> bool:
    return config.icm


def _iterated(config) -> bool:
    return not config.icm


_CWC = chen_wang.ChenWangConfig


@dataclass(frozen=True)
class CoherentConfig:
    """A validated coherent NP-MRF run; every option and its default is a field here (the
    coherence options are Chen–Wang's, :class:`npmrf3d.methods.chen_wang.ChenWangConfig`)."""

    size: tuple[int, int, int] = same_option(_CWC, "size")
    window: tuple[int, ...] = same_option(_CWC, "window", help="window side per level, coarsest first: "
                                          "one number or one per level")
    levels: int = same_option(_CWC, "levels")
    views: tuple[str, ...] = same_option(_CWC, "views")
    iterations: tuple[int, ...] = same_option(_CWC, "iterations", applies=_iterated, needs="icm is not set")
    grid: int = same_option(_CWC, "grid")
    heuristic: str = option("ML_H2b", "how the views' estimates decide: ML_H2b (product) or ML_H2a (minimum); "
                            "ML_H1a, ML_H1b (per-view picks) with --t0 0 only", kind="choice",
                            choices=lambda: COHERENT_HEURISTICS)
    centre_bandwidth: float = option(0.1, "width of the Parzen kernel on candidate colours, as a factor of "
                                     "the exemplar's standard deviation", kind="real", low=0.0, low_open=True)
    outlier: float = option(0.01, "share of a uniform term mixed into each view's estimate", kind="real",
                            low=0.0, high=1.0, high_open=True)
    smoothness: float = option(0.0, "strength of a prior for colours that agree with the voxel's six face "
                               "neighbours (0 = none): continues a phase's runs along every axis", kind="real", low=0.0)
    attached: bool = option(False, "the smoothness prior sees the minority phase's pieces apart from its largest "
                            "as the majority phase: draws the phase towards its network", kind="flag",
                            applies=lambda c: c.smoothness > 0, needs="smoothness is above 0")
    feature_weight: float = option(0.0, "weight of the line-distance channel; 0 = colours alone", kind="real", low=0.0)
    k: int = same_option(_CWC, "k")
    index_weight: float = same_option(_CWC, "index_weight")
    position_weight: float = same_option(_CWC, "position_weight")
    position_boost: float = same_option(_CWC, "position_boost")
    random_candidates: int = same_option(_CWC, "random_candidates")
    global_share: float = same_option(_CWC, "global_share")
    coherence_bias: float = same_option(_CWC, "coherence_bias")
    # measured (docs/quality.md, "Value histograms"): the histogram prior alone keeps hubble's spots and leaves
    # gravel as it was; the vote weighting (Chen–Wang's default) cost gravel's grain here
    value_weight: float = same_option(_CWC, "value_weight", 0.0)
    value_prior: float = same_option(_CWC, "value_prior", 5.0)
    value_bins: int = same_option(_CWC, "value_bins")
    phase_weight: float = same_option(_CWC, "phase_weight", 0.0)
    # annealing over the candidates: t0 = 0 decides by the highest score (ICM)
    t0: float = option(0.0, "annealing: first temperature of each level; each voxel draws among its "
                       "candidates ~ exp(score / T) (0 = no annealing: the highest score decides)",
                       kind="real", low=0.0, group="relaxation")
    t_end: float = option(0.05, "annealing: last temperature of each level, at most --t0", kind="real",
                          group="relaxation", applies=_annealed, needs="t0 is above 0")
    schedule: str = option("geometric", "annealing: how the temperature falls from --t0 to --t-end",
                           kind="choice", choices=lambda: SCHEDULES, group="relaxation",
                           applies=_annealed, needs="t0 is above 0")
    sampler: str = option("heat-bath", "annealing: heat-bath (draw among the candidates ~ exp(score / T)) "
                          "or metropolis (propose one, accept by the Metropolis rule)", kind="choice",
                          choices=lambda: CANDIDATE_SAMPLERS, group="relaxation", applies=_annealed,
                          needs="t0 is above 0")
    # ICM with per-voxel temperatures (Urs et al. 2014; model.kcoherence_icm) instead of the
    # fixed iterations (then unused): a level's sweeps stop by `stop` or `max_sweeps`
    icm: bool = option(False, "ICM with per-voxel temperatures (Urs et al. 2014) instead of --iterations",
                       kind="flag", group="relaxation")
    xi: float = option(IcmSchedule.xi, "icm: cooling step (more negative cools faster)", kind="real",
                       high=0.0, high_open=True, group="relaxation", applies=_icm, needs="icm is set")
    stop: float = option(IcmSchedule.stop, "icm: stop a level once the global temperature fell by this "
                         "fraction (1 = down to 0)", kind="real", low=0.0, high=1.0, low_open=True,
                         group="relaxation", applies=_icm, needs="icm is set")
    max_sweeps: int = option(IcmSchedule.max_sweeps, "icm: most sweeps per level", kind="int", low=1,
                             group="relaxation", applies=_icm, needs="icm is set")
    upsample: str = option(IcmSchedule.upsample, "icm: the 7 non-inherited children of a voxel copy its "
                           "shifted source (8/8) or get random sources (1/8)", kind="choice",
                           choices=lambda: LABEL_UPSAMPLING, group="relaxation", applies=_icm,
                           needs="icm is set")
    inherit: str = option(IcmSchedule.inherit, "icm: inherited voxels may still change (resynth) or are "
                          "frozen (fixed)", kind="choice", choices=lambda: INHERIT, group="relaxation",
                          applies=_icm, needs="icm is set")
    # block-local (Chen–Wang's fields): the finer levels read a pilot block's histograms, any
    # block can be made alone
    blockwise: bool = same_option(_CWC, "blockwise")
    pilot: int = same_option(_CWC, "pilot")
    whole_voxels: int = same_option(_CWC, "whole_voxels")
    seed: int | None = same_option(_CWC, "seed")

    def to_dict(self) -> dict:
        """Plain JSON-able dictionary."""
        return asdict(self)


DEFAULTS = CoherentConfig()
#: The options the coherent sampler takes from Chen–Wang's configuration, as they are.
_SHARED = tuple(name for name in options_of(chen_wang.ChenWangConfig) if name in options_of(CoherentConfig))


@made_from(CoherentConfig)
def make_coherent_config(values: dict) -> CoherentConfig:
    """Validate keyword arguments, one per option of :class:`CoherentConfig`, into a frozen
    :class:`CoherentConfig` (the shared coherence fields are validated as Chen–Wang's, the others
    by their fields' limits). ML_H1a and ML_H1b are ICM-only: with ``t0 > 0`` they are refused."""
    cw = chen_wang.make_chen_wang_config(**{name: values[name] for name in _SHARED})
    own = {name: validate(CoherentConfig, name, values[name]) for name in options_of(CoherentConfig)
           if name not in _SHARED and name != "t_end"}
    heuristic, t0 = own["heuristic"], own["t0"]
    if t0 > 0.0 and heuristic in PER_VIEW_HEURISTICS:
        check.fail(f"heuristic {heuristic} cannot be annealed (t0 > 0): ML_H1a and ML_H1b are ICM-only "
                   f"per-view argmax rules with no score to draw by; use t0 = 0, or ML_H2b or ML_H2a")
    t_end = values["t_end"]
    if t0 > 0.0:
        t_end = check.real("t_end", t_end, low=0.0, low_open=own["schedule"] == "geometric", high=t0)
    if own["icm"] and cw.blockwise:
        check.fail("icm=True cannot run blockwise: its stop rule reads every voxel's temperature; "
                   "use icm=False (the fixed iterations) or blockwise=False")
    if own["icm"] and t0 > 0.0:
        check.fail(f"icm=True and t0={t0:g} are two relaxations: ICM decides by the highest score "
                   "(set t0=0), annealing runs the fixed iterations (set icm=False)")
    return CoherentConfig(**own, t_end=float(t_end), **{name: getattr(cw, name) for name in _SHARED})


def _chen_wang_config(config: CoherentConfig) -> chen_wang.ChenWangConfig:
    """The Chen–Wang configuration within a validated ``config`` (its shared fields, already
    validated as Chen–Wang's: made as it is, not checked again)."""
    return chen_wang.ChenWangConfig(**{name: getattr(config, name) for name in _SHARED})


def temperatures(config: CoherentConfig) -> tuple[tuple[float, ...], ...]:
    """The annealing temperatures of a run: per level (coarsest first), one per iteration, from
    ``t0`` to ``t_end`` by ``schedule``; all 0 (the highest score decides) when ``t0`` is 0.

    Examples
    --------
    >>> temperatures(make_coherent_config(size=32, levels=2, window=5, iterations=(3, 2), t0=1.0, t_end=0.01))
    ((1.0, 0.1, 0.01), (1.0, 0.01))
    """
    if config.t0 == 0.0:
        return tuple((0.0,) * n for n in config.iterations)
    return tuple(tuple(float(t) for t in SCHEDULES[config.schedule](config.t0, config.t_end, n))
                 for n in config.iterations)


def icm_schedule(config: CoherentConfig) -> IcmSchedule | None:
    """The ICM options of a run with ``icm=True``; None without."""
    if not config.icm:
        return None
    return IcmSchedule(config.xi, config.stop, config.max_sweeps, config.upsample, config.inherit)


def coherent_levels(config: CoherentConfig, per_view: Mapping[str, np.ndarray]) -> KCoherenceLevels:
    """The k-coherence engine of a run: deciding by the NP-MRF rule (annealed by the
    configuration's temperatures, or ICM's per-voxel temperatures with ``icm``)."""
    decision = CandidateDecision(config.heuristic, config.centre_bandwidth, config.outlier,
                                 None if config.icm else temperatures(config), config.sampler, config.smoothness,
                                 config.attached)
    return KCoherenceLevels("coherent", _chen_wang_config(config), per_view, decision, icm_schedule(config),
                            config.feature_weight)


def run(per_view: Mapping[str, np.ndarray], config: CoherentConfig, rng: np.random.Generator, *,
        progress=None, checkpoint: str | Path | None = None, t_start: float | None = None,
        region=None) -> SynthesisResult:
    """Run a validated configuration on validated float32 ``(H, W, C)`` exemplars (one per view,
    each checked against every level's window): the k-coherence engine
    (:class:`npmrf3d.model.kcoherence_engine.KCoherenceLevels`) deciding by the NP-MRF rule. The
    body of :func:`coherent_synthesize` and the registered method (:data:`npmrf3d.methods.METHODS`);
    ``region`` (a ``blockwise`` configuration): one block from its dependency cone."""
    t_start = time.perf_counter() if t_start is None else t_start
    chen_wang._check_exemplar_levels(_chen_wang_config(config), per_view)
    levels = coherent_levels(config, per_view)
    out = run_pyramid(levels, rng, progress=progress, checkpoint=checkpoint, t_start=t_start, region=region)
    return SynthesisResult(volume=levels.colours(out.state.volume), history=out.history, config=config,
                           timings=out.timings, labels=levels.labels, stats=out.stats)


def coherent_synthesize(exemplar=None, *, size=DEFAULT_SIZE, rng=None, progress=None,
                        checkpoint: str | Path | None = None, exemplars: Mapping | None = None,
                        **options) -> SynthesisResult:
    """Synthesize a solid texture with the coherent NP-MRF sampler.

    ``options`` are the fields of :class:`CoherentConfig` (``size``, ``window``, ``levels``,
    ``views``, ``iterations``, ``heuristic``, ``centre_bandwidth``, ``outlier``, ``k``,
    ``index_weight``, ``position_weight``, ``position_boost``, ``random_candidates``); ``rng`` a
    seed or Generator (the result depends on it only).

    Examples
    --------
    >>> import numpy as np
    >>> stripes = np.tile(np.array([0, 0, 1, 1], dtype=np.uint8) * 255, (16, 4))
    >>> res = coherent_synthesize(stripes, size=8, window=4, levels=1, iterations=2, rng=0)
    >>> res.volume.shape, sorted(np.unique(res.volume).tolist())
    ((8, 8, 8, 1), [0.0, 1.0])
    """
    t_start = time.perf_counter()
    config, generator, per_view = prepare(METHOD, exemplar, exemplars, size=size, rng=rng,
                                          progress=progress, checkpoint=checkpoint, options=options)
    return run(per_view, config, generator, progress=progress, checkpoint=checkpoint, t_start=t_start)


def coherent_aprons(config: CoherentConfig, per_view=None) -> tuple[int, ...] | None:
    """Per level, how far a ``blockwise`` run reaches (:func:`npmrf3d.model.kcoherence_engine.block_aprons`)."""
    return block_aprons(config, icm_schedule(config))


def trial_checkpoint(checkpoint: str | Path | None, index: int, levels: int) -> Path | None:
    """The checkpoint file of pyramid ``index`` (0 first) of :func:`best_of_pyramids`, which has
    ``levels`` levels: ``checkpoint`` itself for the first, ``NAME.levelsL.SUFFIX`` beside it
    for the others (each pyramid resumes from its own).

    >>> str(trial_checkpoint("out/run.npz", 1, 2))
    'out/run.levels2.npz'
    """
    if checkpoint is None or index == 0:
        return None if checkpoint is None else Path(checkpoint)
    path = Path(checkpoint)
    return path.with_name(f"{path.stem}.levels{levels}{path.suffix}")


def best_of_pyramids(per_view, configs, rng: np.random.Generator, *, progress=None, checkpoint=None,
                     t_start=None) -> SynthesisResult:
    """Run :func:`run` with each configuration in turn (pyramids of different depth:
    the segmented preset's ``levels`` and ``levels - SEGMENTED.fewer_levels``) and keep the
    volume whose :func:`npmrf3d.analysis.metrics.two_point_shape_error` against the exemplars is lowest
    (the first on ties; the isotropic reference, since a scanned material is judged by its 3D
    statistics, the same along every axis). One configuration: that run alone.

    The pyramids draw on ``rng`` in turn, so the result depends on its seed only; each has its
    own checkpoint (:func:`trial_checkpoint`). ``stats["levels_kept"]`` holds the kept volume's
    levels and, with several pyramids, ``stats["level_trials"]`` each one's levels, error and
    seconds; ``timings["total"]`` covers them all. A ``progress`` callback with a ``note(text)``
    method is told when each pyramid starts and which was kept.
    """
    configs = list(configs)
    several = len(configs) > 1
    note = getattr(progress, "note", None) if several else None  # the callback's optional hook
    results, errors = [], []
    for index, config in enumerate(configs):
        if note is not None:
            note(f"segmented exemplar: pyramid {index + 1} of {len(configs)}, "
                 f"{config.levels} level{'s' * (config.levels != 1)}")
        results.append(run(per_view, config, rng, progress=progress, t_start=t_start,
                           checkpoint=trial_checkpoint(checkpoint, index, config.levels)))
        if several:
            errors.append(two_point_shape_error({v: per_view[v] for v in config.views},
                                                results[-1].volume, reference="isotropic"))
    best = int(np.argmin(errors)) if several else 0
    kept = configs[best].levels
    stats = {**results[best].stats, "levels_kept": kept}
    if several:
        others = " against ".join(f"{e:.3g}" for i, e in enumerate(errors) if i != best)
        if note is not None:
            note(f"kept the {kept}-level volume (two-point shape error against the exemplar "
                 f"{errors[best]:.3g} against {others})")
        ends = [r.timings["total"] for r in results]
        stats["level_trials"] = [{"levels": c.levels, "two_point_shape_error": e,
                                  "seconds": end - (ends[i - 1] if i else 0.0)}
                                 for i, (c, e, end) in enumerate(zip(configs, errors, ends))]
    timings = {**results[best].timings, "total": results[-1].timings["total"]}
    return dataclasses.replace(results[best], stats=stats, timings=timings)


METHOD = SynthesisMethod(
    name="coherent", run=run, make_config=refusing(make_coherent_config, CoherentConfig),
    config_class=CoherentConfig, synthesize=coherent_synthesize, fit=chen_wang._fit,
    description="the coherent NP-MRF sampler: the NP-MRF likelihood over k-coherent candidates",
    resources=coherent_estimate,
    aprons=coherent_aprons,
)
