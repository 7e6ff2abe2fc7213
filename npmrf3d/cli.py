"""Command line: ``npmrf3d synth`` (make a solid texture) and ``npmrf3d info`` (the machine).

Every user mistake (bad option values, unreadable exemplars, an output folder that already
holds a run) is reported as one line ``npmrf3d: error: <message>`` on stderr with exit code 2,
before any synthesis work starts and without leaving files behind. Argparse usage errors also
exit with 2 (with argparse's own message); Ctrl-C exits with 130.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import os
import pathlib
import sys
import time

from . import data, io
from .config import VARIANTS
from .errors import ParameterError
from .exemplar import BUNDLED_PREFIX, exemplar_source, resolve_exemplars
from .neighborhood import VIEWS
from .pyramid import INHERIT, UPSAMPLING
from .runs import RUN_FILES, run_record, write_run

__all__ = ["main", "build_parser"]

PROG = "npmrf3d"
_DEFAULT_RULE = VARIANTS["default"]
_HEURISTIC_NAMES = ("ML_H1a", "ML_H1b", "ML_H2a", "ML_H2b")
#: Modules that add further sub-commands: each has ``register(commands, formatter_class)``,
#: which adds its parser and sets ``handler=fn`` with ``fn(args, argv) -> exit code``.
_COMMAND_MODULES: tuple[str, ...] = ("npmrf3d._cli_metrics", "npmrf3d.studies.cli", "npmrf3d.baselines.cli")


# --------------------------------------------------------------------------- parser


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter, argparse.RawDescriptionHelpFormatter):
    """Shows every default and keeps the hand-formatted description and examples.

    A help string that already says ``(default: ...)`` in words keeps it as written.
    """

    def _get_help_string(self, action):
        text = action.help or ""
        return text if "(default:" in text else super()._get_help_string(action)


def _rule_help(text: str, field: str) -> str:
    value = getattr(_DEFAULT_RULE, field)
    return f"{text} (default: None = the variant's value; the 'default' variant uses {value})"


def build_parser() -> argparse.ArgumentParser:
    """The ``npmrf3d`` argument parser with its ``synth`` and ``info`` sub-commands."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog=PROG,
        description="3D solid textures from one 2D exemplar with a non-parametric Markov random field.",
        epilog="Run 'npmrf3d synth --help' for the synthesis options.",
        formatter_class=_HelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    synth = commands.add_parser(
        "synth",
        help="synthesise a solid texture from an exemplar and write a run folder",
        description=(
            "Synthesise a solid texture whose slices look like the exemplar and write\n"
            f"{', '.join(RUN_FILES)} into the output folder.\n\n"
            "examples:\n"
            "  npmrf3d synth                                  # bundled exemplar, 32^3\n"
            "  npmrf3d synth wood.png --size 64 --out wood    # your own image\n"
            "  npmrf3d synth --size 8 --levels 1 --window 3   # a tiny, quick run"
        ),
        formatter_class=_HelpFormatter,
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
        "--size", default="32", metavar="N",
        help="output size in voxels: N for an N^3 cube or N1,N2,N3; each divisible by 2**(levels-1)",
    )
    shape.add_argument(
        "--window", type=int, default=7, metavar="W",
        help="side of each view's square neighbourhood, an odd integer from 3 to 15",
    )
    shape.add_argument(
        "--levels", type=int, default=3, metavar="L",
        help="number of pyramid levels (the paper's scales), an integer from 1 to 8",
    )
    shape.add_argument(
        "--upsample", default=None, metavar="{" + ",".join(UPSAMPLING) + "}",
        help="how a level initialises the next finer one: 1/8 keeps only the inherited voxel and "
             "draws the other 7 at random, 8/8 copies the parent into all 8 "
             "(default: none = the paper's choice, 1/8 for icm and 8/8 for anneal)",
    )
    shape.add_argument(
        "--inherit", default="resynth", metavar="{" + ",".join(INHERIT) + "}",
        help="whether voxels inherited from the coarser level may still change (resynth) or stay "
             "fixed (fixed)",
    )

    method = synth.add_argument_group("sampler")
    method.add_argument(
        "--heuristic", default="ML_H2b", metavar="{" + ",".join(_HEURISTIC_NAMES) + "}",
        help="how the three per-view densities make one voxel value: ML_H1a least probable per-view "
             "argmax, ML_H1b average of per-view argmaxes, ML_H2a argmax of the minimum, ML_H2b "
             "argmax of the product",
    )
    method.add_argument(
        "--relaxation", default="icm", metavar="{icm,anneal}",
        help="relaxation algorithm: icm (iterated conditional modes with per-voxel temperatures; "
             "options --xi --stop --max-sweeps) or anneal (simulated annealing with one global "
             "temperature; options --sampler --schedule --t0 --t-end --proposals --proposal; "
             "needs ML_H2a or ML_H2b)",
    )
    method.add_argument(
        "--xi", type=float, default=-3.0, metavar="X",
        help="icm: cooling step, a negative number (more negative cools faster)",
    )
    method.add_argument(
        "--stop", type=float, default=0.95, metavar="F",
        help="icm: stop a level once the global temperature fell by this fraction, in (0, 1] "
             "(1 = down to 0)",
    )
    method.add_argument(
        "--max-sweeps", type=int, default=30, metavar="N",
        help="icm: hard limit of sweeps per level, a positive integer",
    )
    method.add_argument(
        "--sampler", default="heat-bath", metavar="{heat-bath,metropolis}",
        help="anneal: heat-bath (this project's addition and the default, chosen by measurement: "
             "draw the new value from the tempered objective over all labels) or metropolis (the "
             "paper: one proposal per voxel and sweep, accepted by the Metropolis rule; needs many "
             "more proposals)",
    )
    method.add_argument(
        "--schedule", default="geometric", metavar="{geometric,linear}",
        help="anneal: how the global temperature falls from --t0 to --t-end within each level",
    )
    method.add_argument(
        "--t0", type=float, default=1.0, metavar="T",
        help="anneal: temperature of the first sweep of each level, a positive number",
    )
    method.add_argument(
        "--t-end", type=float, default=0.05, metavar="T",
        help="anneal: temperature of the last sweep of each level, in (0, t0] (0 allowed for the "
             "linear schedule)",
    )
    method.add_argument(
        "--proposals", type=int, default=10, metavar="P",
        help="anneal: proposals (sweeps) per voxel per level, a positive integer",
    )
    method.add_argument(
        "--proposal", default="exemplar", metavar="{exemplar,labels}",
        help="anneal, metropolis: draw candidates from the exemplar's values (the paper) or "
             "uniformly from the label set",
    )
    method.add_argument(
        "--variant", default="default", metavar="{" + ",".join(sorted(VARIANTS)) + "}",
        help="preset of the decision rule: literal = the paper word for word (collapses to a flat "
             "volume), default = the variant chosen by measurement (see docs/quality.md)",
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
        "--decision", default=None, metavar="{argmax,sample}",
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
        "--views", default=",".join(VIEWS), metavar="V[,V...]",
        help=f"comma-separated constrained views, 1 to 3 distinct names of {', '.join(VIEWS)}",
    )
    for view in VIEWS:
        views.add_argument(
            f"--exemplar-{view}", default=None, metavar="PATH",
            help=f"a different exemplar file (or {BUNDLED_PREFIX}NAME) for the {view} view "
                 f"(default: none = EXEMPLAR)",
        )
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
        help="let exemplar patches wrap around the exemplar's borders (for tileable exemplars)",
    )

    run = synth.add_argument_group("run")
    run.add_argument(
        "--seed", type=int, default=0, metavar="S",
        help="random seed, a non-negative integer; the result depends on it only",
    )
    run.add_argument(
        "--out", default="npmrf3d-out", metavar="DIR",
        help="output folder for the run files; created if missing",
    )
    run.add_argument(
        "--overwrite", action="store_true",
        help="replace the files of a previous run in --out instead of refusing",
    )
    run.add_argument(
        "--quiet", action="store_true",
        help="print nothing but errors (no progress bars, no summary)",
    )
    run.add_argument(
        "--checkpoint", default=None, metavar="PATH",
        help="a .npz file written after each level; if it exists and matches this run, synthesis "
             "resumes after its last finished level (default: none = no checkpoint)",
    )

    commands.add_parser(
        "info",
        help="print versions, threads, bundled exemplars, heuristics and variants",
        description="Print the version, package versions, numba threads, CPU count, bundled "
                    "exemplars, heuristics and decision-rule variants.",
        formatter_class=_HelpFormatter,
    )
    for module in _COMMAND_MODULES:
        importlib.import_module(module).register(commands, _HelpFormatter)
    return parser


