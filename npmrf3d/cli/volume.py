"""``npmrf3d volume VOLUME`` (``volume-lh``, optionally deformed) and ``npmrf3d volume-npmrf
VOLUME`` (``npmrf-3d``): synthesise from a 3D exemplar (a scan crop).

Options and defaults come from the methods' config classes
(:class:`npmrf3d.methods.volume_lh.VolumeConfig`, :class:`npmrf3d.methods.npmrf_3d.NpmrfVolumeConfig`); the run folder
is the one ``npmrf3d synth`` writes (its preview shows the exemplar's centre slice).
"""

from __future__ import annotations

import argparse
import dataclasses
import pathlib
import time

import numpy as np

from ..analysis.materials import stationarity_warning
from ..errors import ParameterError
from ..io.runs import RUN_FILES
from ..methods import check_resources
from ..methods.npmrf_3d import METHOD as NPMRF_METHOD
from ..methods.volume_lh import METHOD
from ..model.exemplar import exemplar_source
from ..model.exemplar3d import load_volume_exemplar
from ..model.fields import FIELDS, field_input
from ._blocks import run_to_output, zarr_output
from ._common import (
    add_run_options,
    check_checkpoint,
    output_folder,
    parse_size,
    say,
)
from ._options import given

__all__ = ["FIELD_HELP", "register"]

#: One line per option taken from :class:`VolumeConfig` (size, vector_field and seed have their own).
FIELD_HELP = {
    "levels": "pyramid levels; the coarsest has size / 2**(levels-1) voxels per side",
    "window": "side of the appearance-space neighbourhoods, odd, 3 to 7 (the paper: 5)",
    "pca_dims": "appearance-space dimensions kept by PCA (the paper: 8)",
    "k": "size of the similarity sets (the paper: 3)",
    "exclude": "later similarity-set members lie farther than this many voxels from earlier ones "
               "(the paper's 7x7x7 neighbourhood: 3)",
    "passes": "correction passes per level, each of 8 parity sub-passes",
    "neighbourhood": "synthesis neighbourhood: diagonal (the paper's 8 diagonal neighbours) or "
                     "faces (those and the 6 face neighbours)",
    "jitter": "jitter amplitude at the coarser levels, in units of the level's spacing (the paper: 0.7)",
    "fine_jitter": "jitter amplitude at the finest level",
    "start": "the coarsest level: 'blocks' (the exemplar laid out at the level's spacing, every tile "
             "with its own random offset, and jitter), 'tiled' (one offset for all, as the paper's "
             "pyramid from one voxel: repeats the exemplar at its period) or 'random' (uniform coordinates)",
    "usage": "strength of the position histogram: a candidate copying an over-used part of the "
             "exemplar pays usage x (half the distance of two random neighbourhoods) per excess "
             "use (0: the paper's rule, which collapses onto one homogeneous region of a "
             "non-stationary scan)",
    "balance": "strength of the phase histogram: a candidate whose phase (a segmented scan's "
               "value, or a side of a grey scan's Otsu threshold) the volume already holds more "
               "often than the exemplar pays balance x (half the distance of two random "
               "neighbourhoods) x (its excess share + a price that sums the excess over the "
               "sub-passes); at the coarse levels a coordinate counts as the phase mix of the "
               "voxels its descendants copy (0: the phase fractions drift; a thin minority "
               "phase such as a rock's pores erodes)",
    "angle": "degrees of rotation of the named fields twist and bend",
    "adaptive": "Parzen bandwidth: 2h^2 = adaptive * the smallest neighbourhood distance, > 0",
    "centre_bandwidth": "width of the kernel on candidate centre values, times the exemplar's "
                        "standard deviation, > 0",
}
_OWN = ("size", "vector_field", "seed")


def _option(name: str) -> str:
    return "--" + name.replace("_", "-")


def register(commands, formatter_class) -> None:
    """Add the ``volume`` (``volume-lh``) and ``volume-npmrf`` (``npmrf-3d``) sub-commands."""
    _add(commands, "volume", METHOD, formatter_class,
         help="synthesise a volume from a 3D exemplar (a scan crop), optionally deformed by a "
              "vector field",
         description=(
            "Synthesise a volume from a 3D exemplar: every voxel copies an exemplar voxel\n"
            "(appearance-space coordinate pyramid with k = 3 similarity sets, jitter and\n"
            "correction), optionally turned by a vector field.\n\n"
            "examples:\n"
            "  npmrf3d volume crop.tif --size 128 --out big\n"
            "  npmrf3d volume crop.npy --size 64 --vector-field twist --angle 180\n"
            "  npmrf3d volume crop.npy --vector-field directions.npy   # (N1, N2, N3, 3) or (..., 3, 3)"
         ))
    _add(commands, "volume-npmrf", NPMRF_METHOD, formatter_class,
         help="synthesise a volume from a 3D exemplar with the NP-MRF of one 3D view (npmrf-3d)",
         description=(
             "The NP-MRF with one 3D view: each voxel copies the coherent candidate whose\n"
             "centre value maximises the Parzen LCPDF of full w^3 neighbourhoods.\n\n"
             "example:\n"
             "  npmrf3d volume-npmrf crop.tif --size 128 --out big"
         ))


