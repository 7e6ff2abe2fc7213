"""What every sub-command shares: the help formatter, output folders, exemplar arguments,
the run folder writer and the one-line error (the progress bars: :mod:`._progress`).

The library reports through return values, progress callbacks and exceptions; this package is
the one place that prints and draws bars.
"""

from __future__ import annotations

import argparse
import dataclasses
import errno
import os
import pathlib
import sys

from ..errors import ParameterError
from ..io.checkpoints import is_checkpoint_file
from ..io.files import broken_link
from ..io.runs import (
    RUN_DERIVED,
    RUN_FILES,
    OutputLock,
    check_replaceable,
    run_record,
    write_run,
)
from ..methods import check_resources, estimate
from ..methods._api import settled
from ..model.exemplar import exemplar_source, resolve_exemplars
from ..model.neighbourhood import VIEWS
from ..resources import available_memory, format_bytes
from ._options import given, speak_options

PROG = "npmrf3d"


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line, ``npmrf3d <command>: error: ...``,
    with exit code 2 (the usage block only with ``--help``); sub-parsers inherit the class."""

    def error(self, message: str):
        line = " ".join(str(message).split())
        self.exit(2, f"{self.prog}: error: {line} (see '{self.prog} --help')\n")

    def parse_args(self, args=None, namespace=None):
        """As argparse's, except that an argument no parser knows is refused by the sub-command
        it was given to (``npmrf3d volume: error: unrecognized arguments: ...``)."""
        namespace, extras = self.parse_known_args(args, namespace)
        if extras:
            self._command_parser(namespace).error(f"unrecognized arguments: {' '.join(extras)}")
        return namespace

    def _command_parser(self, namespace) -> argparse.ArgumentParser:
        """The innermost sub-command's parser that ``namespace`` was parsed with."""
        parser = self
        while True:
            commands = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
            chosen = getattr(namespace, commands[0].dest, None) if commands else None
            if chosen not in (commands[0].choices if commands else {}):
                return parser
            parser = commands[0].choices[chosen]


def add_run_options(parser: argparse.ArgumentParser, *, out: str, zarr: bool = True,
                    blockwise: bool = False) -> argparse._ArgumentGroup:
    """The options of every command that makes a volume, defined once: ``--seed``, ``--out``
    (default ``out``; with ``zarr`` a name ending in ``.zarr`` is a Zarr volume, made in blocks
    with ``--blockwise`` when the command has it: ``blockwise``), ``--overwrite``, ``--quiet``,
    ``--dry-run`` and ``--checkpoint``."""
    run = parser.add_argument_group("run")
    run.add_argument("--seed", type=int, default=0, metavar="S",
                     help="random seed, a non-negative integer; the result depends on it only")
    run.add_argument("--out", default=out, metavar="DIR",
                     help="output folder for the run files; created if missing" + (
                         "; a name ending in .zarr: a chunked Zarr volume instead (napari opens it), "
                         "made at once" if zarr else "") + (
                         ", or with --blockwise in blocks (any size that fits on disk)"
                         if zarr and blockwise else ""))
    run.add_argument("--overwrite", action="store_true",
                     help="replace the files of a previous run in --out instead of refusing")
    run.add_argument("--quiet", action="store_true",
                     help="print nothing but errors (no progress bars, no summary)")
    run.add_argument("--dry-run", action="store_true",
                     help="print the memory (and rough time) the run needs and whether it fits; "
                          "write nothing")
    run.add_argument("--checkpoint", default=None, metavar="PATH",
                     help="a .npz file written after each level; if it exists and matches this run, "
                          "synthesis resumes after its last finished level (default: none = no "
                          "checkpoint)")
    return run


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    return _bounded_int(text, 1, "a positive integer")


def non_negative_int(text: str) -> int:
    """An argparse type: an integer >= 0."""
    return _bounded_int(text, 0, "a non-negative integer")


def _bounded_int(text: str, low: int, what: str) -> int:
    try:
        value = int(text)
    except (TypeError, ValueError):
        raise argparse.ArgumentTypeError(f"must be {what}; got {text!r}") from None
    if value < low:
        raise argparse.ArgumentTypeError(f"must be {what}; got {value}")
    return value