# --------------------------------------------------------------------------- synth


def _parse_size(text: str) -> int | tuple[int, ...]:
    parts = [p.strip() for p in str(text).split(",")]
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        raise ParameterError(
            f"size must be an integer N or three comma-separated integers N1,N2,N3; got {text!r}"
        ) from None
    return numbers[0] if len(numbers) == 1 else tuple(numbers)


def _check_out(out: pathlib.Path, overwrite: bool, files: tuple[str, ...] = RUN_FILES,
               what: str = "a run") -> None:
    """The output folder must be usable (checked before the work; the writers check again).

    It may exist if it holds none of ``files`` (or ``overwrite`` is set) and is writable, or
    be creatable under its nearest existing ancestor. ``what`` names ``files`` in the message.
    """
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


def _output_folder(args: argparse.Namespace) -> pathlib.Path:
    """The checked ``--out`` folder of a command that writes a run folder."""
    if not args.out.strip():
        raise ParameterError("--out must name a folder; got an empty string")
    out = pathlib.Path(args.out)
    _check_out(out, args.overwrite)
    return out


def _view_sources(args: argparse.Namespace):
    """(EXEMPLAR file, {view: --exemplar-VIEW file}, views -> {view: name for run.json})."""
    exemplar, exemplar_name = exemplar_source(args.exemplar)
    per_view_sources, names = {}, {}
    for view in VIEWS:
        source, name = exemplar_source(getattr(args, f"exemplar_{view}"))
        if source is not None:
            per_view_sources[view], names[view] = source, name
    return exemplar, per_view_sources, lambda views: {v: names.get(v, exemplar_name) for v in views}