def _add(commands, name, method, formatter_class, *, help, description) -> None:
    parser = commands.add_parser(name, aliases=[method.name], help=help, description=description,
                                 formatter_class=formatter_class)
    config_class = method.config_class
    parser.add_argument("exemplar", metavar="VOLUME",
                        help="3D exemplar: .npy (D, H, W[, C]) or a TIFF stack (ImageJ/Fiji, multi-page)")
    fields = {f.name: f for f in dataclasses.fields(config_class)}
    parser.add_argument("--size", default=",".join(map(str, fields["size"].default)), metavar="N",
                        help="output size in voxels: N for an N^3 cube or N1,N2,N3; each divisible "
                             "by 2**(levels-1)")
    group = parser.add_argument_group("method")
    for field_name, f in fields.items():
        if field_name in _OWN or field_name in getattr(config_class, "unused", ()):
            continue
        kind = {int: int, float: float}.get(type(f.default))
        if kind is None:
            group.add_argument(_option(field_name), default=f.default, metavar="NAME",
                               help=FIELD_HELP[field_name])
        else:
            group.add_argument(_option(field_name), type=kind, default=f.default,
                               metavar="N" if kind is int else "X", help=FIELD_HELP[field_name])
    if method is METHOD:
        group.add_argument("--vector-field", default=fields["vector_field"].default,
                           metavar="{" + ",".join(FIELDS) + "}|FILE.npy",
                           help="deformation: a named field, or a .npy file of directions (N1, N2, N3, 3) "
                                "or frames (N1, N2, N3, 3, 3) of the output size")
    inputs = parser.add_argument_group("exemplar")
    inputs.add_argument("--exemplar-kind", default="auto", choices=("auto", "volume"), metavar="{auto,volume}",
                        help="auto recognises a volume (and refuses an image); volume reads a 3-D "
                             "array whose last axis is at most 4 as a volume")
    inputs.add_argument("--spacing", default=None, metavar="S[,SY,SX]",
                        help="voxel size of the exemplar, which must be isotropic (default: none = "
                             "what an ImageJ TIFF records, else isotropic)")
    add_run_options(parser, out=f"npmrf3d-{name}-out")
    parser.set_defaults(handler=lambda args, argv: _handler(args, argv, method))
    parser.epilog = f"Writes {', '.join(RUN_FILES)} into the output folder."


def _spacing(text):
    if text is None:
        return None
    try:
        values = [float(p) for p in str(text).split(",")]
    except ValueError:
        raise ParameterError(f"--spacing must be one number or three (z,y,x); got {text!r}") from None
    return values[0] if len(values) == 1 else tuple(values)


#: The named fields that ``--angle`` turns.
ANGLE_FIELDS = ("twist", "bend")


def _check_angle(args: argparse.Namespace) -> None:
    """``--angle`` turns the named fields twist and bend; with any other field it would change
    nothing, so it is refused."""
    if not given(args, "angle"):
        return
    field = str(args.vector_field)
    if field.lower() not in ANGLE_FIELDS:
        what = "a field file" if field.lower().endswith(".npy") else field
        raise ParameterError(f"--angle turns only --vector-field {' or '.join(ANGLE_FIELDS)}; with "
                             f"--vector-field {what} it changes nothing: drop --angle or choose "
                             f"--vector-field {' or '.join(ANGLE_FIELDS)}")


def _handler(args: argparse.Namespace, argv: list[str], method) -> int:
    t_start = time.perf_counter()
    fields = [f.name for f in dataclasses.fields(method.config_class)
              if f.name not in _OWN and f.name not in getattr(method.config_class, "unused", ())]
    options = {name: getattr(args, name) for name in fields}
    size = parse_size(args.size)
    extra = {}
    # messages name library parameters; npmrf3d.cli.main turns them into these options
    config = method.make_config(size=size, seed=args.seed, vector_field="none", **options)
    if config.passes < 1:
        raise ParameterError(f"--passes must be between 1 and 16; got {config.passes}: without a "
                             f"correction pass a level keeps its up-sampled, jittered coordinates "
                             f"unmatched")
    if method is METHOD:
        _check_angle(args)
        field_name, extra["vector_field"] = field_input(args.vector_field, config.size)
        config = dataclasses.replace(config, vector_field=field_name)
    out = output_folder(args)
    checkpoint = pathlib.Path(args.checkpoint) if args.checkpoint is not None else None
    check_checkpoint(checkpoint, out)
    source, _ = exemplar_source(args.exemplar)
    exemplar = load_volume_exemplar(source, exemplar_kind=args.exemplar_kind,
                                    spacing=_spacing(args.spacing))
    per_view = {"volume": exemplar}
    warning = stationarity_warning(exemplar)
    if warning is not None and not args.quiet:
        say(f"npmrf3d {args.command}: warning: {warning}", error=True)
    if not args.dry_run and not zarr_output(args):  # a Zarr volume made at once checks it itself
        check_resources(method, config, per_view,
                        hint="lower --size (or the exemplar size); --dry-run shows the estimate")
    middle = {"exemplar slice": np.ascontiguousarray(exemplar[exemplar.shape[0] // 2])}
    title = f"{method.name}, field {config.vector_field}, {config.levels} levels, seed {config.seed}"
    return run_to_output(args, argv, args.command, method, config, per_view, {"volume": args.exemplar}, title,
                         out=out, checkpoint=checkpoint, preview=middle, t_start=t_start, unit="pass", symbol="E",
                         **extra)
