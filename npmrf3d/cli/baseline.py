"""Command line of the baselines: ``npmrf3d baseline kopf [EXEMPLAR] ...`` (NP_K).

Registered by :data:`npmrf3d.cli.main.COMMANDS`. Every option is a field of
:class:`npmrf3d.methods.kopf.KopfConfig` (or of ``chen-wang``'s configuration), made an option by
:func:`npmrf3d.cli._generic.add_method_parser`; the sub-command runs the ``kopf`` entry of
:data:`npmrf3d.methods.METHODS`. Same
conventions as ``npmrf3d synth``: every option shows its default in ``--help``; a tqdm bar per
level on stderr (``--quiet`` turns it off); the run folder holds ``volume.npy``, ``volume.tif``,
``preview.png`` and ``run.json``; user mistakes are one line on stderr with exit code 2, raised
before any synthesis work and without leaving files behind.
"""

from __future__ import annotations

import argparse
import time

from .. import io
from ..errors import ParameterError
from ..io.runs import RUN_FILES
from ..methods import chen_wang
from ..model.kopf_constraints import constraint_arrays
from ..methods.kopf import DEFAULT_ITERATIONS, METHOD, KopfConfig
from ..options import options_of
from ._blocks import run_to_output, zarr_output
from ._common import parse_size, prepare_run
from ._generic import add_method_parser, config_options, refuse_written
from ._options import given

__all__ = ["register"]

#: Library parameter names whose messages should name the command-line option instead.
_OPTION_NAMES = ("histogram_bins", "histogram_weight", "mean_shift", "constraint_weight",
                 "iterations", "variance", "grid", "eps", "window", "levels")

def register(commands, formatter_class) -> None:
    """Add ``kopf`` and ``chen-wang``, each by its method's name and under ``baseline``."""
    baseline = commands.add_parser(
        "baseline",
        help="synthesise with a baseline method the NP-MRF sampler is compared with (kopf, chen-wang)",
        description="Baseline methods, with the same outputs as 'npmrf3d synth'.",
        formatter_class=formatter_class,
    )
    methods = baseline.add_subparsers(dest="baseline", metavar="METHOD", required=True)
    for add in (_add_kopf, _add_chen_wang):
        add(methods, formatter_class)  # npmrf3d baseline kopf | chen-wang
        add(commands, formatter_class)  # npmrf3d kopf | chen-wang, as every method by its name


def _kopf_options(parser: argparse.ArgumentParser, sections: dict) -> None:
    """``kopf``'s options beyond its configuration's fields: iterations and mean-shift bandwidths
    as written on the command line, and the voxel constraints (inputs, not configuration)."""
    sections["volume and pyramid"].add_argument(
        "--iterations", default=str(DEFAULT_ITERATIONS), metavar="N[,N..]",
        help="search + optimisation iterations per level: one number, or one per level (coarsest first)")
    mean_shift = options_of(KopfConfig)["mean_shift"]
    sections["energy and search"].add_argument(
        "--mean-shift", default=",".join(str(h) for h in mean_shift[0].default), metavar="H0,H1",
        help=mean_shift[1].help)
    views = sections["views and exemplars"]
    views.add_argument("--constraint", default=None, metavar="PATH",
                       help="voxel constraints: a .npy or .tif volume (N1, N2, N3[, C]) of target values "
                            "(default: none)")
    views.add_argument("--constraint-weight", default=None, metavar="W|PATH",
                       help="constraint weights: a number >= 0 or a .npy/.tif volume (N1, N2, N3) "
                            "(default: 1 everywhere when --constraint is given)")


def _add_kopf(commands, formatter_class, name: str = "kopf") -> None:
    add_method_parser(
        commands, name, METHOD,
        help="NP_K: texture optimisation with histogram matching (Kopf et al. 2007)",
        description=(
            "NP_K (Kopf et al. 2007): minimise the robust distance between the volume's\n"
            "axis-orthogonal 2D neighbourhoods and their nearest exemplar neighbourhoods\n"
            "(PCA + approximate kd-tree search on a sparse grid, IRLS averaging, histogram\n"
            f"matching), coarse to fine. Writes {', '.join(RUN_FILES)} into the output folder.\n\n"
            "examples:\n"
            "  npmrf3d kopf                                         # bundled exemplar, 64^3\n"
            "  npmrf3d kopf bundled:ihc --size 128 --out ihc-kopf\n"
            "  npmrf3d kopf wood.png --views front,right    # two constrained views"
        ),
        out="npmrf3d-kopf-out", formatter_class=formatter_class, handler=_kopf, extra=_kopf_options,
    )


