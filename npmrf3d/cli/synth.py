"""``npmrf3d synth``: make a solid texture with the NP-MRF sampler and write a run folder.

Every option's default is the field default of :class:`npmrf3d.config.SynthesisConfig` (whose
relaxation fields come from :class:`npmrf3d.model.relax.IcmOptions` and
:class:`npmrf3d.model.relax.AnnealOptions`), and every choice list comes from its registry, so the
API, the configuration and the command line cannot disagree (``tests/test_defaults.py``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from .. import data
from ..config import DEFAULT_SIZE, PRESETS, SEGMENTED_MODES, SUPPORTS, VARIANTS, SynthesisConfig
from ..errors import ParameterError
from ..io.runs import RUN_FILES
from ..methods.npmrf import METHOD, segmented
from ..methods.npmrf_coherent import SEGMENTED, SEGMENTED_MAX_VALUES
from ..methods.npmrf_options import DEFAULT_SAMPLER, DEFAULT_XI, SPARSE_GRID
from ..model.exemplar import BUNDLED_PREFIX
from ..model.heuristics import DECISIONS, HEURISTICS
from ..model.neighbourhood import VIEWS
from ..model.pyramid import INHERIT, UPSAMPLING
from ..model.relax import RELAXATIONS
from ..model.relax.anneal import PROPOSALS, SAMPLERS, SCHEDULES
from ._common import (
    PROG,
    add_exemplar_kind,
    add_run_options,
    choices,
    claim_output,
    default,
    dry_run,
    parse_size,
    prepare_run,
    say,
    write_result,
)
from ._blocks import add_block_options, blockwise_requested, run_zarr, zarr_output
from ._options import given
from ._progress import run_method

__all__ = ["register", "run"]

#: Parameters whose library name differs from the option; messages name the option instead.
OPTION_NAMES = ("max_sweeps", "centre_bandwidth", "histogram_weight", "grey_levels", "t_end")
_DEFAULT_RULE = PRESETS["tuned"]


def _d(name: str):
    return default(SynthesisConfig, name)


def _rule_help(text: str, field: str) -> str:
    value = getattr(_DEFAULT_RULE, field)
    return f"{text} (default: None = the preset's value; support full with preset tuned uses {value})"


def register(commands, formatter_class) -> None:
    """Add the ``synth`` sub-command."""
    synth = commands.add_parser(
        "synth", aliases=["npmrf"],
        help="synthesise a solid texture from an exemplar and write a run folder",
        description=(
            "Synthesise a solid texture whose slices look like the exemplar and write\n"
            f"{', '.join(RUN_FILES)} into the output folder.\n\n"
            "examples:\n"
            "  npmrf3d synth                                  # bundled exemplar, 64^3\n"
            "  npmrf3d synth wood.png --size 64 --out wood    # your own image\n"
            "  npmrf3d synth --size 8 --levels 1 --window 3   # a tiny, quick run\n"
            "  npmrf3d synth --size 512 --out big.zarr        # any size, in blocks, into Zarr"
        ),
        formatter_class=formatter_class,
    )
    default_name = f"{BUNDLED_PREFIX}{data.DEFAULT_EXEMPLAR}"
    synth.add_argument(
        "exemplar", nargs="?", default=default_name, metavar="EXEMPLAR",
        help="2D exemplar image (.png, .jpg, .bmp, .gif, .tif or .npy) used for every constrained "
             f"view; omitted = the bundled default exemplar, or '{BUNDLED_PREFIX}NAME' for a bundled "
             f"one ({', '.join(data.available())})",
    )
    shape = synth.add_argument_group("volume and pyramid")
    shape.add_argument(
        "--size", default=str(DEFAULT_SIZE), metavar="N",
        help="output size in voxels: N for an N^3 cube or N1,N2,N3; each divisible by 2**(levels-1)",
    )
    shape.add_argument(
        "--window", type=int, default=_d("window"), metavar="W",
        help="side of each view's square neighbourhood, an odd integer from 3 to 15 (support "
             "coherent on a segmented exemplar: 5, see --segmented)",
    )
    shape.add_argument(
        "--grid", type=int, default=_d("grid"), metavar="G",
        help="support coherent: the neighbourhoods that are searched and vote lie every G voxels "
             "along both plane axes of each view (1 = every voxel; 2 = a quarter of the work), an "
             "integer from 1 to the window; every level's side a multiple of it (default: "
             f"{SPARSE_GRID} where every level's side is even, else 1; 1 for a segmented exemplar "
             "and with --support full)",
    )
    shape.add_argument(
        "--levels", type=int, default=_d("levels"), metavar="L",
        help="number of pyramid levels (the paper's scales), an integer from 1 to 8 (support "
             "coherent on a segmented exemplar: this many and one fewer are both run, see "
             "--segmented)",
    )
    shape.add_argument(
        "--upsample", default=None, metavar=choices(UPSAMPLING),
        help="how a level initialises the next finer one: 1/8 keeps only the inherited voxel and "
             "draws the other 7 at random, 8/8 copies the parent into all 8 "
             "(support coherent: 8/8, its children copying the parent's shifted sources) "
             "(default: none = 8/8 for support coherent; for support full the paper's choice, "
             "1/8 for icm and 8/8 for anneal)",
    )
    shape.add_argument(
        "--inherit", default=_d("inherit"), metavar=choices(INHERIT),
        help="whether voxels inherited from the coarser level may still change (resynth) or stay "
             "fixed (fixed)",
    )

    method = synth.add_argument_group("sampler")
    method.add_argument(
        "--heuristic", default=_d("heuristic"), metavar=choices(HEURISTICS),
        help="how the three per-view densities make one voxel value: ML_H1a least probable per-view "
             "argmax, ML_H1b average of per-view argmaxes, ML_H2a argmax of the minimum, ML_H2b "
             "argmax of the product",
    )
    method.add_argument(
        "--relaxation", default=_d("relaxation"), metavar=choices(RELAXATIONS),
        help="relaxation algorithm: icm (iterated conditional modes with per-voxel temperatures; "
             "options --xi --stop --max-sweeps) or anneal (simulated annealing with one global "
             "temperature; options --sampler --schedule --t0 --t-end --proposals --proposal; "
             "needs ML_H2a or ML_H2b)",
    )
    method.add_argument(
        "--xi", type=float, default=None, metavar="X",
        help="icm with per-voxel temperatures: cooling step, a negative number (more negative "
             f"cools faster) (default: none = {DEFAULT_XI['full']} with support full, the "
             f"paper's; {DEFAULT_XI['coherent']} with support coherent, measured)",
    )
    method.add_argument(
        "--stop", type=float, default=_d("stop"), metavar="F",
        help="icm: stop a level once the global temperature fell by this fraction, in (0, 1] "
             "(1 = down to 0)",
    )
    method.add_argument(
        "--max-sweeps", type=int, default=_d("max_sweeps"), metavar="N",
        help="icm: hard limit of sweeps per level, a positive integer",
    )
    method.add_argument(
        "--sampler", default=None, metavar=choices(SAMPLERS),
        help="anneal: heat-bath (this project's addition: draw the new value from the tempered "
             "objective, over all labels with support full, among the candidates with support "
             "coherent) or metropolis (the paper: one proposal per voxel and sweep, accepted by "
             "the Metropolis rule) (default: none = "
             f"{DEFAULT_SAMPLER['full']} with support full, {DEFAULT_SAMPLER['coherent']} with "
             "support coherent, each chosen by measurement: docs/quality.md)",
    )
    method.add_argument(
        "--schedule", default=_d("schedule"), metavar=choices(SCHEDULES),
        help="anneal: how the global temperature falls from --t0 to --t-end within each level",
    )
    method.add_argument(
        "--t0", type=float, default=_d("t0"), metavar="T",
        help="anneal: temperature of the first sweep of each level, a positive number",
    )
    method.add_argument(
        "--t-end", type=float, default=_d("t_end"), metavar="T",
        help="anneal: temperature of the last sweep of each level, in (0, t0] (0 allowed for the "
             "linear schedule)",
    )
    method.add_argument(
        "--proposals", type=int, default=_d("proposals"), metavar="P",
        help="anneal: proposals (sweeps) per voxel per level, a positive integer",
    )
    method.add_argument(
        "--proposal", default=_d("proposal"), metavar=choices(PROPOSALS),
        help="anneal, metropolis: draw candidates from the exemplar's values (the paper) or "
             "uniformly from the label set",
    )
    method.add_argument(
        "--support", default=None, metavar=choices(SUPPORTS),
        help="which exemplar neighbourhoods each view's Parzen estimate sums over: coherent = the "
             "coherent candidates of the neighbourhoods containing the voxel (chosen by measurement, "
             "docs/quality.md; --window at every level, --heuristic ML_H2b/ML_H2a, --centre-bandwidth "
             "as a factor of the exemplar's standard deviation and --outlier; with anneal, a "
             "heat-bath draw among the candidates, --proposals iterations per level), full = every "
             "exemplar patch (Urs et al. 2014) with the decision rule --preset "
             "(default: none = coherent)",
    )
    method.add_argument(
        "--preset", default=None, metavar=choices(PRESETS),
        help="support full: the decision rule, tuned = sharpened bandwidths, a sampled decision, "
             "a histogram penalty (chosen by measurement), paper = Urs et al. 2014 word for word "
             "(collapses to a flat volume on photographs) (default: none = tuned)",
    )
    method.add_argument(
        "--variant", default=None, metavar=choices(VARIANTS),
        help="the older single name of a support and a preset: coherent = --support coherent, "
             "sharp or default = --support full --preset tuned, literal = --support full --preset "
             "paper (default: none)",
    )
    method.add_argument(
        "--segmented", default=_d("segmented"), metavar=choices(SEGMENTED_MODES),
        help="support coherent: the preset for a segmented exemplar (a thresholded scan slice, a "
             "label map): window 5 at every level in place of --window, and histogram vote "
             "weighting, which keep the phase fractions and the pore sizes; then a second run "
             "with one level fewer, and the volume kept is the one whose two-point correlation "
             "is nearer the exemplar's (about twice the time; with --checkpoint FILE.npz the "
             "second run resumes from FILE.levelsL.npz) (measured on micro-CT slices, "
             "docs/segmented.md); auto = when the exemplars hold at most "
             f"{SEGMENTED_MAX_VALUES} distinct grey values, no = --window and --levels as given; "
             "run.json's stats say which ran (segmented, level_trials, levels_kept)",
    )
    method.add_argument(
        "--phase-weight", type=float, default=None, metavar="W",
        help="support coherent: a phase control through the histogram prior -- the value bins "
             "split at the exemplars' Otsu threshold, and a candidate of the phase the volume "
             "over-uses loses W times that phase's price; keeps a minority phase's share of a "
             "scan slice (docs/materials.md), >= 0 (0 = off) "
             f"(default: {_d('phase_weight'):g}; 0 with --support full)",
    )
    method.add_argument(
        "--bandwidth", type=float, default=None, metavar="B",
        help=_rule_help("neighbour bandwidth as a factor of h_opt, a positive number", "bandwidth"),
    )
    method.add_argument(
        "--centre-bandwidth", type=float, default=None, metavar="B",
        help=_rule_help("centre-value bandwidth as a factor of h_opt, a positive number",
                        "centre_bandwidth"),
    )
    method.add_argument(
        "--adaptive", type=float, default=None, metavar="A",
        help=_rule_help("if > 0, set the neighbour bandwidth per voxel and view to 2h^2 = A * "
                        "(best patch distance); 0 = off", "adaptive"),
    )
    method.add_argument(
        "--decision", default=None, metavar=choices(DECISIONS),
        help=_rule_help("how a voxel picks its label: argmax (the paper's ICM) or sample from "
                        "exp(score / tau)", "decision"),
    )
    method.add_argument(
        "--tau", type=float, default=None, metavar="T",
        help=_rule_help("temperature of the sample decision, a positive number", "tau"),
    )
    method.add_argument(
        "--histogram-weight", type=float, default=None, metavar="W",
        help=_rule_help("weight of the penalty on labels the volume over-uses relative to the "
                        "exemplar, >= 0 (0 = off)", "histogram_weight"),
    )
    method.add_argument(
        "--outlier", type=float, default=None, metavar="A",
        help=_rule_help("weight of a uniform term mixed into each view's density before "
                        "ML_H2a/ML_H2b combine the views, in [0, 1) (0 = off, the paper)", "outlier"),
    )

    views = synth.add_argument_group("views and exemplars")
    views.add_argument(
        "--views", default=",".join(_d("views")), metavar="V[,V...]",
        help=f"comma-separated constrained views, 1 to 3 distinct names of {', '.join(VIEWS)}",
    )
    for view in VIEWS:
        views.add_argument(
            f"--exemplar-{view}", default=None, metavar="PATH",
            help=f"a different exemplar file (or {BUNDLED_PREFIX}NAME) for the {view} view "
                 f"(default: none = EXEMPLAR)",
        )
    add_exemplar_kind(views)
    views.add_argument(
        "--grey-levels", type=int, default=None, metavar="K",
        help="re-quantise every exemplar channel to K evenly spaced levels, 2 to 65536 "
             "(default: none = keep the exemplar's values)",
    )
    views.add_argument(
        "--palette", type=int, default=None, metavar="K",
        help="reduce the exemplar to at most K colours by k-means, 2 to 65536 "
             "(default: none = keep every colour)",
    )
    views.add_argument(
        "--toroidal-exemplar", action="store_true",
        help="support full: let exemplar patches wrap around the exemplar's borders (for tileable "
             "exemplars)",
    )
    method.add_argument(
        "--temperatures", action="store_true", default=None,
        help="support coherent, icm: per-voxel temperatures (Urs et al. 2014): trust-weighted "
             "searches and votes, warm voxels re-decided until --stop or --max-sweeps, cooling by "
             "--xi; needed there by --xi, --stop, --max-sweeps, --inherit and --upsample 1/8 "
             "(default: none = on for support full with icm, where it is the only ICM; off for "
             "support coherent, which re-decides every voxel in each of a level's iterations)",
    )

    add_block_options(add_run_options(synth, out="npmrf3d-synth-out", zarr=True))

    synth.set_defaults(handler=run)


#: Above this many distinct exemplar values, synth suggests --palette (the label stage scales
#: with the number of labels; a colour photograph easily has thousands).
MANY_VALUES = 1024


def _note_many_values(per_view: dict) -> None:
    arrays = {id(a): a for a in per_view.values()}.values()
    values = np.unique(np.concatenate([a.reshape(-1, a.shape[2]) for a in arrays]), axis=0)
    if len(values) > MANY_VALUES:
        say(f"{PROG}: note: the exemplar has {len(values)} distinct values, each a label; run "
              f"time grows with the label count: --palette 64 (colour) or --grey-levels 64 "
              f"is usually as good and much faster", error=True)


def _check_segmented_window(args: argparse.Namespace, config, per_view: dict) -> None:
    """The segmented preset runs its own window at every level, so a ``--window`` the user wrote
    would change nothing: refused with ``--segmented yes``; with ``--segmented auto`` (the
    default, decided on the exemplar) a warning on stderr says so, even with ``--quiet``."""
    if (config.support != "coherent" or not given(args, "window")
            or config.window == SEGMENTED.window):
        return
    if config.segmented == "yes":
        raise ParameterError(f"--window {config.window} changes nothing with --segmented yes, whose "
                             f"preset uses window {SEGMENTED.window} at every level: drop --window, "
                             f"or pass --segmented no to use it")
    if config.segmented == "auto" and segmented(config, per_view):
        say(f"{PROG}: warning: the exemplar holds at most {SEGMENTED_MAX_VALUES} grey values, so "
            f"--segmented auto runs the segmented preset with window {SEGMENTED.window} and "
            f"--window {config.window} is not used; pass --segmented no to use it", error=True)


def run(args: argparse.Namespace, argv: list[str]) -> int:
    """``npmrf3d synth``: validate everything, then run the ``npmrf`` method and write the folder."""
    t_start = time.perf_counter()
    config = METHOD.make_config(
        size=parse_size(args.size), window=args.window, levels=args.levels,
        heuristic=args.heuristic, relaxation=args.relaxation, views=args.views,
        upsample=args.upsample, inherit=args.inherit, xi=args.xi, stop=args.stop,
        max_sweeps=args.max_sweeps, sampler=args.sampler, schedule=args.schedule, t0=args.t0,
        t_end=args.t_end, proposals=args.proposals, proposal=args.proposal, variant=args.variant,
        support=args.support, preset=args.preset,
        segmented=args.segmented, bandwidth=args.bandwidth,
        centre_bandwidth=args.centre_bandwidth, adaptive=args.adaptive, decision=args.decision,
        tau=args.tau, histogram_weight=args.histogram_weight, outlier=args.outlier,
        grey_levels=args.grey_levels,
        palette=args.palette, toroidal_exemplar=args.toroidal_exemplar, temperatures=args.temperatures,
        blockwise=blockwise_requested(args), whole_voxels=args.whole_voxels, phase_weight=args.phase_weight,
        grid=args.grid, seed=args.seed,
    )
    out, checkpoint, per_view, sources = prepare_run(args, METHOD, config, whole=not zarr_output(args))

    _check_segmented_window(args, config, per_view)
    if zarr_output(args):
        window = SEGMENTED.window if segmented(config, per_view) else config.window
        return run_zarr(args, argv, "synth", METHOD, config, per_view, sources,
                        f"npmrf3d {config.heuristic}, blockwise, window {window}, seed {config.seed}")
    if args.dry_run:
        return dry_run(METHOD, config, per_view)
    if not args.quiet and config.palette is None and config.grey_levels is None:
        _note_many_values(per_view)
    with claim_output(out, args.overwrite):
        result = run_method(args, METHOD, config, per_view, checkpoint=checkpoint, t_start=t_start)
        window = SEGMENTED.window if result.stats.get("segmented") else config.window
        rule = "" if config.support == "coherent" else f" ({config.preset})"
        title = (f"npmrf3d {config.heuristic}, support {config.support}{rule}, window {window}, "
                 f"{result.stats.get('levels_kept', config.levels)} levels, seed {config.seed}")
        write_result(out, args, argv, "synth", result, per_view, sources, title,
                     method=METHOD.name, labels=int(len(result.labels)))
    return 0
