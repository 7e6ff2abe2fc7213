"""``npmrf3d volume VOLUME`` (``volume-lh``, optionally deformed) and ``npmrf3d volume-npmrf
VOLUME`` (``npmrf-3d``): synthesise from a 3D exemplar (a scan crop).

Options, defaults and help are the fields of the methods' configurations
(:class:`npmrf3d.methods.volume_lh.VolumeConfig`, :class:`npmrf3d.methods.npmrf_3d.NpmrfVolumeConfig`),
made options by :func:`npmrf3d.cli._generic.add_method_parser`; the run folder
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
from ..methods.volume_lh import METHOD, VolumeConfig
from ..options import options_of
from ..model.exemplar import exemplar_source
from ..model.exemplar3d import load_volume_exemplar
from ..model.fields import FIELDS, field_input
from ._blocks import run_to_output, zarr_output
from ._generic import add_method_parser, config_options
from ._common import (
    check_checkpoint,
    output_folder,
    parse_size,
    say,
)
from ._options import given

__all__ = ["register"]

#: Options the handler reads itself.
_OWN = ("size", "vector_field", "seed")


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
            "  npmrf3d volume bundled:fibres48 --size 64 --out grown\n"
            "  npmrf3d volume crop.tif --size 64 --vector-field twist --angle 180\n"
            "  npmrf3d volume crop.npy --vector-field directions.npy   # (N1, N2, N3, 3) or (..., 3, 3)"
         ))
    _add(commands, "volume-npmrf", NPMRF_METHOD, formatter_class,
         help="synthesise a volume from a 3D exemplar with the NP-MRF of one 3D view (npmrf-3d)",
         description=(
             "The NP-MRF with one 3D view: each voxel copies the coherent candidate whose\n"
             "centre value maximises the Parzen LCPDF of full w^3 neighbourhoods.\n\n"
             "example:\n"
             "  npmrf3d volume-npmrf bundled:fibres48 --size 32 --out vol-npmrf"
         ))


def _volume_inputs(parser: argparse.ArgumentParser, sections: dict) -> None:
    """A 3D exemplar's inputs: the volume, how it is read and its voxel size."""
    parser.add_argument("exemplar", metavar="VOLUME",
                        help="3D exemplar: .npy (D, H, W[, C]), a TIFF stack (ImageJ/Fiji, multi-page) or "
                             "bundled:NAME")
    inputs = sections["views and exemplars"]
    inputs.add_argument("--exemplar-kind", default="auto", choices=("auto", "volume"), metavar="{auto,volume}",
                        help="auto recognises a volume (and refuses an image); volume reads a 3-D "
                             "array whose last axis is at most 4 as a volume")
    inputs.add_argument("--spacing", default=None, metavar="S[,SY,SX]",
                        help="voxel size of the exemplar, which must be isotropic (default: what an "
                             "ImageJ TIFF records, else isotropic)")


_volume_inputs.usage = "VOLUME"


def _vector_field(parser: argparse.ArgumentParser, sections: dict) -> None:
    sections["method"].add_argument(
        "--vector-field", default=options_of(VolumeConfig)["vector_field"][0].default,
        metavar="{" + ",".join(FIELDS) + "}|FILE.npy",
        help="deformation: a named field, or a .npy file of directions (N1, N2, N3, 3) or frames "
             "(N1, N2, N3, 3, 3) of the output size")


def _add(commands, name, method, formatter_class, *, help, description) -> None:
    add_method_parser(commands, name, method, aliases=(method.name,), help=help, description=description,
                      out=f"npmrf3d-{name}-out", formatter_class=formatter_class, inputs=_volume_inputs,
                      extra=_vector_field if method is METHOD else None,
                      handler=lambda args, argv: _handler(args, argv, method))


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
    options = config_options(args, method.config_class)
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
    out = output_folder(args, () if zarr_output(args) else RUN_FILES)  # a Zarr volume checks its own identity
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
