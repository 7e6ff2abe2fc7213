"""Frozen run configurations and the result object.

A :class:`SynthesisConfig` is what an NP-MRF run was asked to do, after validation: it is stored
in ``run.json``, compared by the tests and rebuilt by the CLI. The sampler's estimator supports
are :data:`SUPPORTS`; the full support's decision rules by name are :data:`PRESETS` (``paper``,
Urs et al. 2014 word for word, the ablation baseline; ``tuned``, chosen by measurement,
``benchmarks/bench_quality.py``, ``docs/quality.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from .model import heuristics, pyramid
from .model.relax import RELAXATIONS, AnnealOptions, IcmOptions
from .model.relax.anneal import PROPOSALS, SAMPLERS, SCHEDULES
from .options import option

#: Side of the cube made when no size is given (API and command line, every method).
DEFAULT_SIZE = 64

__all__ = ["APPLIES", "COHERENT_RULE", "TEMPERATURE_OPTIONS", "applies", "DEFAULT_SIZE", "DecisionRule", "PRESETS", "SUPPORTS", "SynthesisConfig",
           "SynthesisMethod", "SynthesisResult", "VARIANTS"]


#: How ``--help`` states the default of a decision-rule option: the support's rule decides.
_PRESET_VALUE = "--preset's"


def _registry(name: str):
    """A registry of the model by name (read when ``--help`` or a check first needs it)."""
    return tuple(getattr(heuristics, name, None) or getattr(pyramid, name))


#: The combinations (support, relaxation) that use an option, for the options that some
#: combinations cannot use (every other option applies everywhere): entered by each such field
#: itself (:func:`_in_table`), in the fields' order.
APPLIES: dict[str, tuple[tuple[str, str], ...]] = {}
#: The options that support ``coherent`` with ICM uses only with per-voxel temperatures (without
#: them every voxel is re-decided in each of a level's iterations and children copy 8/8).
TEMPERATURE_OPTIONS = ("xi", "stop", "max_sweeps", "inherit")


def applies(name: str, where: tuple) -> bool:
    """Whether option ``name`` changes the result of the combination ``where``, a (support,
    relaxation) pair or the (support, relaxation, temperatures) of :func:`combination`."""
    if name in TEMPERATURE_OPTIONS and len(where) > 2 and where[:2] == ("coherent", "icm"):
        return bool(where[2])
    return name not in APPLIES or tuple(where[:2]) in APPLIES[name]


def _in_table(name: str, where: tuple[tuple[str, str], ...], needs: str | None) -> dict:
    """Enter option ``name`` in :data:`APPLIES` as used by the (support, relaxation) pairs
    ``where`` only, and give its field the ``applies`` (from that table) and the ``needs`` text
    that go with it; ``needs`` None: the table's entry only (the field is always recorded)."""
    APPLIES[name] = where

    def read(config) -> bool:
        return applies(name, (config.support, config.relaxation, config.temperatures))
    return {} if needs is None else {"applies": read, "needs": needs}


_FULL = (("full", "icm"), ("full", "anneal")), "support is full"
_COHERENT = (("coherent", "icm"), ("coherent", "anneal")), "support is coherent"
_ANNEAL = (("full", "anneal"), ("coherent", "anneal")), "relaxation is anneal"
_TEMPERED = (("full", "icm"), ("coherent", "icm")), "temperatures is set (relaxation icm)"


