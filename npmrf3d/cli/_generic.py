"""A sub-command built from a registered method's frozen configuration.

Every field of the method's config class becomes an option (``window`` -> ``--window``) whose
default, type and ``--help`` default are read from the field itself, so the API, the
configuration and the command line cannot disagree; values go through the method's own
``make_config``, which validates them. Integers, reals, booleans (a flag that sets ``True``),
names and per-level tuples (``8,6,4``) are supported; ``size`` takes ``N`` or ``N1,N2,N3``.
Used for ``npmrf3d baseline chen-wang`` and ``npmrf3d coherent``.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from .. import data
from ..io.runs import RUN_FILES
from ..model.exemplar import BUNDLED_PREFIX
from ..model.neighbourhood import VIEWS
from ._common import (
    add_exemplar_kind,
    add_run_options,
    claim_output,
    dry_run,
    parse_size,
    prepare_run,
    write_result,
)
from ._progress import run_method

__all__ = ["add_method_parser"]

#: Fields every such command handles itself (not as plain options).
_OWN = ("size", "views", "seed")


def _parse_tuple(text: str) -> int | tuple[int, ...]:
    parts = [p.strip() for p in str(text).split(",")]
    try:
        numbers = tuple(int(p) for p in parts)
    except ValueError:  # argparse words it as "argument --window: expected ..."
        raise argparse.ArgumentTypeError(f"expected an integer or comma-separated integers; "
                                         f"got {text!r}") from None
    return numbers[0] if len(numbers) == 1 else numbers


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def add_method_parser(commands, name: str, method, *, help: str, description: str,
                      out: str, field_help: dict[str, str], formatter_class,
                      refuse=None) -> argparse.ArgumentParser:
    """Add sub-command ``name`` that runs ``method`` (a :class:`npmrf3d.config.SynthesisMethod`);
    ``field_help`` explains each configuration field (every field must have an entry);
    ``refuse(args, config, per_view)``, when given, raises a
    :class:`~npmrf3d.errors.ParameterError` for options written on the command line that the
    configuration or the exemplars leave without effect (before any work, also with
    ``--dry-run``)."""
    parser = commands.add_parser(name, help=help, description=description, formatter_class=formatter_class)
    parser.add_argument(
        "exemplar", nargs="?", default=f"{BUNDLED_PREFIX}{data.DEFAULT_EXEMPLAR}", metavar="EXEMPLAR",
        help="2D exemplar image (.png, .jpg, .bmp, .gif, .tif or .npy) used for every view; omitted = "
             f"the bundled default exemplar, or '{BUNDLED_PREFIX}NAME' for a bundled one",
    )
    fields = {f.name: f for f in dataclasses.fields(method.config_class)}
    size = fields["size"].default
    parser.add_argument("--size", default=",".join(map(str, size)),
                        metavar="N", help="output size in voxels: N for an N^3 cube or N1,N2,N3; each "
                                          "divisible by 2**(levels-1)")
    group = parser.add_argument_group("method")
    for fname, f in fields.items():
        if fname in _OWN:
            continue
        text = field_help[fname]
        value = f.default
        if isinstance(value, bool):
            group.add_argument(_option(fname), action="store_true", default=value, help=text)
        elif isinstance(value, tuple):
            group.add_argument(_option(fname), type=_parse_tuple, default=",".join(map(str, value)),
                               metavar="N[,N...]", help=text)
        elif isinstance(value, int):
            group.add_argument(_option(fname), type=int, default=value, metavar="N", help=text)
        elif isinstance(value, float):
            group.add_argument(_option(fname), type=float, default=value, metavar="X", help=text)
        else:
            group.add_argument(_option(fname), default=value, metavar="NAME", help=text)
    views = parser.add_argument_group("views and exemplars")
    views.add_argument("--views", default=",".join(fields["views"].default), metavar="V[,V...]",
                       help=f"comma-separated constrained views, 1 to 3 distinct names of {', '.join(VIEWS)}")
    for view in VIEWS:
        views.add_argument(f"--exemplar-{view}", default=None, metavar="PATH",
                           help=f"a different exemplar file (or {BUNDLED_PREFIX}NAME) for the {view} "
                                f"view (default: none = EXEMPLAR)")
    add_exemplar_kind(views)
    add_run_options(parser, out=out)

    def handler(args: argparse.Namespace, argv: list[str]) -> int:
        t_start = time.perf_counter()
        options = {f: getattr(args, f) for f in fields if f not in _OWN}
        for fname, value in options.items():
            if value == fields[fname].default:
                # the field's own object: per-level defaults then adapt to --levels (make_config)
                options[fname] = fields[fname].default
        # messages name library parameters; npmrf3d.cli.main turns them into these options
        config = method.make_config(size=parse_size(args.size), views=args.views, seed=args.seed, **options)
        out_dir, checkpoint, per_view, sources = prepare_run(args, method, config)
        if refuse is not None:
            refuse(args, config, per_view)
        if args.dry_run:
            return dry_run(method, config, per_view)
        with claim_output(out_dir, args.overwrite):
            result = run_method(args, method, config, per_view, checkpoint=checkpoint,
                                t_start=t_start, unit="iter", symbol="E")
            title = f"{method.description.split(':')[0]}, {config.levels} levels, seed {config.seed}"
            write_result(out_dir, args, argv, parser.prog.replace("npmrf3d ", "", 1), result,
                         per_view, sources, title, method=method.name)
        return 0

    parser.set_defaults(handler=handler)
    parser.epilog = f"Writes {', '.join(RUN_FILES)} into the output folder."
    return parser
