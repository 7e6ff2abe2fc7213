"""Every method's sub-command, built from its frozen configuration.

Each option field of the method's configuration (:func:`npmrf3d.options.option`) becomes an
option (``window`` -> ``--window``) whose type, limits, choices, help text, section and default
are read from the field itself, so the API, the configuration, ``--help`` and the docs cannot
disagree; values go through the method's own ``make_config``, which validates them and refuses an
option the run would not read. Integers, reals, names, flags and per-level lists (``8,6,4``) are
supported; ``size`` takes ``N`` or ``N1,N2,N3``; a field whose default the run decides
(``decided``) defaults to ``None`` here and ``--help`` says what decides it.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

from .. import data
from ..config import DEFAULT_SIZE
from ..io.runs import RUN_FILES
from ..model.exemplar import BUNDLED_PREFIX
from ..model.neighbourhood import VIEWS
from ..options import default_text, field_default, flag_name, flat_options, options_of, refuse_inapplicable
from ._common import (
    add_exemplar_kind,
    add_run_options,
    choices,
    parse_size,
    prepare_run,
)
from ._blocks import add_block_options, blockwise_requested, run_to_output, zarr_output
from ._options import given

__all__ = ["add_method_parser", "config_options", "method_options", "refuse_written"]

#: The order of the sections of ``--help``; a field's ``group`` names one.
SECTIONS = ("volume and pyramid", "method", "energy and search", "relaxation", "views and exemplars", "blocks")
_METAVARS = {"int": "N", "real": "X", "levels": "N[,N..]", "text": "NAME"}


def _parse_tuple(text: str) -> int | tuple[int, ...]:
    parts = [p.strip() for p in str(text).split(",")]
    try:
        numbers = tuple(int(p) for p in parts)
    except ValueError:  # argparse words it as "argument --window: expected ..."
        raise argparse.ArgumentTypeError(f"expected an integer or comma-separated integers; "
                                         f"got {text!r}") from None
    return numbers[0] if len(numbers) == 1 else numbers


def method_options(config_class) -> dict:
    """{name: (field, option)} of every option of ``config_class`` the command line takes: its
    fields, with a nested configuration's fields (the decision rule) in its place."""
    return {name: (f, opt) for name, (f, opt) in flat_options(config_class).items() if opt.kind != "own"}


def _add_option(group, name: str, f: dataclasses.Field, opt) -> None:
    default = None if opt.decided is not None else field_default(f)
    text, metavar = opt.help, opt.metavar or _METAVARS.get(opt.kind)
    if opt.kind == "choice" and not opt.metavar:
        metavar = choices(opt.names()) if len(choices(opt.names())) <= 14 else "NAME"
        if not all(n in text for n in opt.names()):
            text += f": {', '.join(opt.names())}"
    text += f" (default: {opt.decided})" if opt.decided is not None else ""
    if opt.kind == "flag":
        group.add_argument(flag_name(name), action="store_true", default=default, help=text)
        return
    kind = {"int": int, "real": float, "levels": _parse_tuple}.get(opt.kind)
    if opt.kind == "levels" and default is not None:
        default = default_text(f, opt)
    group.add_argument(flag_name(name), type=kind, default=default, metavar=metavar, help=text)


def config_options(args: argparse.Namespace, config_class) -> dict:
    """The values of ``config_class``'s options on the command line ``args``, for ``make_config``;
    a per-level default is passed as the field's own object, so that it adapts to ``--levels``."""
    values = {}
    for name, (f, opt) in method_options(config_class).items():
        value = getattr(args, name)
        if opt.kind == "levels" and value == _parse_tuple(default_text(f, opt)):
            value = field_default(f)
        values[name] = value
    return values


