"""``npmrf3d synth``: make a solid texture with the NP-MRF sampler and write a run folder.

Every option -- its default, limits, choices and help -- is a field of
:class:`npmrf3d.config.SynthesisConfig` (the decision rule's of :class:`npmrf3d.config.DecisionRule`),
read by :func:`npmrf3d.cli._generic.add_method_parser`, so the API, the configuration, ``--help``
and the docs cannot disagree (``tests/test_defaults.py``).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from ..config import VARIANTS, SynthesisConfig
from ..errors import ParameterError
from ..io.runs import RUN_FILES
from ..methods.npmrf import METHOD, segmented
from ..methods.npmrf_coherent import SEGMENTED, SEGMENTED_MAX_VALUES
from ._blocks import add_block_options, blockwise_requested, run_zarr, zarr_output
from ._common import PROG, claim_output, dry_run, parse_size, prepare_run, say, write_result
from ._generic import add_method_parser, config_options, refuse_written
from ._options import given
from ._progress import run_method

__all__ = ["register", "run"]

#: Parameters whose library name differs from the option; messages name the option instead.
OPTION_NAMES = ("max_sweeps", "centre_bandwidth", "histogram_weight", "grey_levels", "t_end")


def _extra(parser: argparse.ArgumentParser, sections: dict) -> None:
    """``synth``'s own options beside its configuration's: the older ``--variant`` (a support
    and a preset by one name; accepted, not listed) and the block options."""
    sections["method"].add_argument("--variant", default=None, choices=tuple(VARIANTS), help=argparse.SUPPRESS)
    add_block_options(sections["blocks"])


def register(commands, formatter_class) -> None:
    """Add the ``synth`` sub-command (alias ``npmrf``)."""
    add_method_parser(
        commands, "synth", METHOD, aliases=("npmrf",),
        help="synthesise a solid texture from an exemplar and write a run folder",
        description=(
            "Synthesise a solid texture whose slices look like the exemplar and write\n"
            f"{', '.join(RUN_FILES)} into the output folder. Every option: docs/commands/synth.md.\n\n"
            "examples:\n"
            "  npmrf3d synth                                  # bundled exemplar, 64^3\n"
            "  npmrf3d synth wood.png --size 64 --out wood    # your own image\n"
            "  npmrf3d synth --size 8 --levels 1 --window 3   # a tiny, quick run\n"
            "  npmrf3d synth --size 512 --blockwise --out big.zarr   # any size, in blocks, into Zarr"
        ),
        out="npmrf3d-synth-out", formatter_class=formatter_class, handler=run, extra=_extra,
    )


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
        kind = "grey values" if all(a.shape[-1] == 1 for a in per_view.values()) else "colours (by their mean)"
        say(f"{PROG}: warning: the exemplar holds at most {SEGMENTED_MAX_VALUES} distinct {kind}, so "
            f"--segmented auto runs the segmented preset with window {SEGMENTED.window} and "
            f"--window {config.window} is not used; pass --segmented no to use it", error=True)


def run(args: argparse.Namespace, argv: list[str]) -> int:
    """``npmrf3d synth``: validate everything, then run the ``npmrf`` method and write the folder."""
    t_start = time.perf_counter()
    config = METHOD.make_config(size=parse_size(args.size), views=args.views, seed=args.seed,
                                variant=args.variant, **{**config_options(args, SynthesisConfig),
                                                         "blockwise": blockwise_requested(args)})
    refuse_written(args, config)
    config, out, checkpoint, per_view, sources = prepare_run(args, METHOD, config, whole=not zarr_output(args))

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