def os_error_message(exc: OSError) -> str:
    """One line for an operating-system error while reading or writing (a full disk, a missing
    permission, a path through a file)."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    where = f" '{exc.filename}'" if getattr(exc, "filename", None) else ""
    hint = "; free some space or choose another --out" if exc.errno == errno.ENOSPC else ""
    return f"cannot read or write{where}: {reason}{hint}"


def guarded(handler, args, argv, option_names=()) -> int:
    """Run a command handler and turn every user-facing failure into one line and an exit code:
    2 for user errors, operating-system errors (a full disk) and memory exhaustion, 130 for
    Ctrl-C or SIGTERM."""
    try:
        return handler(args, argv)
    except ParameterError as exc:
        return error(str(exc), option_names)
    except MemoryError:
        return error("out of memory; lower --size (--dry-run shows what a run needs)")
    except OSError as exc:
        if isinstance(exc, BrokenPipeError):
            raise
        return error(os_error_message(exc))


class HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows every default and keeps the hand-formatted description and examples.

    A help string that already says ``(default: ...)`` in words keeps it as written; a flag
    (off unless given) shows none. Option names get 28 columns, so that most help starts beside
    its option.
    """

    def __init__(self, prog, indent_increment=2, max_help_position=28, width=None):
        super().__init__(prog, indent_increment, max_help_position, width)

    def _get_help_string(self, action):
        text = action.help or ""
        if "(default:" in text or (action.default is False and not action.nargs):  # a flag: off
            return text
        return super()._get_help_string(action)


def default(config_class: type, name: str):
    """The default of field ``name`` of a config dataclass (where the CLI takes its defaults).

    >>> from npmrf3d.config import SynthesisConfig
    >>> default(SynthesisConfig, "window")
    7
    """
    for f in dataclasses.fields(config_class):
        if f.name == name:
            if f.default is not dataclasses.MISSING:
                return f.default
            if f.default_factory is not dataclasses.MISSING:
                return f.default_factory()
    raise KeyError(f"{config_class.__name__} has no field {name!r} with a default")


def choices(names) -> str:
    """A ``{a,b,c}`` metavar from the names of a registry."""
    return "{" + ",".join(names) + "}"


def say(text: str, *, error: bool = False) -> None:
    """Write one line of command-line output (stdout, or stderr for diagnostics): the one place
    the package writes to the terminal (bars aside); library code reports through callbacks."""
    stream = sys.stderr if error else sys.stdout
    stream.write(f"{text}\n")
    stream.flush()


def error(message: str, option_names=()) -> int:
    """Print ``npmrf3d: error: <message>`` on one line (library names turned into options by
    :func:`speak_options`)."""
    line = " ".join(part.strip() for part in str(message).splitlines() if part.strip())
    line = speak_options(line, option_names)
    say(f"{PROG}: error: {line or 'invalid input'}", error=True)
    return 2


