"""The NP-MRF sampler's options, validated by axis into a frozen :class:`SynthesisConfig`.

The sampler has three independent choices (docs/model.md, section 8): the estimator
**support** (``coherent`` candidates or the ``full`` exemplar), the **heuristic** (ML_H1a,
ML_H1b, ML_H2a, ML_H2b) and the **relaxation** (``icm`` or ``anneal``), each with its own
options. :func:`make_config` accepts an option only where it changes the result: an option
given a value other than its default where the chosen combination cannot use it is refused in
one line (:class:`npmrf3d.ParameterError`), never silently ignored. :data:`APPLIES` says which
option belongs to which combination (the README's option table is made from it).
"""

from __future__ import annotations

import dataclasses

from .. import _validation as check
from ..config import (
    APPLIES,
    TEMPERATURE_OPTIONS,
    applies,
    COHERENT_RULE,
    DEFAULT_SIZE,
    PRESETS,
    SEGMENTED_MODES,
    SUPPORTS,
    VARIANTS,
    SynthesisConfig,
)
from ..model.heuristics import DECISIONS, get_heuristic
from ..model.kcoherence_icm import IcmSchedule
from ..model.neighbourhood import VIEWS
from ..model.pyramid import INHERIT, UPSAMPLING
from ..model.relax import RELAXATIONS
from ..model.relax.anneal import PROPOSALS, SAMPLERS, SCHEDULES

__all__ = ["APPLIES", "BY_SUPPORT", "DEFAULT_SAMPLER", "DEFAULT_UPSAMPLE", "DEFAULT_XI", "applies", "combination",
           "make_config"]