def _write_result(out: pathlib.Path, args: argparse.Namespace, argv: list[str], command: str,
                  result, per_view: dict, sources: dict, title: str, **extra) -> None:
    """Write the run folder (volume, TIFF, preview, run.json with ``extra``) and say so."""
    record = run_record(command, result, exemplars=sources, argv=[PROG, *argv], **extra)
    write_run(out, volume=result.volume, exemplars=per_view, record=record,
              overwrite=args.overwrite, title=title)
    if not args.quiet:
        shape = "x".join(str(n) for n in result.volume.shape)
        labels = f"{len(result.labels)} labels, " if len(result.labels) else ""
        print(f"wrote {out}{os.sep}: {', '.join(RUN_FILES)}")
        print(f"volume {shape} (N1xN2xN3xC), {labels}{result.timings['total']:.1f} s")


#: Above this many distinct exemplar values, synth suggests --palette (the label stage scales
#: with the number of labels; a colour photograph easily has thousands).
MANY_VALUES = 1024


def _note_many_values(per_view: dict) -> None:
    import numpy as np

    arrays = {id(a): a for a in per_view.values()}.values()
    values = np.unique(np.concatenate([a.reshape(-1, a.shape[2]) for a in arrays]), axis=0)
    if len(values) > MANY_VALUES:
        print(f"{PROG}: note: the exemplar has {len(values)} distinct values, each a label; run "
              f"time grows with the label count: --palette 64 (colour) or --grey-levels 64 "
              f"is usually as good and much faster", file=sys.stderr)


def _check_checkpoint(path: pathlib.Path | None) -> None:
    if path is None:
        return
    if path.exists() and not path.is_file():
        raise ParameterError(f"checkpoint '{path}' exists and is not a file")
    if not path.absolute().parent.is_dir():
        raise ParameterError(f"folder of checkpoint '{path}' does not exist")


class _Progress:
    """One tqdm bar per level on stderr: steps (``unit``) done, a level quantity as postfix.

    Called as ``progress(level, step, steps, value)`` with ``step = 0`` at the start of each
    level: sweeps and the global temperature ``T`` for synth, iterations and the energy ``E``
    for NP_K.
    """

    def __init__(self, size: tuple[int, int, int], enabled: bool, unit: str = "sweep",
                 symbol: str = "T"):
        self.size = size
        self.enabled = enabled
        self.unit = unit
        self.symbol = symbol
        self.bar = None

    def __call__(self, level: int, sweep: int, max_sweeps: int, temperature: float) -> None:
        if not self.enabled:
            return
        if sweep == 0 or self.bar is None:
            self.close()
            from tqdm import tqdm

            from .pyramid import level_shape

            shape = level_shape(self.size, level)
            side = f"{shape[0]}^3" if len(set(shape)) == 1 else "x".join(map(str, shape))
            self.bar = tqdm(total=max_sweeps, desc=f"level {level} ({side})", unit=self.unit,
                            file=sys.stderr, leave=True, dynamic_ncols=True)
        self.bar.set_postfix({self.symbol: f"{temperature:.4g}"}, refresh=False)
        if sweep > self.bar.n:
            self.bar.update(sweep - self.bar.n)
        else:
            self.bar.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.total = self.bar.n
            self.bar.refresh()
            self.bar.close()
            self.bar = None