def parse_size(text: str) -> int | tuple[int, ...]:
    """``N`` or ``N1,N2,N3`` as an int or a tuple."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        raise ParameterError(
            f"size must be an integer N or three comma-separated integers N1,N2,N3; got {text!r}"
        ) from None
    return numbers[0] if len(numbers) == 1 else tuple(numbers)


def check_out(out: pathlib.Path, overwrite: bool, files: tuple[str, ...] = RUN_FILES,
              what: str = "a run") -> None:
    """The output folder must be usable (checked before the work; the writers check again).

    It may exist if it holds none of ``files`` (or ``overwrite`` is set) and is writable, or
    be creatable under its nearest existing ancestor (never through a symbolic link that
    leads nowhere). ``what`` names ``files`` in the message.
    """
    link = broken_link(out)
    if link is not None:
        raise ParameterError(f"output folder '{out}' {link}; remove the link or choose another --out")
    if out.exists():
        if not out.is_dir():
            raise ParameterError(f"output folder '{out}' exists and is not a folder")
        previous = [name for name in files if (out / name).exists()]
        if previous and not overwrite:
            raise ParameterError(
                f"output folder '{out}' already holds {what} ({', '.join(previous)}); "
                "pass --overwrite or choose another --out"
            )
        if not os.access(out, os.W_OK | os.X_OK):
            raise ParameterError(f"output folder '{out}' is not writable")
        return
    ancestor = out.absolute().parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ParameterError(f"output folder '{out}' cannot be created: '{ancestor}' is not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ParameterError(f"output folder '{out}' cannot be created: '{ancestor}' is not writable")


def output_folder(args: argparse.Namespace, files: tuple[str, ...] = RUN_FILES) -> pathlib.Path:
    """The checked ``--out`` folder of a command that writes a run folder (with ``--overwrite``
    never the working folder, one of its parents or the home folder: the swap would pull the
    folder away from under the calling shell); ``files``: the run's files it must not hold."""
    if not args.out.strip():
        raise ParameterError("--out must name a folder; got an empty string")
    out = pathlib.Path(args.out)
    resolved = pathlib.Path(os.path.realpath(out))  # realpath: a link loop is check_out's to refuse
    if resolved == pathlib.Path(resolved.anchor):
        raise ParameterError(f"--out '{args.out}' is the root of the file system; name a folder for "
                             "the run's files")
    if args.overwrite:
        check_replaceable(out)
    check_out(out, args.overwrite, files)
    return out


def check_checkpoint(path: pathlib.Path | None, out: pathlib.Path | None = None, *,
                     out_file: bool = False) -> None:
    """A ``--checkpoint`` must be a file (or not exist yet) in an existing folder; an existing
    file must be a checkpoint of npmrf3d (a file of the user's is never read as one, nor
    replaced); and it must not clash with the output ``out``: not ``out`` itself, not a folder
    holding it, not one of the files a run folder ``out`` receives or an overwrite drops
    (``out_file``: ``out`` is a file, e.g. a model, and only the same path clashes). Checked
    before any work."""
    if path is None:
        return
    if path.exists() and not path.is_file():
        raise ParameterError(f"checkpoint '{path}' exists and is not a file")
    if not path.absolute().parent.is_dir():
        raise ParameterError(f"folder of checkpoint '{path}' does not exist")
    if not os.access(path.absolute().parent, os.W_OK | os.X_OK):
        # written after the first level (or training steps): refuse before that work
        raise ParameterError(f"folder of checkpoint '{path}' is not writable; choose another "
                             "--checkpoint")
    if out is not None:
        mine, theirs = path.resolve(), out.resolve()
        if mine == theirs:
            raise ParameterError(f"checkpoint '{path}' is the output '{out}' itself; "
                                 "choose a checkpoint path apart from --out")
        if not out_file and mine in theirs.parents:
            raise ParameterError(f"checkpoint '{path}' would have to be a folder holding the output "
                                 f"folder '{out}'; choose a checkpoint path apart from --out")
        if not out_file and mine.parent == theirs and mine.name in (*RUN_FILES, *RUN_DERIVED):
            raise ParameterError(f"checkpoint '{path}' is the run file {mine.name} of the output "
                                 f"folder '{out}', which the run writes or replaces; choose "
                                 "another checkpoint path")
    if path.is_file() and not is_checkpoint_file(path):
        raise ParameterError(f"checkpoint '{path}' is not a checkpoint file of npmrf3d (it is "
                             "left untouched); choose another --checkpoint")


def add_exemplar_kind(group) -> None:
    """``--exemplar-kind``: how a 3-D array or TIFF stack given as a 2D exemplar is read."""
    group.add_argument(
        "--exemplar-kind", default="auto", metavar="{auto,image}", choices=("auto", "image"),
        help="auto refuses a file recognised as a volume (three similar axes, a TIFF stack; "
             "use 'npmrf3d volume' for those) and an ambiguous 3-D array; image reads any 3-D "
             "array as an image H x W x C",
    )


