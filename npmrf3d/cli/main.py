"""The ``npmrf3d`` parser and entry point.

Every user mistake (bad option values, unreadable exemplars, an output folder that already
holds a run, a run larger than the memory, a full disk) is reported as one line
``npmrf3d: error: <message>`` on stderr with exit code 2, before any synthesis work starts and
without leaving files behind. Argparse usage errors are one line too,
``npmrf3d <command>: error: ...`` with exit 2 (:class:`npmrf3d.cli._common.Parser`); Ctrl-C exits
with 130.

Sub-commands are the modules of :data:`COMMANDS`, a static list: each has
``register(commands, formatter_class)``, which adds its parser and sets ``handler=fn`` with
``fn(args, argv) -> exit code``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import warnings

from .. import __version__
from .._kernels._jit import on_first_compile
from ..errors import InputNote
from . import (
    _interrupt,
    _streams,
    baseline,
    coherent,
    info,
    materials,
    metrics,
    neural,
    study,
    synth,
    volume,
)
from ..io.zarr_blocks import finished_blocks
from ._blocks import zarr_output
from ._common import PROG, HelpFormatter, Parser, error, guarded, say
from ._progress import compile_notice
from ._options import environment_problem, given_options, option_strings

__all__ = ["COMMANDS", "build_parser", "main"]

#: The sub-command modules, in the order ``--help`` lists them (``study`` adds ``report``).
COMMANDS = (synth, coherent, info, metrics, study, baseline, volume, neural, materials)
#: Library parameter names that messages should call by their option names (besides the
#: options of the command that ran, which :func:`main` adds).
OPTION_NAMES = synth.OPTION_NAMES


def build_parser() -> argparse.ArgumentParser:
    """The ``npmrf3d`` argument parser with every sub-command of :data:`COMMANDS`."""
    parser = Parser(
        prog=PROG,
        description="3D solid textures from one 2D exemplar with a non-parametric Markov random field.",
        epilog="Run 'npmrf3d synth --help' for the synthesis options.",
        formatter_class=HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for module in COMMANDS:
        module.register(commands, HelpFormatter)
    return parser


def interrupted_message(args) -> str:
    """One line after Ctrl-C or SIGTERM: where the checkpoint is and how to resume."""
    checkpoint = getattr(args, "checkpoint", None)
    if hasattr(args, "block") and zarr_output(args):
        done = len(finished_blocks(args.out))
        if done:
            return (f"interrupted; the {done} finished block{'s' * (done != 1)} are kept in '{args.out}': "
                    f"run the same command again to make the others")
        return f"interrupted before the first block finished; nothing to resume in '{args.out}'"
    if checkpoint and os.path.isfile(checkpoint):
        return (f"interrupted; the levels finished so far are in the checkpoint '{checkpoint}': "
                f"run the same command again to resume")
    if checkpoint:
        return (f"interrupted before the first level finished; nothing to resume from (the "
                f"checkpoint '{checkpoint}' is written after each level)")
    if getattr(args, "handler", None) is not None and hasattr(args, "overwrite"):
        return "interrupted; nothing was written (--checkpoint FILE makes a long run resumable)"
    return "interrupted"


def _print_notes(*, quiet: bool) -> None:
    """Show the library's :class:`~npmrf3d.errors.InputNote` warnings, every time, as one line
    ``npmrf3d: note: ...`` on stderr (none with ``--quiet``); other warnings as Python shows
    them. Call inside ``warnings.catch_warnings()``, which restores both afterwards."""
    show = warnings.showwarning

    def note(message, category, filename, lineno, file=None, line=None):
        if not issubclass(category, InputNote):
            return show(message, category, filename, lineno, file, line)
        if not quiet:
            say(f"{PROG}: note: {message}", error=True)

    warnings.simplefilter("always", InputNote)
    warnings.showwarning = note


#: Commands whose whole purpose is to print: their output lost is their failure (exit 1).
PRINTING = ("info",)


def _prints_only(args) -> bool:
    """Whether the command's output is all it does (``info``, ``--help``, ``--version``,
    ``--dry-run``), so that output lost is the command failed."""
    return args is None or args.command in PRINTING or bool(getattr(args, "dry_run", False))


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (0 ok, 1 the output of a command that only
    prints was lost, 2 user error, 130 interrupted).

    Ctrl-C and SIGTERM end a command alike, from its first moment to its last (one line, exit
    130), latched so that none is lost (:mod:`npmrf3d.cli._interrupt`). Standard output or error
    closed or full never stops a command's work (:func:`npmrf3d.cli._streams.guard_streams`): a
    run still writes its folder and exits 0."""
    previous = _interrupt.install()
    try:
        with _streams.guard_streams() as streams:
            args, code = _interruptible(argv)
            reason = _streams.lost_reason(streams["stdout"])
            if code == 0 and reason is not None and _prints_only(args):
                if reason:  # a reader that hung up ('npmrf3d info | head') is not reported
                    say(f"{PROG}: error: cannot write to standard output: {reason}", error=True)
                return 1
            return code
    finally:
        _interrupt.restore(previous)


def _interruptible(argv: list[str] | None) -> tuple[argparse.Namespace | None, int]:
    """:func:`_main`, whose interruption (Ctrl-C, SIGTERM) is one line and exit code 130."""
    parsed: list[argparse.Namespace] = []
    try:
        with warnings.catch_warnings():
            return _main(argv, parsed)
    except KeyboardInterrupt:
        return _stopped(parsed)
    except BrokenPipeError:  # a write around the guarded streams: stop quietly, as other tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return (parsed or [None])[0], 1
    except Exception:
        # a Ctrl-C that landed inside numba's compiler leaves it half-done, and the next call
        # fails ("no compiled object yet"): that failure is the interrupt's, not a bug
        if _interrupt.pending():
            return _stopped(parsed)
        raise


def _stopped(parsed: list[argparse.Namespace]) -> tuple[argparse.Namespace | None, int]:
    """Say that the command was interrupted (and what it keeps); exit code 130."""
    args = (parsed or [None])[0]
    say(f"{PROG}: {interrupted_message(args)}", error=True)
    return args, 130


def _main(argv: list[str] | None, parsed: list) -> tuple[argparse.Namespace | None, int]:
    """(the parsed arguments or None, the exit code): the body of :func:`main`; the parsed
    arguments are also put in ``parsed`` as soon as they are known."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and usage errors (argparse printed them)
        return None, exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    parsed.append(args)
    problem = environment_problem()
    if problem is not None:
        return args, error(problem)
    args.given = given_options(build_parser(), argv)  # what the user wrote, not the defaults
    option_names = {**{name: "--" + name.replace("_", "-") for name in OPTION_NAMES},
                    **neural.OPTION_NAMES, **option_strings(parser, args)}
    quiet = bool(getattr(args, "quiet", False))
    with _compile_notice(quiet):
        _print_notes(quiet=quiet)
        return args, guarded(args.handler, args, argv, option_names)


def _compile_notice(quiet: bool):
    """One line on stderr when the kernels compile (a cold cache), none with ``--quiet``."""
    notice = compile_notice(enabled=not quiet)
    return contextlib.nullcontext() if notice is None else on_first_compile(notice)