#: Up-sampling used when none is asked for: the paper's choice for each relaxation.
DEFAULT_UPSAMPLE = {"icm": "1/8", "anneal": "8/8"}
#: ICM's cooling step ``xi`` when none is asked for, by support: the paper's -3 for ``full``;
#: -1 for ``coherent``, whose trust-weighted search needs more than the two sweeps per level
#: that -3 leaves (docs/quality.md, "Per-voxel temperatures").
DEFAULT_XI = {"full": SynthesisConfig.xi, "coherent": IcmSchedule.xi}
#: Annealing's draw when none is asked for, by support: heat-bath for ``full`` (it beats the
#: paper's Metropolis rule at equal sweeps); Metropolis for ``coherent``, where the heat-bath
#: draw copies diagonal runs of exemplar pixels (docs/quality.md, "The sampler's combinations").
DEFAULT_SAMPLER = {"full": SynthesisConfig.sampler, "coherent": "metropolis"}
#: The site spacing of support ``coherent`` when none is asked for (where every level's side is a
#: multiple of it): a quarter of the searches and votes, as good on the held-out photographs as
#: every voxel (docs/quality.md, "Sparse sites").
SPARSE_GRID = 2
def fits_grid(size, levels: int, grid: int) -> bool:
    """Whether every level's side is a multiple of ``grid``."""
    return all((n // 2 ** level) % grid == 0 for level in range(levels) for n in size)


def coherent_grid(config: SynthesisConfig, segmented: bool, levels: int) -> int:
    """The site spacing of a ``coherent``-support run with ``levels`` levels: ``config.grid`` when
    given, else every site for a segmented exemplar (the segmented preset's, measured on scans:
    docs/segmented.md) and :data:`SPARSE_GRID` for the others where every level's side is a
    multiple of it (else every site)."""
    if config.grid is not None:
        return config.grid
    if segmented or not fits_grid(config.size, levels, SPARSE_GRID):
        return 1
    return SPARSE_GRID


#: The options whose default depends on the support (None in :func:`make_config` means "the
#: support's"): any value given for them counts as given.
BY_SUPPORT = {"xi": DEFAULT_XI, "sampler": DEFAULT_SAMPLER}

_C = SynthesisConfig  # every default below is a field default of the configuration


def combination(options) -> tuple[str, str, bool]:
    """(support, relaxation, temperatures) that keyword ``options`` of :func:`make_config` ask
    for (unchecked).

    >>> combination({"variant": "literal"}), combination({"relaxation": "anneal"})
    (('full', 'icm', True), ('coherent', 'anneal', False))
    """
    variant = options.get("variant")
    support = VARIANTS[variant][0] if variant in VARIANTS else options.get("support") or _C.support
    relaxation = options.get("relaxation", _C.relaxation)
    temperatures = options.get("temperatures")
    if temperatures is None:
        temperatures = support == "full" and relaxation == "icm"
    return support, relaxation, bool(temperatures)


def _unset(name: str, value) -> bool:
    """Whether option ``name`` was left at its default (for the :data:`BY_SUPPORT` options: not
    given at all)."""
    return value is None or (name not in BY_SUPPORT and value == getattr(_C, name, None))


def _refuse_unused(given: dict, support: str, relaxation: str) -> None:
    """One line for the first option set away from its default that (support, relaxation)
    cannot use."""
    for name, value in given.items():
        if _unset(name, value) or applies(name, (support, relaxation)):
            continue
        users = " or ".join(f"support '{s}' with relaxation '{r}'" for s, r in APPLIES[name])
        check.fail(f"option {name} does not apply to support '{support}' with relaxation "
                   f"'{relaxation}' (it is used by {users}); drop it or choose that combination")


def _support_and_preset(variant, support, preset) -> tuple[str, str]:
    """(support, preset) from the older ``variant`` name or the two axes themselves."""
    if variant is not None:
        named = VARIANTS.get(variant) if isinstance(variant, str) else None
        if named is None:
            check.fail(f"variant must be one of {', '.join(VARIANTS)}; got {variant!r}")
        if (support is not None and support != named[0]) or (preset is not None and preset != named[1]):
            check.fail(f"variant {variant!r} means support {named[0]!r} with preset {named[1]!r}; "
                       f"it contradicts support={support!r}, preset={preset!r}: give one or the other")
        return named
    support = check.choice("support", _C.support if support is None else support, SUPPORTS)
    preset = check.choice("preset", _C.preset if preset is None else preset, tuple(PRESETS))
    return support, preset


def _support_rule(support: str, preset_name: str, **rule_options):
    """The support's decision rule (:data:`npmrf3d.config.COHERENT_RULE`, or the full support's
    preset) with each rule option that is not None checked and put in its place."""
    rule = COHERENT_RULE if support == "coherent" else PRESETS[preset_name]
    overrides = {}
    for name in ("bandwidth", "centre_bandwidth", "tau"):
        if rule_options[name] is not None:
            overrides[name] = check.real(name, rule_options[name], low=0.0, low_open=True)
    for name in ("adaptive", "histogram_weight"):
        if rule_options[name] is not None:
            overrides[name] = check.real(name, rule_options[name], low=0.0)
    if rule_options["outlier"] is not None:
        overrides["outlier"] = check.real("outlier", rule_options["outlier"], low=0.0, high=1.0, high_open=True)
    if rule_options["decision"] is not None:
        overrides["decision"] = check.choice("decision", rule_options["decision"], DECISIONS)
    return dataclasses.replace(rule, **overrides)


def _refuse_relaxation_mismatch(given: dict, support: str, relaxation: str, temperatures: bool, upsample: str,
                                decision: str, heuristic: str) -> None:
    """Refuse a relaxation that the support, per-voxel temperatures, the up-sampling or the
    heuristic cannot run (one line naming what to change)."""
    if support == "full" and relaxation == "icm" and not temperatures:
        check.fail("support 'full' runs ICM with per-voxel temperatures only; drop temperatures=False")
    if support == "coherent" and relaxation == "icm" and not temperatures:
        for name in TEMPERATURE_OPTIONS:
            if not _unset(name, given[name]):
                check.fail(f"option {name} needs per-voxel temperatures with support 'coherent': "
                           f"add temperatures=True (command line: --temperatures), or drop it")
        if upsample == "1/8":
            check.fail("upsample '1/8' needs per-voxel temperatures with support 'coherent': add "
                       "temperatures=True (command line: --temperatures), or drop it")
    if support == "coherent" and relaxation == "anneal" and upsample != "8/8":
        check.fail(f"support 'coherent' anneals with 8/8 up-sampling (every child copies its "
                   f"parent's shifted sources); upsample {upsample!r} runs with support 'full'")
    if decision == "sample" and heuristic in ("ML_H1a", "ML_H1b"):
        check.fail(f"decision 'sample' needs a heuristic with an objective (ML_H2a, ML_H2b); "
                   f"{heuristic} is defined by per-view argmax searches: use decision='argmax'")


def make_config(
    *, size=DEFAULT_SIZE, window=_C.window, levels=_C.levels, heuristic=_C.heuristic,
    relaxation=_C.relaxation, views=_C.views, support=None, preset=None, upsample=None,
    inherit=_C.inherit, xi=None, stop=_C.stop, max_sweeps=_C.max_sweeps, sampler=None,
    schedule=_C.schedule, t0=_C.t0, t_end=_C.t_end, proposals=_C.proposals, proposal=_C.proposal,
    variant=None, segmented=_C.segmented, bandwidth=None, centre_bandwidth=None, adaptive=None,
    decision=None, tau=None, histogram_weight=None, outlier=None, grey_levels=None, palette=None,
    toroidal_exemplar=False, temperatures=None, blockwise=False, whole_voxels=_C.whole_voxels, phase_weight=None,
    grid=_C.grid, seed=None,
) -> SynthesisConfig:
    """Validate plain keyword arguments into a frozen :class:`SynthesisConfig`.

    ``support`` (None: ``coherent``) and ``preset`` (None: ``tuned``; the full support's
    decision rule, :data:`npmrf3d.config.PRESETS`) may also be given together by the older name
    ``variant`` (:data:`npmrf3d.config.VARIANTS`). The rule arguments (``bandwidth`` ...
    ``outlier``) override single fields of the support's rule when not None. ``xi`` (None:
    :data:`DEFAULT_XI` of the support) is ICM's cooling step, ``sampler`` (None:
    :data:`DEFAULT_SAMPLER` of the support) annealing's draw. ``temperatures``
    (None: True for support ``full`` with ICM, False otherwise): ICM with per-voxel temperatures;
    support ``coherent`` then weights its searches and votes by trust and re-decides warm voxels
    only (``xi``, ``stop``, ``max_sweeps``, ``inherit`` and ``upsample`` 1/8 need it there).
    ``blockwise`` (support ``coherent`` without per-voxel temperatures): the block-local sampler
    (the coarsest level and every level of at most ``whole_voxels`` voxels whole, the finer ones
    reading a pilot block's histograms, random numbers hashed from voxel positions), whose volume
    can be made in blocks
    (:mod:`npmrf3d.methods.blocks`); a segmented exemplar then runs the segmented preset's deeper
    pyramid only. ``phase_weight`` (support ``coherent``; None:
    :attr:`SynthesisConfig.phase_weight`, 0 for the full support): the phase control of the histogram prior
    (:class:`npmrf3d.methods.npmrf_coherent.CoherentConfig`), which holds the share of the voxels
    above the exemplars' Otsu threshold to the exemplars' (0: off). ``grid`` (support ``coherent``):
    the sites whose neighbourhoods are searched and vote lie every ``grid`` voxels along both plane
    axes of each view (1: every voxel), so each level's side must be a multiple of it; None: the
    run's own (:func:`coherent_grid`).
    """
    levels = check.integer("levels", levels, low=1, high=8)
    window = check.window(window)
    dims = check.size(size, levels=levels, window=window)
    heuristic = get_heuristic(heuristic).name
    relaxation = check.choice("relaxation", relaxation, RELAXATIONS)
    views = check.views(views, VIEWS)
    support, preset_name = _support_and_preset(variant, support, preset)
    given = {"xi": xi, "stop": stop, "max_sweeps": max_sweeps, "inherit": inherit,
             "sampler": sampler, "schedule": schedule, "t0": t0, "t_end": t_end, "proposals": proposals,
             "proposal": proposal, "preset": preset if variant is None else None, "bandwidth": bandwidth,
             "adaptive": adaptive, "decision": decision, "tau": tau, "histogram_weight": histogram_weight,
             "toroidal_exemplar": bool(toroidal_exemplar) or None, "temperatures": temperatures,
             "segmented": segmented if segmented == "yes" else None,
             "phase_weight": phase_weight}
    if relaxation == "anneal" and not get_heuristic(heuristic).objective:
        check.fail(f"heuristic {heuristic} cannot drive annealing: annealing compares objective "
                   f"values, and {heuristic} is defined by per-view argmax searches with no "
                   f"objective; use ML_H2a or ML_H2b, or relaxation 'icm'")
    if upsample is None:
        upsample = "8/8" if support == "coherent" else DEFAULT_UPSAMPLE[relaxation]
    upsample = check.choice("upsample", upsample, UPSAMPLING)
    inherit = check.choice("inherit", inherit, INHERIT)
    xi = check.real("xi", BY_SUPPORT["xi"][support] if xi is None else xi, high=0.0, high_open=True)
    stop = check.real("stop", stop, low=0.0, high=1.0, low_open=True)
    max_sweeps = check.integer("max_sweeps", max_sweeps, low=1)
    sampler = check.choice("sampler", BY_SUPPORT["sampler"][support] if sampler is None else sampler, SAMPLERS)
    schedule = check.choice("schedule", schedule, SCHEDULES)
    t0 = check.real("t0", t0, low=0.0, low_open=True)
    t_end = check.real("t_end", t_end, low=0.0, low_open=schedule == "geometric", high=t0)
    proposals = check.integer("proposals", proposals, low=1)
    proposal = check.choice("proposal", proposal, PROPOSALS)
    segmented = check.choice("segmented", segmented, SEGMENTED_MODES)
    rule = _support_rule(support, preset_name, bandwidth=bandwidth, centre_bandwidth=centre_bandwidth, tau=tau,
                         adaptive=adaptive, histogram_weight=histogram_weight, outlier=outlier, decision=decision)
    _refuse_unused(given, support, relaxation)  # after the values' own checks
    if temperatures is None:
        temperatures = support == "full" and relaxation == "icm"
    temperatures = check.boolean("temperatures", temperatures)
    _refuse_relaxation_mismatch(given, support, relaxation, temperatures, upsample, rule.decision, heuristic)
    if grey_levels is not None:
        grey_levels = check.integer("grey_levels", grey_levels, low=2, high=65536)
    if palette is not None:
        palette = check.integer("palette", palette, low=2, high=65536)
    if seed is not None:
        seed = check.integer("seed", seed, low=0)
    blockwise = check.boolean("blockwise", blockwise)
    whole_voxels = check.integer("whole_voxels", whole_voxels, low=1)
    if support != "coherent":  # no phase control there
        phase_weight = 0.0
    elif phase_weight is None:
        phase_weight = _C.phase_weight
    phase_weight = check.real("phase_weight", phase_weight, low=0.0)
    if grid is not None:
        grid = check.integer("grid", grid, low=1, high=window)
        if grid != 1 and support != "coherent":
            check.fail(f"grid {grid} needs support 'coherent' (the full-Parzen sampler estimates every "
                       "voxel); use grid 1 or support 'coherent'")
    if blockwise and support != "coherent":
        check.fail("blockwise runs need support 'coherent' (the full-Parzen sampler's estimates "
                   "read the whole exemplar and its ICM stop rule the whole volume)")
    if blockwise and temperatures:
        check.fail("blockwise runs cannot use per-voxel temperatures (their stop rule reads the "
                   "whole volume); drop temperatures=True (command line: --temperatures)")
    return SynthesisConfig(
        size=dims, window=window, levels=levels, heuristic=heuristic, relaxation=relaxation,
        views=views, upsample=upsample, inherit=inherit, xi=xi, stop=stop, max_sweeps=max_sweeps,
        sampler=sampler, schedule=schedule, t0=t0, t_end=t_end, proposals=proposals,
        proposal=proposal, support=support, preset=preset_name, segmented=segmented, rule=rule,
        grey_levels=grey_levels, palette=palette, toroidal_exemplar=bool(toroidal_exemplar),
        temperatures=temperatures, blockwise=blockwise, whole_voxels=whole_voxels, phase_weight=phase_weight,
        grid=grid, seed=seed,
    )