@dataclass(frozen=True)
class DecisionRule:
    """How a visited voxel picks its value (docs/model.md, sections 2 and 8).

    Attributes
    ----------
    bandwidth : float
        Neighbour bandwidth as a factor of ``h_opt`` (used when ``adaptive == 0``).
    centre_bandwidth : float
        Centre-value bandwidth ``h_c`` as a factor of ``h_opt`` (1.0 = the paper's single h).
    adaptive : float
        If > 0, the neighbour bandwidth is set per site and view to
        ``2 h^2 = adaptive * D_min`` (relative tolerance around the best-matching patch).
    decision : {"argmax", "sample"}
        ``argmax`` is the paper's ICM; ``sample`` draws from ``exp(score / tau)``.
    tau : float
        Temperature of the ``sample`` decision.
    histogram_weight : float
        Weight of a histogram penalty ``-w * max(0, log(q_k / e_k))`` on labels that the volume
        already over-uses relative to the exemplar (0 = off, the paper).
    outlier : float
        Weight of a uniform term mixed into each view's LCPDF before ML_H2a/ML_H2b combine the
        views (a robust product of experts; 0 = off, the paper).
    """

    bandwidth: float = option(1.0, "support full: neighbour bandwidth / h_opt", kind="real",
                              low=0.0, low_open=True, decided=_PRESET_VALUE, metavar="B",
                              **_in_table('bandwidth', *_FULL))
    centre_bandwidth: float = option(1.0, "centre-value bandwidth / h_opt (or / sigma)", kind="real", low=0.0,
                                     low_open=True, decided=_PRESET_VALUE, metavar="B")
    adaptive: float = option(0.0, "support full: 2h^2 = A * best distance", kind="real", low=0.0,
                             decided=_PRESET_VALUE, metavar="A",
                             **_in_table('adaptive', *_FULL))
    decision: str = option("argmax", "support full: argmax, or sample exp(score/tau)",
                           kind="choice", choices=lambda: _registry("DECISIONS"),
                           decided=_PRESET_VALUE,
                           **_in_table('decision', *_FULL))
    tau: float = option(1.0, "support full: temperature of sample", kind="real", low=0.0,
                        low_open=True, decided=_PRESET_VALUE, metavar="T",
                        **_in_table('tau', *_FULL))
    histogram_weight: float = option(0.0, "support full: over-used label penalty",
                                     kind="real", low=0.0, decided=_PRESET_VALUE, metavar="W",
                                     **_in_table('histogram_weight', *_FULL))
    outlier: float = option(0.0, "uniform share in each view's estimate",
                            kind="real", low=0.0, high=1.0, high_open=True,
                            decided=_PRESET_VALUE, metavar="A")


#: The estimator supports: which exemplar neighbourhoods a view's Parzen sum runs over
#: (docs/model.md, section 8): ``coherent`` candidates (the default, chosen by measurement,
#: docs/quality.md) or ``full``, every exemplar patch (Urs et al. 2014).
SUPPORTS = ("coherent", "full")

#: The full-Parzen support's decision rules by name: ``paper`` is Urs et al. 2014 word for word
#: (the ablation baseline; it collapses to flat volumes on photographs, docs/full_parzen.md),
#: ``tuned`` the sharpened bandwidths, sampled decision, histogram penalty and outlier share
#: chosen by measurement (docs/full_parzen.md, "The levers").
PRESETS: dict[str, DecisionRule] = {
    "paper": DecisionRule(),
    "tuned": DecisionRule(
        bandwidth=0.2, centre_bandwidth=0.1, adaptive=0.0, decision="sample", tau=0.1,
        histogram_weight=8.0, outlier=0.01,
    ),
}
#: The coherent support's rule: ``centre_bandwidth`` is a factor of the exemplar's standard
#: deviation and ``outlier`` the uniform share of each view's estimate (its other fields unused).
COHERENT_RULE = DecisionRule(centre_bandwidth=0.1, outlier=0.01)

#: ``variant``, the older single name of a support and a preset, still accepted:
#: name -> (support, preset).
VARIANTS: dict[str, tuple[str, str]] = {
    "coherent": ("coherent", "tuned"),
    "sharp": ("full", "tuned"),
    "default": ("full", "tuned"),
    "literal": ("full", "paper"),
}
#: ``segmented``: whether the coherent support uses its preset for segmented exemplars
#: (:data:`npmrf3d.methods.npmrf_coherent.SEGMENTED`): "auto" when the exemplars hold few grey values.
SEGMENTED_MODES = ("auto", "yes", "no")


