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
    COHERENT_RULE,
    DEFAULT_SIZE,
    PRESETS,
    SUPPORTS,
    TEMPERATURE_OPTIONS,
    VARIANTS,
    DecisionRule,
    SynthesisConfig,
    applies,
)
from ..model.heuristics import get_heuristic
from ..model.kcoherence_icm import IcmSchedule
from ..model.neighbourhood import VIEWS
from ..options import made_from, options_of, validate

__all__ = ["APPLIES", "BASE_LEVELS", "BY_SUPPORT", "DEFAULT_SAMPLER", "DEFAULT_UPSAMPLE", "DEFAULT_XI", "applies", "combination",
           "make_config", "pyramid_levels", "settle"]

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


#: The pyramid's depth when none is asked for, for exemplars and volumes up to :data:`BASE_SIDE`
#: wide: the exemplar's coarsest level is then 16 to 31 pixels (docs/quality.md, "Larger
#: exemplars: the pyramid's depth").
BASE_LEVELS = 3
#: Each doubling of both the exemplar's and the volume's smallest side beyond this adds a level,
#: so that the coarsest exemplar level stays 16 to 31 pixels wide and its window spans as much of
#: a structural unit as on a 64-pixel exemplar: at 128^3 from 128-pixel photographs, 4 levels
#: keep block walls' courses better than 3 (docs/quality.md).
BASE_SIDE = 64


def pyramid_levels(size, exemplar_side: int) -> int:
    """The levels of a run that asks for none: :data:`BASE_LEVELS`, and one more for each
    doubling of both ``exemplar_side`` (the smallest side of the exemplars) and the volume's
    smallest side beyond :data:`BASE_SIDE`, while every side of ``size`` halves evenly (at most 8).

    >>> pyramid_levels((64, 64, 64), 128), pyramid_levels((128,) * 3, 128), pyramid_levels((256,) * 3, 200)
    (3, 4, 4)
    """
    levels = BASE_LEVELS
    while (levels < 8 and min(exemplar_side, *size) >= BASE_SIDE * 2 ** (levels - BASE_LEVELS + 1)
           and all(n % 2 ** levels == 0 for n in size)):
        levels += 1
    return levels


def settle(config: SynthesisConfig, per_view) -> SynthesisConfig:
    """``config`` with the levels it leaves to the run (None) decided from the exemplars
    ``per_view`` (:func:`pyramid_levels`); a configuration that names its levels, as it is."""
    if config.levels is not None:
        return config
    side = min(min(a.shape[:2]) for a in per_view.values())
    return dataclasses.replace(config, levels=pyramid_levels(config.size, side))


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


def _support_rule(support: str, preset_name: str, values: dict) -> DecisionRule:
    """The support's decision rule (:data:`npmrf3d.config.COHERENT_RULE`, or the full support's
    preset) with each rule option of ``values`` that is not None checked and put in its place."""
    rule = COHERENT_RULE if support == "coherent" else PRESETS[preset_name]
    return dataclasses.replace(rule, **{name: validate(DecisionRule, name, values[name])
                                        for name in options_of(DecisionRule) if values[name] is not None})


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


#: Options checked against others rather than by their fields' limits alone.
_TIED = {
    "t_end": lambda v: check.real("t_end", v["t_end"], low=0.0, low_open=v["schedule"] == "geometric",
                                  high=v["t0"]),
    "grid": lambda v: None if v["grid"] is None else check.integer("grid", v["grid"], low=1, high=v["window"]),
}


def _decided(values: dict, support: str, relaxation: str) -> dict:
    """The options whose default the run decides (None in :func:`make_config`), decided:
    ``upsample`` (8/8 for support ``coherent``, else :data:`DEFAULT_UPSAMPLE` of the relaxation),
    ``xi`` and ``sampler`` (:data:`BY_SUPPORT`), ``temperatures`` (with support ``full`` and ICM)
    and ``phase_weight`` (the field's for support ``coherent``, 0 for ``full``, which has no phase
    control)."""
    def given(name, default):
        return default if values[name] is None else values[name]
    return {"upsample": given("upsample", "8/8" if support == "coherent" else DEFAULT_UPSAMPLE[relaxation]),
            **{name: given(name, by_support[support]) for name, by_support in BY_SUPPORT.items()},
            "temperatures": given("temperatures", support == "full" and relaxation == "icm"),
            "phase_weight": given("phase_weight", _C.phase_weight) if support == "coherent" else 0.0}


def _refuse_coherent_only(values: dict, support: str) -> None:
    """Refuse what only support ``coherent`` without per-voxel temperatures runs: sparse sites,
    blocks."""
    if values["grid"] not in (None, 1) and support != "coherent":
        check.fail(f"grid {values['grid']} needs support 'coherent' (the full-Parzen sampler estimates every "
                   "voxel); use grid 1 or support 'coherent'")
    if values["blockwise"] and support != "coherent":
        check.fail("blockwise runs need support 'coherent' (the full-Parzen sampler's estimates "
                   "read the whole exemplar and its ICM stop rule the whole volume)")
    if values["blockwise"] and values["temperatures"]:
        check.fail("blockwise runs cannot use per-voxel temperatures (their stop rule reads the "
                   "whole volume); drop temperatures=True (command line: --temperatures)")


@made_from(SynthesisConfig, size=DEFAULT_SIZE, variant=None)
def make_config(values: dict) -> SynthesisConfig:
    """Validate keyword arguments, one per option of :class:`SynthesisConfig` (the decision
    rule's in its place) and ``variant``, into a frozen :class:`SynthesisConfig`: each option
    is checked against its field's limits; what ties several together is checked here.

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
    levels = validate(_C, "levels", values["levels"])
    window = check.window(values["window"])
    size = check.size(values["size"], levels=BASE_LEVELS if levels is None else levels, window=window)
    heuristic = get_heuristic(values["heuristic"]).name
    relaxation = validate(_C, "relaxation", values["relaxation"])
    variant, raw = values.pop("variant"), dict(values)
    support, preset = _support_and_preset(variant, values["support"], values["preset"])
    own = {"levels": levels, "window": window, "size": size,
           "heuristic": heuristic, "relaxation": relaxation, "views": check.views(values["views"], VIEWS),
           "support": support, "preset": preset,
           "seed": None if values["seed"] is None else check.integer("seed", values["seed"], low=0)}
    if relaxation == "anneal" and not get_heuristic(heuristic).objective:
        check.fail(f"heuristic {heuristic} cannot drive annealing: annealing compares objective "
                   f"values, and {heuristic} is defined by per-view argmax searches with no "
                   f"objective; use ML_H2a or ML_H2b, or relaxation 'icm'")
    values.update(own, **_decided(values, support, relaxation))
    for name, (_, opt) in options_of(_C).items():  # in the fields' order, each once
        if name in _TIED:
            values[name] = _TIED[name](values)
        elif name not in own and opt.kind != "nested":
            values[name] = validate(_C, name, values[name])
    rule = _support_rule(support, preset, values)
    given = {**{name: raw[name] for name in APPLIES}, "preset": raw["preset"] if variant is None else None,
             "segmented": raw["segmented"] if raw["segmented"] == "yes" else None}
    _refuse_unused(given, support, relaxation)  # after the values' own checks
    _refuse_relaxation_mismatch(given, support, relaxation, values["temperatures"], values["upsample"],
                                rule.decision, heuristic)
    _refuse_coherent_only(values, support)
    return SynthesisConfig(rule=rule, **{name: values[name] for name in options_of(_C) if name != "rule"})