def _exemplar_inputs(parser: argparse.ArgumentParser, sections: dict) -> None:
    """The inputs of a command with 2D exemplars: the exemplar, the constrained views and one
    exemplar per view."""
    parser.add_argument(
        "exemplar", nargs="?", default=f"{BUNDLED_PREFIX}{data.DEFAULT_EXEMPLAR}", metavar="EXEMPLAR",
        help=f"2D image or .npy for every view, or {BUNDLED_PREFIX}NAME (default: %(default)s)")
    views = sections["views and exemplars"]
    views.add_argument("--views", default=",".join(VIEWS), metavar="V[,V..]",
                       help=f"constrained views, of {', '.join(VIEWS)}")
    for view in VIEWS:
        views.add_argument(f"--exemplar-{view}", default=None, metavar="PATH",
                           help=f"the {view} view's (default: EXEMPLAR)")
    add_exemplar_kind(views)


def refuse_written(args: argparse.Namespace, config) -> None:
    """Refuse an option written on the command line that a run of ``config`` would not read, also
    when its value is the default (the API, which cannot tell, refuses values set away from it)."""
    refuse_inapplicable(config, [name for name in options_of(type(config)) if given(args, name)])


def add_method_parser(commands, name: str, method, *, help: str, description: str,
                      out: str, formatter_class, refuse=None, handler=None, aliases=(),
                      extra=None, inputs=None, zarr: bool = True) -> argparse.ArgumentParser:
    """Add sub-command ``name`` (and ``aliases``) that runs ``method`` (a
    :class:`npmrf3d.config.SynthesisMethod`) with its configuration's options.

    ``refuse(args, config, per_view)``, when given, raises a :class:`~npmrf3d.errors.ParameterError`
    for what only the exemplars can tell (before any work, also with ``--dry-run``);
    ``handler(args, argv)`` replaces the run below; ``extra(parser, sections)`` adds the command's
    own options (a later option of the same name replaces a field's); ``inputs(parser, sections)``
    replaces the 2D exemplar, its views and the per-view exemplars (a 3D exemplar's command; its
    ``usage`` attribute names the input in the usage line); ``zarr``: ``--out X.zarr`` makes a
    Zarr volume (else the command refuses it, and its help does not offer it)."""
    parser = commands.add_parser(name, aliases=list(aliases), help=help, description=description,
                                 formatter_class=formatter_class, conflict_handler="resolve",
                                 usage=f"%(prog)s {getattr(inputs, 'usage', '[EXEMPLAR]')} [options]")
    sections = {title: parser.add_argument_group(title) for title in SECTIONS}
    sections["volume and pyramid"].add_argument(
        "--size", default=str(DEFAULT_SIZE), metavar="N",
        help="output side N, or N1,N2,N3")
    for fname, (f, opt) in method_options(method.config_class).items():
        _add_option(sections[opt.group], fname, f, opt)
    (inputs or _exemplar_inputs)(parser, sections)
    if extra is not None:
        extra(parser, sections)
    blockwise = "blockwise" in method_options(method.config_class)
    add_run_options(parser, out=out, zarr=zarr, blockwise=blockwise)
    if blockwise:
        add_block_options(sections["blocks"], sampler=False)

    def run_command(args: argparse.Namespace, argv: list[str]) -> int:
        t_start = time.perf_counter()
        options = config_options(args, method.config_class)
        if hasattr(args, "block"):
            blockwise_requested(args)
        # messages name library parameters; npmrf3d.cli.main turns them into these options
        config = method.make_config(size=parse_size(args.size), views=args.views, seed=args.seed, **options)
        refuse_written(args, config)
        config, out_dir, checkpoint, per_view, sources = prepare_run(args, method, config, whole=not zarr_output(args))
        if refuse is not None:
            refuse(args, config, per_view)
        title = f"{method.description.split(':')[0]}, {config.levels} levels, seed {config.seed}"
        return run_to_output(args, argv, parser.prog.replace("npmrf3d ", "", 1), method, config, per_view,
                             sources, title, out=out_dir, checkpoint=checkpoint, t_start=t_start, unit="iter",
                             symbol="E")

    parser.set_defaults(handler=handler or run_command)
    parser.epilog = f"Writes {', '.join(RUN_FILES)} into the output folder."
    return parser