@dataclass(frozen=True)
class SynthesisConfig:
    """A validated NP-MRF synthesis run (see :func:`npmrf3d.synthesize` for the meaning).

    ``xi``, ``stop`` and ``max_sweeps`` drive ICM (:class:`npmrf3d.model.relax.IcmOptions`);
    ``sampler`` ... ``proposal`` drive annealing (:class:`npmrf3d.model.relax.AnnealOptions`). Both
    sets stay flat fields here so that ``run.json`` records and checkpoints keep their layout;
    their defaults come from the two options classes, and :attr:`relaxation_options` gives the
    chosen relaxation's own options.
    """

    size: tuple[int, int, int] = option(help="output size", kind="own")
    window: int = option(7, "side of each view's square neighbourhood, odd, 3 to 15",
                         kind="int", metavar="W", group="volume and pyramid")
    # None: decided from the exemplar and the volume (methods.npmrf_options.pyramid_levels)
    levels: int | None = option(None, "pyramid levels (scales), 1 to 8", kind="int", low=1, high=8,
                                optional=True, metavar="L", group="volume and pyramid",
                                decided="3; one more per doubling of both the exemplar and the volume "
                                        "beyond 64")
    heuristic: str = option("ML_H2b", "how the views' estimates combine: ML_H2b product, ML_H2a minimum, "
                            "ML_H1a/ML_H1b per-view argmax",
                            kind="choice", choices=lambda: _registry("HEURISTICS"))
    relaxation: str = option("icm", "icm, or anneal (simulated annealing)",
                             kind="choice", choices=lambda: tuple(RELAXATIONS))
    views: tuple[str, ...] = option(("front", "right", "top"), "constrained views", kind="own")
    upsample: str = option("1/8", "a voxel starts 1 or all 8 of its children", kind="choice",
                           choices=lambda: _registry("UPSAMPLING"), group="volume and pyramid",
                           decided="8/8; support full with icm: 1/8")
    inherit: str = option("resynth", "inherited voxels may change (resynth) or stay (fixed)",
                          kind="choice", choices=lambda: _registry("INHERIT"),
                          group="volume and pyramid",
                          **_in_table('inherit', (("full", "icm"), ("full", "anneal"), ("coherent", "icm")),
                                     "temperatures is set, or support is full"))
    xi: float = option(IcmOptions.xi, "icm: cooling step, < 0", kind="real",
                       high=0.0, high_open=True, decided="-1; support full: -3",
                       **_in_table('xi', *_TEMPERED))
    stop: float = option(IcmOptions.stop, "icm: a level stops when its temperature fell by F",
                         kind="real", low=0.0, high=1.0, low_open=True, metavar="F",
                         **_in_table('stop', *_TEMPERED))
    max_sweeps: int = option(IcmOptions.max_sweeps, "icm: most sweeps per level", kind="int", low=1,
                             **_in_table('max_sweeps', *_TEMPERED))
    sampler: str = option(AnnealOptions.sampler, "anneal: heat-bath or metropolis (the paper)", kind="choice",
                          choices=lambda: SAMPLERS, decided="metropolis; support full: heat-bath",
                          **_in_table('sampler', *_ANNEAL))
    schedule: str = option(AnnealOptions.schedule, "anneal: temperature from --t0 to --t-end",
                           kind="choice", choices=lambda: SCHEDULES,
                           **_in_table('schedule', *_ANNEAL))
    t0: float = option(AnnealOptions.t0, "anneal: a level's first temperature", kind="real", low=0.0,
                       low_open=True, metavar="T",
                       **_in_table('t0', *_ANNEAL))
    t_end: float = option(AnnealOptions.t_end, "anneal: a level's last temperature, <= t0",
                          kind="real", low=0.0, metavar="T",
                          **_in_table('t_end', *_ANNEAL))
    proposals: int = option(AnnealOptions.proposals, "anneal: sweeps per level",
                            kind="int", low=1, metavar="P",
                            **_in_table('proposals', *_ANNEAL))
    proposal: str = option(AnnealOptions.proposal,
                           "anneal, metropolis, support full: proposals from the exemplar or the labels",
                           kind="choice",
                           choices=lambda: PROPOSALS,
                           **_in_table('proposal', (("full", "anneal"),), "support is full (relaxation anneal)"))
    support: str = option("coherent", "estimates over coherent candidates or every patch (full)",
                          kind="choice", choices=lambda: SUPPORTS,
                          decided="coherent")
    preset: str = option("tuned", "support full: the decision rule",
                         kind="choice", choices=lambda: tuple(PRESETS),
                         decided="tuned",
                         **_in_table('preset', *_FULL))
    segmented: str = option("auto", "support coherent: the preset for segmented exemplars", kind="choice",
                            choices=lambda: SEGMENTED_MODES,
                            **_in_table('segmented', *_COHERENT))
    rule: DecisionRule = option(help="decision rule", kind="nested", default_factory=DecisionRule)
    grey_levels: int | None = option(None, "re-quantise each channel to K levels",
                                     kind="int", low=2, high=65536, optional=True, metavar="K",
                                     group="views and exemplars", decided="keep the values")
    palette: int | None = option(None, "at most K colours (k-means)",
                                 kind="int", low=2, high=65536, optional=True, metavar="K",
                                 group="views and exemplars", decided="keep every colour")
    toroidal_exemplar: bool = option(False, "support full: exemplar patches wrap around",
                                     kind="flag", group="views and exemplars",
                                     **_in_table('toroidal_exemplar', *_FULL))
    temperatures: bool = option(False, "icm with per-voxel temperatures (Urs et al. 2014)",
                                kind="flag", decided="with support full",
                                **_in_table('temperatures', _TEMPERED[0], None))
    blockwise: bool = option(False, "the block-local sampler (docs/blocks.md)", kind="flag", group="blocks")
    # blockwise: levels of at most this many voxels run whole, once for all blocks (256^3: the
    # cones of blocks of 128 at 512^3 would repeat its 256^3 level 8.8 times over)
    whole_voxels: int = option(2 ** 24, "--blockwise: levels of at most N voxels run whole, once",
                               kind="int", low=1, group="blocks", applies=lambda config: config.blockwise,
                               needs="blockwise is set")
    # the coherent sampler's phase control (docs/materials.md, "Phase control in the default"):
    # on scan slices the minority phase keeps its share and the two-point correlation shape
    # comes nearer the scans' crops; photographs' quality unchanged (docs/quality.md)
    phase_weight: float = option(16.0, "support coherent: phase control (0 = off)", kind="real", low=0.0,
                                 metavar="W", decided="16; support full: 0",
                                 **_in_table('phase_weight', *_COHERENT))
    # the coherent sampler's line-distance channel (npmrf3d.model.features, docs/quality.md "The
    # line-distance channel"): continuous dark lines on block walls, grainier stochastic textures
    feature_weight: float = option(0.0, "support coherent: weight of a channel of the distance to thin "
                                   "dark lines, matched with the colours (0 = colours alone)", kind="real",
                                   low=0.0, **_in_table('feature_weight', *_COHERENT))
    # support coherent: neighbourhoods searched and voting every `grid` voxels along both plane axes;
    # None: the run's own (methods.npmrf_options.coherent_grid: 2 on photographs where every level's
    # side is even, docs/quality.md "Sparse sites"; else every site)
    grid: int | None = option(None, "support coherent: sites every G voxels",
                              kind="int", low=1, optional=True, metavar="G",
                              group="volume and pyramid", decided="2 on even sides, else 1")
    seed: int | None = option(None, "random seed", kind="own")

    def to_dict(self) -> dict:
        """Plain JSON-able dictionary (tuples become lists)."""
        return asdict(self)

    @property
    def relaxation_options(self) -> IcmOptions | AnnealOptions:
        """The options of the chosen relaxation, as its own frozen dataclass."""
        cls = RELAXATIONS[self.relaxation].options
        return cls(**{f.name: getattr(self, f.name) for f in fields(cls)})


