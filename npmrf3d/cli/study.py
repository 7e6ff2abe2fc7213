"""Sub-commands ``npmrf3d study NAME`` and ``npmrf3d report RESULTS_DIR``.

Registered by :data:`npmrf3d.cli.main.COMMANDS`; :func:`study_main` is the entry point of the
one-line scripts in the repository's ``studies/`` folder. The bar over a study's runs is drawn
here (:class:`npmrf3d.cli._progress.RunsProgress`), called back by the runner.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from ..errors import ParameterError
from ..studies.catalog import NPK_FULL_EXEMPLARS, STUDIES, STUDY_EXEMPLARS, get_study
from ..studies.report import write_report
from ..studies.runner import run_study
from ._common import (
    PROG,
    HelpFormatter,
    Parser,
    guarded,
    non_negative_int,
    positive_int,
    say,
)
from ._options import given, given_options
from ._progress import RunsProgress
from ._streams import guard_streams
from .synth import OPTION_NAMES

__all__ = ["register", "study_main"]

_DEFAULT_OUT = "study-results"


def _add_study_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true",
                        help="the tiny variant (8^3-16^3 volumes, one seed; what the tests run) "
                             "instead of the full one")
    parser.add_argument("--out", default=_DEFAULT_OUT, metavar="DIR",
                        help="results root; the study writes DIR/<study>/ (run folders, "
                             "results.csv, figures, study.json)")
    parser.add_argument("--scheduler", default="local", metavar="ADDRESS|local|serial",
                        help="'local' starts a Dask LocalCluster on this machine, 'serial' runs "
                             "in this process one run after the other, an address such as "
                             "tcp://host:8786 uses an existing Dask scheduler (start one with "
                             "'dask scheduler' and 'dask worker ADDRESS')")
    parser.add_argument("--workers", type=positive_int, default=None, metavar="N",
                        help="worker processes of the local cluster (default: None = the number "
                             "of cores divided by --threads)")
    parser.add_argument("--threads", type=positive_int, default=None, metavar="T",
                        help="numba threads per run (default: None = cores / workers on a local "
                             "cluster, numba's default when serial, the workers' "
                             "NUMBA_NUM_THREADS on an existing scheduler); workers x threads "
                             "never exceeds the cores")
    parser.add_argument("--seeds", type=non_negative_int, nargs="+", default=None, metavar="S",
                        help="seeds to run (default: None = the study's: 0 1 2 in full mode, "
                             "0 in quick mode)")
    parser.add_argument("--exemplars", nargs="+", default=None, metavar="NAME",
                        help="exemplars to run (default: None = the study's); bundled names, "
                             "'etr:NAME' for an installed Extreme Tux Racer terrain, or image "
                             f"files; the NP_K study's full list is {' '.join(STUDY_EXEMPLARS)} "
                             f"(its full variant runs {' '.join(NPK_FULL_EXEMPLARS)})")
    parser.add_argument("--size", type=positive_int, nargs="+", default=None, metavar="N",
                        help="volume sides (default: None = the study's: 64 in full mode)")
    parser.add_argument("--levels", type=positive_int, default=None, metavar="L",
                        help="pyramid levels (default: None = the study's: 3 in full mode)")
    parser.add_argument("--volume", default=None, metavar="FILE",
                        help="real 3-D volume (.npy or .tif) for the groundtruth study "
                             "(default: None; required by groundtruth)")
    parser.add_argument("--slice-axis", type=int, default=0, choices=(0, 1, 2), metavar="A",
                        help="groundtruth: the exemplar is a slice across this axis of --volume")
    parser.add_argument("--slice-index", type=non_negative_int, default=None, metavar="I",
                        help="groundtruth: index of that slice (default: None = the middle)")
    parser.add_argument("--slices", type=int, default=1, choices=(1, 3), metavar="K",
                        help="groundtruth: 1 = that one slice is every view's exemplar; 3 = each "
                             "view takes the volume's middle slice in its own plane (front: "
                             "axes 0-1, right: 1-2, top: 0-2), for an anisotropic material "
                             "(default: 1)")
    parser.add_argument("--quiet", action="store_true",
                        help="no progress bar and no messages, only errors")


def _refuse_unread(args: argparse.Namespace, study) -> None:
    """One line for an option written on the command line that this study run would not read
    (the written value may be the default: the library sees only values)."""
    if given(args, "workers") and args.scheduler != "local":
        raise ParameterError(f"--workers sizes a local cluster and changes nothing with --scheduler "
                             f"{args.scheduler}; drop it or use --scheduler local")
    if not study.needs_volume:
        for name in ("volume", "slice_axis", "slice_index", "slices"):
            if given(args, name):
                raise ParameterError(f"--{name.replace('_', '-')} changes nothing in study "
                                     f"{study.name}, which compares with no real volume; drop it")
    elif given(args, "slice_axis") and args.slices == 3:
        raise ParameterError("--slice-axis picks the axis of one slice; with --slices 3 each view "
                             "takes the middle slice in its own plane: drop it")


def _run(args: argparse.Namespace, name: str | None = None) -> int:
    study = get_study(name or args.name)
    if not str(args.out).strip():
        raise ParameterError("--out must name a folder; got an empty string")
    _refuse_unread(args, study)
    echo = None if args.quiet else say
    progress = RunsProgress(study.name, enabled=not args.quiet)
    try:
        outcome = run_study(
            study, mode="quick" if args.quick else "full", out=args.out,
            scheduler=None if args.scheduler == "local" else args.scheduler, workers=args.workers,
            threads=args.threads, seeds=args.seeds, exemplars=args.exemplars, sizes=args.size,
            levels=args.levels, volume=args.volume, slice_axis=args.slice_axis,
            slice_index=args.slice_index, slices=args.slices, progress=progress, echo=echo)
    finally:
        progress.close()
    if echo is not None:
        say(f"report: npmrf3d report {outcome.study_dir}")
    failed, total = outcome.counts.get("failed", 0), len(outcome.rows)
    if failed:
        which = "all" if failed == total else f"{failed} of"
        say(f"{PROG} study: error: {which} {total} runs failed (see the 'error' column of "
            f"{outcome.study_dir / 'results.csv'}); re-running the command retries them", error=True)
        return 1
    return 0


def _study_handler(args, argv) -> int:
    return _run(args)


def _report_handler(args, argv) -> int:
    path = write_report(args.results_dir, args.out, overwrite=args.overwrite,
                        warn=lambda line: say(f"{PROG} report: {line}", error=True))
    say(f"wrote {path}")
    return 0


def register(commands, formatter_class) -> None:
    """Add ``study`` and ``report`` to the ``npmrf3d`` sub-command parsers."""
    names = ", ".join(STUDIES)
    study = commands.add_parser(
        "study",
        help="run one of the paper's comparisons as a grid of runs on Dask",
        description=(
            "Run a study (a grid of exemplars x methods x seeds) on a Dask cluster, or resume it:\n"
            "finished runs are skipped, failed runs are recorded and tried again next time.\n"
            f"studies: {names}\n\n"
            "examples:\n"
            "  npmrf3d study heuristics --quick                 # tiny, a minute\n"
            "  npmrf3d study npk --workers 2                    # full, local cluster\n"
            "  npmrf3d study cooling --scheduler tcp://10.0.0.5:8786\n"
            "  npmrf3d study groundtruth --volume scan.tif --slice-axis 2\n"
            "  npmrf3d study groundtruth --volume fibres.tif --slices 3    # anisotropic"
        ),
        formatter_class=formatter_class,
    )
    study.add_argument("name", metavar="NAME", help=f"the study: one of {names}")
    _add_study_options(study)
    study.set_defaults(handler=_study_handler)

    report = commands.add_parser(
        "report",
        help="write one self-contained HTML page of study results",
        description="Write one HTML file (figures embedded, no network needed) with the tables, "
                    "parameters, versions, seeds, timings and failures of every study under "
                    "RESULTS_DIR (or of the one study RESULTS_DIR is).",
        formatter_class=formatter_class,
    )
    report.add_argument("results_dir", metavar="RESULTS_DIR",
                        help=f"a study folder (holding results.csv) or a results root such as "
                             f"{_DEFAULT_OUT}")
    report.add_argument("--out", default=None, metavar="FILE",
                        help="HTML file to write (default: None = RESULTS_DIR/report.html)")
    report.add_argument("--overwrite", action="store_true",
                        help="replace an existing report file instead of refusing")
    report.set_defaults(handler=_report_handler)


def study_main(name: str, argv: list[str] | None = None) -> int:
    """Run study ``name`` with the ``npmrf3d study`` options (for ``studies/<name>.py``)."""
    study = get_study(name)
    parser = Parser(
        prog=f"{pathlib.Path(sys.argv[0]).name}",
        description=f"{study.title}. {study.question} (same as '{PROG} study {name}')",
        formatter_class=HelpFormatter,
    )
    _add_study_options(parser)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    fresh = Parser(formatter_class=HelpFormatter)
    _add_study_options(fresh)
    args.given = given_options(fresh, list(sys.argv[1:] if argv is None else argv))
    with guard_streams():  # stdout or stderr closed or full: the study still runs
        try:
            return guarded(lambda a, _: _run(a, name), args, argv, OPTION_NAMES)
        except KeyboardInterrupt:
            say(f"{PROG}: interrupted", error=True)
            return 130