def _synth(args: argparse.Namespace, argv: list[str]) -> int:
    from .synthesis import make_config, run

    t_start = time.perf_counter()
    config = make_config(
        size=_parse_size(args.size), window=args.window, levels=args.levels,
        heuristic=args.heuristic, relaxation=args.relaxation, views=args.views,
        upsample=args.upsample, inherit=args.inherit, xi=args.xi, stop=args.stop,
        max_sweeps=args.max_sweeps, sampler=args.sampler, schedule=args.schedule, t0=args.t0,
        t_end=args.t_end, proposals=args.proposals, proposal=args.proposal, variant=args.variant, bandwidth=args.bandwidth,
        centre_bandwidth=args.centre_bandwidth, adaptive=args.adaptive, decision=args.decision,
        tau=args.tau, histogram_weight=args.histogram_weight, outlier=args.outlier,
        grey_levels=args.grey_levels,
        palette=args.palette, toroidal_exemplar=args.toroidal_exemplar, seed=args.seed,
    )
    out = _output_folder(args)
    checkpoint = pathlib.Path(args.checkpoint) if args.checkpoint is not None else None
    _check_checkpoint(checkpoint)

    exemplar, per_view_sources, source_names = _view_sources(args)
    per_view = resolve_exemplars(exemplar, per_view_sources, config.views, window=config.window,
                                 levels=config.levels, toroidal=config.toroidal_exemplar)
    sources = source_names(config.views)
    if not args.quiet and config.palette is None and config.grey_levels is None:
        _note_many_values(per_view)

    import numpy as np

    progress = _Progress(config.size, enabled=not args.quiet)
    try:
        result = run(config, per_view, np.random.default_rng(config.seed), progress=progress,
                     checkpoint=checkpoint, t_start=t_start)
    finally:
        progress.close()

    title = (f"npmrf3d {config.heuristic}, variant {config.variant}, window {config.window}, "
             f"{config.levels} levels, seed {config.seed}")
    _write_result(out, args, argv, "synth", result, per_view, sources, title,
                  labels=int(len(result.labels)))
    return 0


# --------------------------------------------------------------------------- info


def _info() -> int:
    from . import __version__
    from ._kernels import _jit
    from .heuristics import HEURISTICS

    versions = io.package_versions()
    print(f"npmrf3d {__version__}")
    print(f"platform: {versions['platform']}")
    print(f"CPU count: {os.cpu_count()}")
    print(f"numba threads: {_jit.thread_count()}")
    print("packages:")
    for name, value in versions.items():
        if name not in ("platform", "cpu_count"):
            print(f"  {name:<11} {value}")
    print("bundled exemplars:")
    for name in data.available():
        mark = "  (default)" if name == data.DEFAULT_EXEMPLAR else ""
        print(f"  {BUNDLED_PREFIX}{name}{mark}")
    print("heuristics:")
    for h in HEURISTICS.values():
        kind = "objective" if h.objective else "no objective"
        print(f"  {h.name}  {h.description} ({kind})")
    print("variants:")
    for name, rule in VARIANTS.items():
        fields = ", ".join(f"{k}={v}" for k, v in dataclasses.asdict(rule).items())
        print(f"  {name:<8} {fields}")
    return 0


# --------------------------------------------------------------------------- main


#: Parameters whose library name differs from the option; messages name the option instead.
_OPTION_NAMES = ("max_sweeps", "centre_bandwidth", "histogram_weight", "grey_levels", "t_end")


def say(text: str, *, error: bool = False) -> None:
    """Write one line of command-line output (stdout, or stderr for diagnostics).

    The one place where the command line talks to the user; the library itself reports through
    return values, progress callbacks and exceptions.
    """
    print(text, file=sys.stderr if error else sys.stdout)


def _error(message: str) -> int:
    line = " ".join(part.strip() for part in str(message).splitlines() if part.strip())
    for name in _OPTION_NAMES:
        if line.startswith(f"{name} must "):
            line = "--" + name.replace("_", "-") + line[len(name):]
    print(f"{PROG}: error: {line or 'invalid input'}", file=sys.stderr)
    return 2


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (0 ok, 2 user error, 130 interrupted)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version and usage errors (argparse printed them)
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    try:
        if args.command == "info":
            return _info()
        if args.command == "synth":
            return _synth(args, argv)
        return args.handler(args, argv)
    except ParameterError as exc:
        return _error(str(exc))
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. 'npmrf3d info | head': stop quietly, as other tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 1