@dataclass(frozen=True)
class SynthesisResult:
    """What :func:`npmrf3d.synthesize` returns.

    Attributes
    ----------
    volume : (N1, N2, N3, C) float32 ndarray
        The synthesized volume, values in the exemplar's units.
    history : list of list of float
        Global temperature after each sweep, one list per level (coarsest first); the first
        entry of each list is the global temperature before the first sweep.
    config : SynthesisConfig
        The validated configuration of the run.
    timings : dict
        Wall time in seconds per level (``level_2``, ...), ``setup`` and ``total``.
    labels : (K, C) float32 ndarray
        The label set used.
    stats : dict
        Per-level counts: sweeps, voxel updates, voxel-view LCPDF evaluations.
    """

    volume: np.ndarray
    history: list[list[float]]
    config: SynthesisConfig
    timings: dict
    labels: np.ndarray
    stats: dict


#: ``run(per_view_exemplars, config, rng, *, progress=None, checkpoint=None, **inputs)``: make a
#: volume from validated exemplars (view -> float32 (H, W, C)) and a validated configuration.
MethodRun = Callable[..., SynthesisResult]


@dataclass(frozen=True)
class SynthesisMethod:
    """One way of making a volume: an entry of :data:`npmrf3d.methods.METHODS`.

    Attributes
    ----------
    name : str
        Registry name (``npmrf``, ``kopf``, ...), used by the studies, the CLI and ``run.json``.
    run : callable
        ``run(per_view_exemplars, config, rng, *, progress=None, checkpoint=None) ->
        SynthesisResult``; ``progress(level, step, steps, value)`` as in
        :func:`npmrf3d.model.pyramid.run_pyramid`. Method-specific inputs that are not configuration
        (NP_K's constraint volume) may follow as further keyword arguments.
    make_config : callable
        Plain keyword arguments -> a validated ``config_class`` instance (raises
        :class:`npmrf3d.ParameterError`).
    config_class : type
        The method's frozen configuration dataclass; its field defaults are the defaults of
        the API and the command line.
    synthesize : callable
        The public one-call function (``synthesize(exemplar=None, *, ..., rng=None, progress=None)``):
        validate, load the exemplars, run.
    fit : callable
        ``fit(config) -> dict(window=..., levels=..., toroidal=...)``: what
        :func:`npmrf3d.model.exemplar.resolve_exemplars` checks every exemplar against.
    description : str
        One line for ``npmrf3d info`` and error messages.
    resources : callable, optional
        ``resources(config, exemplar_shapes) -> npmrf3d.resources.Estimate``: the peak memory
        (and a rough time) of a run, from its configuration and the (H, W, C) shape of each
        view's exemplar, before anything is allocated. None: the volume and one work copy
        (:func:`npmrf3d.resources.generic_estimate`).
    unavailable : callable, optional
        ``unavailable() -> str | None``: why the method cannot run in this environment (an
        optional extra is not installed), or None when it can; checked without importing the
        extra. None: always available. The studies leave unavailable methods out and say so.
    aprons : callable, optional
        ``aprons(config, per_view_exemplars) -> tuple[int, ...] | None``: per level (0 the
        finest), how far a level's result reaches over its iterations, for a run whose blocks
        can be made alone (:mod:`npmrf3d.model.regions`); ``run`` then takes ``region=`` (a
        :class:`npmrf3d.model.regions.RegionPlan`) and returns that block. None, or a None
        result: the method runs on the whole volume only.
    settle : callable, optional
        ``settle(config, per_view_exemplars) -> config``: the configuration with what it leaves to
        the exemplars decided (the NP-MRF sampler's levels), applied once the exemplars are
        loaded and before anything reads the configuration further. None: nothing to decide.
    """

    name: str
    run: MethodRun
    make_config: Callable[..., Any]
    config_class: type
    synthesize: Callable[..., SynthesisResult]
    fit: Callable[[Any], dict]
    description: str = ""
    resources: Callable[[Any, dict], Any] | None = None
    unavailable: Callable[[], str | None] | None = None
    aprons: Callable[[Any, Any], Any] | None = None
    settle: Callable[[Any, Any], Any] | None = None