def view_sources(args: argparse.Namespace):
    """(EXEMPLAR file, {view: --exemplar-VIEW file}, views -> {view: name for run.json}). An
    EXEMPLAR not written is None: the default, which the views without an --exemplar-VIEW read
    and which is not refused as unused when every view has its own."""
    exemplar, exemplar_name = exemplar_source(args.exemplar)
    if not given(args, "exemplar"):
        exemplar = None
    per_view_sources, names = {}, {}
    for view in VIEWS:
        source, name = exemplar_source(getattr(args, f"exemplar_{view}"))
        if source is not None:
            per_view_sources[view], names[view] = source, name
    return exemplar, per_view_sources, lambda views: {v: names.get(v, exemplar_name) for v in views}


def prepare_run(args: argparse.Namespace, method, config, *, whole: bool = True):
    """Checks and inputs shared by every command that runs a method of the registry, in the
    order that keeps user errors ahead of any work: the ``--out`` folder, the ``--checkpoint``,
    the exemplars, and (``whole``: the volume made at once) the memory. Returns (the
    configuration settled on the exemplars, out, checkpoint, per-view exemplars, per-view names
    for run.json)."""
    out = output_folder(args, RUN_FILES if whole else ())  # a Zarr volume checks its own identity
    checkpoint = pathlib.Path(args.checkpoint) if getattr(args, "checkpoint", None) is not None else None
    check_checkpoint(checkpoint, out)
    exemplar, per_view_sources, source_names = view_sources(args)
    per_view = resolve_exemplars(exemplar, per_view_sources, config.views, **method.fit(config),
                                 exemplar_kind=getattr(args, "exemplar_kind", "auto"))
    config = settled(method, config, per_view)
    if whole and not getattr(args, "dry_run", False):
        check_resources(method, config, per_view, hint=_RESOURCE_HINT)
    return config, out, checkpoint, per_view, source_names(config.views)


_RESOURCE_HINT = ("lower --size (or --levels, the exemplar size), or make it in blocks with --out VOL.zarr; "
                  "--dry-run shows the estimate")


class claim_output:
    """``with claim_output(out, overwrite):`` the exclusive lock on ``--out`` for a whole run
    (a second run into the same folder refuses at once), with the folder checked again under it."""

    def __init__(self, out: pathlib.Path, overwrite: bool):
        self.out, self.overwrite, self.lock = out, overwrite, OutputLock(out)

    def __enter__(self):
        self.lock.acquire()
        try:
            check_out(self.out, self.overwrite)
        except BaseException:
            self.lock.release()
            raise
        return self

    def __exit__(self, *exc):
        self.lock.release()


def dry_run(method, config, per_view: dict) -> int:
    """``--dry-run``: print what the run would need and whether it fits; write nothing."""
    needed = estimate(method, config, per_view)
    available = available_memory()
    size = "x".join(str(n) for n in config.size)
    levels = getattr(config, "levels", None)  # the settled pyramid, where the method has one
    say(f"{method.name} {size}{'' if levels is None else f', {levels} levels'}: {needed.describe()}")
    if available is not None:
        fits = "fits" if needed.bytes <= available else "does NOT fit"
        say(f"available memory: {format_bytes(available)} (the run {fits})")
    return 0


def write_result(out: pathlib.Path, args: argparse.Namespace, argv: list[str], command: str,
                 result, per_view: dict, sources: dict, title: str, *, method: str | None = None,
                 **extra) -> None:
    """Write the run folder (volume, TIFF, preview, run.json with ``extra``) and say so."""
    record = run_record(command, result, exemplars=sources, method=method, argv=[PROG, *argv],
                        **extra)
    write_run(out, volume=result.volume, exemplars=per_view, record=record,
              overwrite=args.overwrite, title=title)
    if not args.quiet:
        shape = "x".join(str(n) for n in result.volume.shape)
        labels = f"{len(result.labels)} labels, " if len(result.labels) else ""
        say(f"wrote {out}{os.sep}: {', '.join(RUN_FILES)}")
        say(f"volume {shape} (N1xN2xN3xC), {labels}{result.timings['total']:.1f} s")