def _add_chen_wang(commands, formatter_class, name: str = "chen-wang") -> None:
    add_method_parser(
        commands, name, chen_wang.METHOD,
        help="Chen & Wang 2010: k-coherence search, discrete solver, position and index histograms",
        description=(
            "Chen & Wang (2010): every voxel keeps, per view, the exemplar pixel it was copied\n"
            "from; each view's neighbourhoods search their best match among the neighbours'\n"
            "coherent shifts and k-coherence sets (index-histogram penalty), and every voxel\n"
            "copies one texel voted by the neighbourhoods that contain it (IRLS weights with\n"
            "position-histogram re-weighting). Colours are exemplar colours. docs/chen_wang.md\n\n"
            "examples:\n"
            "  npmrf3d chen-wang bundled:gravel --size 64\n"
            "  npmrf3d chen-wang bundled:ihc --size 128 --window 8,6,4 --out ihc-cw"
        ),
        out="npmrf3d-chen-wang-out", formatter_class=formatter_class,
        refuse=refuse_chen_wang,
    )


def refuse_chen_wang(args: argparse.Namespace, config, per_view: dict) -> None:
    """What ``chen-wang`` refuses once the exemplars are read: a written ``--pca-dims`` above the
    dimensions of the smallest neighbourhoods (window x window
    x channels at the level with the smallest window), which the PCA could not keep: the value
    would be cut down at that level without a word. The default is kept as the most dimensions
    each level may use."""
    if not given(args, "pca_dims"):
        return
    w = min(config.window)
    channels = min(a.shape[2] for a in per_view.values())
    limit = w * w * channels
    if config.pca_dims > limit:
        raise ParameterError(
            f"--pca-dims {config.pca_dims} is more than the neighbourhoods have: the {w}x{w} window "
            f"of a {channels}-channel exemplar has {limit} dimensions; choose at most {limit} (or "
            f"larger --window values)")

def _parse_iterations(text: str):
    parts = [p.strip() for p in str(text).split(",")]
    try:
        numbers = [int(p) for p in parts]
    except ValueError:
        raise ParameterError(f"--iterations must be an integer or comma-separated integers; got {text!r}") from None
    return numbers[0] if len(numbers) == 1 else tuple(numbers)

def _parse_mean_shift(text: str):
    if str(text).strip().lower() in ("none", "off"):
        return None
    parts = [p.strip() for p in str(text).split(",")]
    try:
        numbers = [float(p) for p in parts]
    except ValueError:
        raise ParameterError(f"--mean-shift must be 'none', a number or two comma-separated numbers; "
                             f"got {text!r}") from None
    if len(numbers) > 2:
        raise ParameterError(f"--mean-shift must be 'none', a number or two comma-separated numbers; "
                             f"got {text!r}")
    return numbers[0] if len(numbers) == 1 else tuple(numbers)

def _constraint_weight(text: str | None):
    if text is None:
        return None
    try:
        return float(text)
    except ValueError:
        pass
    weights = io.read_volume(text)
    if weights.shape[3] != 1:
        raise ParameterError(f"--constraint-weight volume '{text}' must have one channel; "
                             f"got shape {weights.shape}")
    return weights[..., 0]

def _option_message(message: str) -> str:
    for name in _OPTION_NAMES:
        if message.startswith(f"{name} must "):
            return "--" + name.replace("_", "-") + message[len(name):]
    return message

def _kopf(args: argparse.Namespace, argv: list[str]) -> int:
    try:
        return _run(args, argv)
    except ParameterError as exc:
        raise ParameterError(_option_message(str(exc))) from None

def _run(args: argparse.Namespace, argv: list[str]) -> int:
    t_start = time.perf_counter()
    if args.constraint_weight is not None and args.constraint is None:
        raise ParameterError("--constraint-weight needs --constraint (the volume of target values "
                             "it weighs): add --constraint or drop --constraint-weight")
    constraint = io.read_volume(args.constraint) if args.constraint is not None else None
    weight = _constraint_weight(args.constraint_weight)
    config = METHOD.make_config(
        size=parse_size(args.size), views=args.views, seed=args.seed, constrained=constraint is not None,
        **{**config_options(args, KopfConfig), "iterations": _parse_iterations(args.iterations),
           "mean_shift": _parse_mean_shift(args.mean_shift)})
    refuse_written(args, config)
    config, out, checkpoint, per_view, sources = prepare_run(args, METHOD, config, whole=not zarr_output(args))
    if constraint is not None:  # its checks, before the work (the method repeats them)
        channels = next(iter(per_view.values())).shape[2]
        constraint_arrays(constraint, weight, config.size, channels)
    title = f"NP_K (Kopf et al. 2007), window {config.window}, {config.levels} levels, seed {config.seed}"
    return run_to_output(args, argv, "baseline kopf", METHOD, config, per_view, sources, title, out=out,
                         checkpoint=checkpoint, record={"constraint": args.constraint,
                                                        "constraint_weight": args.constraint_weight},
                         t_start=t_start, unit="iter", symbol="E", constraint=constraint, constraint_weight=weight)
