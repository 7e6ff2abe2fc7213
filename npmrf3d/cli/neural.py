"""``npmrf3d neural train`` and ``npmrf3d neural generate``: the on-demand generator.

Options and defaults come from :class:`npmrf3d.methods.neural.NeuralConfig` (its field defaults). The
commands need the ``[neural]`` extra; without it they stop with one line naming the install
command (exit 2). This module imports no torch: ``npmrf3d --help`` and the other commands work
without the extra.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import time

import numpy as np

from .. import _validation as check
from .. import data
from ..errors import ParameterError
from ..io.files import atomic_write, broken_link, write_volume_tiff
from ..io.zarr_blocks import volume_attrs
from ..methods import neural
from ..methods.neural import _extra
from ..methods.neural.config import (
    DESCRIPTORS,
    ORIGIN_LIMIT,
    ZARR_BLOCK,
    ZARR_WORKERS,
    NeuralConfig,
)
from ..model.exemplar import BUNDLED_PREFIX
from ..model.neighbourhood import VIEWS
from ._common import (
    check_checkpoint,
    choices,
    default,
    parse_size,
    positive_int,
    say,
    view_sources,
)
from ._blocks import kept_on_interrupt
from ._options import given
from ._progress import CountProgress

__all__ = ["register"]

#: Library parameter names -> the option that sets them (for one-line messages).
OPTION_NAMES = {"slice_size": "--size", "vgg19_weights": "--vgg19"}
#: Volume files ``neural generate`` writes in memory (a Zarr folder is written block by block).
VOLUME_SUFFIXES = (".npy", ".tif", ".tiff", ".zarr")


def _d(name: str):
    return default(NeuralConfig, name)


def _rename(exc: ParameterError) -> ParameterError:
    message = str(exc)
    for name, option in OPTION_NAMES.items():
        if message.startswith(f"{name} "):
            return ParameterError(option + message[len(name):])
    first = message.split(" ", 1)[0]
    if first in NeuralConfig.__dataclass_fields__:
        return ParameterError("--" + first.replace("_", "-") + message[len(first):])
    return exc


def _threads(value: int | None) -> None:
    if value is not None:
        _extra.require("torch", "the neural commands").set_num_threads(value)


def _check_new_file(text: str, overwrite: bool, what: str) -> pathlib.Path:
    """The ``--out`` file ``text`` names, checked: a file that may be written (a Zarr volume: a
    folder)."""
    if not text.strip():
        raise ParameterError("--out must name a file; got an empty string")
    path = pathlib.Path(text)
    nowhere = broken_link(path)
    if nowhere is not None and path.suffix.lower() == ".zarr":  # a folder is made beside it, then moved there
        raise ParameterError(f"{what} '{path}' {nowhere}; remove the link or choose another --out")
    if path.exists() and path.is_dir() and path.suffix.lower() != ".zarr":
        raise ParameterError(f"{what} '{path}' is a folder; give a file name")
    if path.exists() and not overwrite:
        raise ParameterError(f"{what} '{path}' already exists; pass --overwrite or choose another --out")
    if not path.absolute().parent.is_dir():
        raise ParameterError(f"folder of {what} '{path}' does not exist")
    if not os.access(path.absolute().parent, os.W_OK | os.X_OK):
        raise ParameterError(f"folder of {what} '{path}' is not writable; choose another --out")
    return path


def _train(args: argparse.Namespace, argv) -> int:
    _extra.require("torch", "'npmrf3d neural train'")
    options = {name: getattr(args, name) for name in (
        "iterations", "batch", "learning_rate", "scales", "noise_channels", "channel_step", "tile",
        "descriptor", "filters", "descriptor_scales", "filter_size", "histogram_weight", "checkpoint_every",
        "seed")}
    options["calibrate"] = not args.no_calibrate
    try:
        config = neural.make_neural_config(views=args.views, slice_size=args.size,
                                           vgg19_weights=args.vgg19, **options)
    except ParameterError as exc:
        raise _rename(exc) from None
    out = _check_new_file(args.out, args.overwrite, "model file")
    if args.checkpoint is None and given(args, "checkpoint_every"):
        raise ParameterError("--checkpoint-every changes nothing without --checkpoint PATH; add it "
                             "or drop --checkpoint-every")
    checkpoint = None if args.checkpoint is None else pathlib.Path(args.checkpoint)
    check_checkpoint(checkpoint, out, out_file=True)
    exemplar, per_view_sources, _names = view_sources(args)
    _threads(args.threads)
    bar = CountProgress("train", unit="step", symbol="loss", enabled=not args.quiet)
    try:
        model = neural.train(exemplar, exemplars=per_view_sources, rng=config.seed,
                             progress=bar, checkpoint=checkpoint,
                             **{k: v for k, v in config.to_dict().items() if k != "size"})
    finally:
        bar.close()
    neural.save_model(model, out)
    if not args.quiet:
        t = model.timings["train"]
        say(f"wrote {out}: {model.parameters} parameters, {config.iterations} steps, "
            f"loss {model.history[-1]:.4g}, {t:.1f} s ({t / max(1, len(model.history)):.2f} s per step)")
    return 0


def _generate(args: argparse.Namespace, argv) -> int:
    _extra.require("torch", "'npmrf3d neural generate'")
    out = pathlib.Path(args.out)
    if out.suffix.lower() not in VOLUME_SUFFIXES:
        raise ParameterError(f"--out must end in one of {', '.join(VOLUME_SUFFIXES)}; got '{out}'")
    size = parse_size(args.size)
    try:
        origin = parse_size(args.origin)
    except ParameterError:
        raise ParameterError(f"--origin must be an integer or three comma-separated integers "
                             f"X,Y,Z; got {args.origin!r}") from None
    from_cli = {"size": size, "origin": origin}
    try:
        size = check.triple("size", from_cli["size"], low=1)
        origin = tuple(check.integer("origin", o, low=-ORIGIN_LIMIT, high=ORIGIN_LIMIT)
                       for o in check.triple("origin", from_cli["origin"]))
        check.integer("block", args.block, low=1)
        check.integer("workers", args.workers, low=1)
    except ParameterError as exc:
        raise ParameterError("--" + str(exc)) from None
    zarr_out = out.suffix.lower() == ".zarr"
    unread = [name for name in ("block", "workers", "scheduler") if given(args, name)]
    if unread and not zarr_out:
        raise ParameterError(f"--{unread[0]} applies to a Zarr volume, made block by block; it "
                             f"changes nothing with --out {out.suffix}: drop it or write .zarr")
    _check_new_file(args.out, args.overwrite or zarr_out, "output")
    if zarr_out and any(origin):
        raise ParameterError(f"--origin must be 0,0,0 for a Zarr volume (it holds [0, size)); got {args.origin}")
    if zarr_out and args.seed is not None:
        raise ParameterError("--seed does not apply to a Zarr volume, whose blocks use the model's own "
                             "seed: drop --seed, or write .npy or .tif")
    model = neural.load_model(args.model)
    _threads(args.threads)
    t0 = time.perf_counter()
    if zarr_out:
        attrs = volume_attrs(neural.model_identity(args.model), size, args.block)
        bar = CountProgress("blocks", unit="block", enabled=not args.quiet)
        try:
            with kept_on_interrupt(args, out, attrs):
                summary = neural.write_zarr(args.model, out, size=size, block=args.block,
                                            scheduler=args.scheduler, workers=args.workers,
                                            overwrite=args.overwrite, progress=lambda d, n: bar(d, n, None))
        finally:
            bar.close()
        if not args.quiet:
            say(f"wrote {out}: {'x'.join(map(str, size))}x{model.channels} float32 Zarr, "
                f"{summary['written']} blocks written, {summary['skipped']} already done, "
                f"{time.perf_counter() - t0:.1f} s")
        return 0
    volume = neural.generate(model, origin, size, seed=args.seed)
    if out.suffix == ".npy":
        atomic_write(out, lambda tmp: np.save(tmp, volume))
    else:
        write_volume_tiff(out, volume)
    if not args.quiet:
        t = time.perf_counter() - t0
        say(f"wrote {out}: {'x'.join(map(str, volume.shape))} (N1xN2xN3xC) at origin "
            f"{','.join(map(str, origin))}, {t:.1f} s ({volume.shape[0] * volume.shape[1] * volume.shape[2] / t:.3g} voxels/s)")
    return 0


def register(commands, formatter_class) -> None:
    """Add ``neural`` with its sub-commands ``train`` and ``generate``."""
    top = commands.add_parser(
        "neural", help="on-demand volumes from a compact 3D CNN generator (needs npmrf3d[neural])",
        description="Train the on-demand generator (Gutierrez et al. 2020) on slices, then make any block of\n"
                    "its unbounded volume, in memory or block by block into Zarr on Dask.",
        formatter_class=formatter_class)
    sub = top.add_subparsers(dest="neural", metavar="COMMAND", required=True)

    train = sub.add_parser(
        "train", help="train a generator on an exemplar (one per view)", formatter_class=formatter_class,
        description="Train the generator on single slices against each view's exemplar; writes a\n"
                    "model file.\n\nexamples:\n  npmrf3d neural train bundled:gravel --out gravel.pt\n"
                    "  npmrf3d neural train wood.png --iterations 600 --checkpoint wood.ckpt --out wood.pt")
    train.add_argument("exemplar", nargs="?", default=f"{BUNDLED_PREFIX}{data.DEFAULT_EXEMPLAR}",
                       metavar="EXEMPLAR", help="2D exemplar image or array for every view")
    train.add_argument("--out", required=True, metavar="MODEL.pt", help="model file to write")
    train.add_argument("--size", type=int, default=_d("slice_size"), metavar="N",
                       help="side of the training slices (default: none = the exemplar's side, at most 128)")
    train.add_argument("--iterations", type=int, default=_d("iterations"), metavar="N",
                       help="optimiser steps; at the default about 12-14 min for a 64x64 exemplar and 45 for a "
                            "128x128 one on 2 CPU cores (600 steps: under 30 min)")
    train.add_argument("--batch", type=int, default=_d("batch"), metavar="N", help="slices per view and step")
    train.add_argument("--learning-rate", type=float, default=_d("learning_rate"), metavar="X", help="Adam step size")
    arch = train.add_argument_group("generator")
    arch.add_argument("--scales", type=int, default=_d("scales"), metavar="N", help="noise scales K + 1")
    arch.add_argument("--noise-channels", type=int, default=_d("noise_channels"), metavar="N", help="noise channels per scale")
    arch.add_argument("--channel-step", type=int, default=_d("channel_step"), metavar="N", help="channels per scale step")
    arch.add_argument("--tile", type=int, default=_d("tile"), metavar="N",
                      help="side of the canonical generation tiles, a multiple of 2**(scales-1)")
    desc = train.add_argument_group("descriptor")
    desc.add_argument("--descriptor", default=_d("descriptor"), metavar=choices(DESCRIPTORS),
                      help="random: Gram matrices of a fixed random filter bank; vgg19: needs --vgg19")
    desc.add_argument("--vgg19", default=None, metavar="FILE",
                      help="a local VGG-19 state_dict (torchvision layout) for --descriptor vgg19 (default: none)")
    desc.add_argument("--filters", type=int, default=_d("filters"), metavar="N", help="random filters per scale")
    desc.add_argument("--descriptor-scales", type=int, default=_d("descriptor_scales"), metavar="N", help="pyramid scales")
    desc.add_argument("--filter-size", type=int, default=_d("filter_size"), metavar="N", help="random filter side")
    desc.add_argument("--histogram-weight", type=float, default=_d("histogram_weight"), metavar="X",
                      help="weight of the value-histogram (sorted-value) loss term beside the Gram terms; 0: none")
    desc.add_argument("--no-calibrate", action="store_true",
                      help="keep the generator's raw values (default: after training, map each channel "
                           "through a monotone quantile map fitted so that the value histogram matches "
                           "the exemplar's; pointwise, so blocks still tile exactly)")
    views = train.add_argument_group("views and exemplars")
    views.add_argument("--views", default=",".join(_d("views")), metavar="V[,V...]",
                       help=f"constrained views, 1 to 3 of {', '.join(VIEWS)}")
    for view in VIEWS:
        views.add_argument(f"--exemplar-{view}", default=None, metavar="PATH",
                           help=f"a different exemplar for the {view} view (default: none = EXEMPLAR)")
    run = train.add_argument_group("run")
    run.add_argument("--seed", type=int, default=0, metavar="S", help="seed of weights, slices and noise")
    run.add_argument("--checkpoint", default=None, metavar="PATH",
                     help="file written every --checkpoint-every steps; resumed from if it matches (default: none)")
    run.add_argument("--checkpoint-every", type=int, default=_d("checkpoint_every"), metavar="N", help="steps between checkpoints")
    run.add_argument("--threads", type=positive_int, default=None, metavar="N", help="torch threads (default: none = torch's choice)")
    run.add_argument("--overwrite", action="store_true", help="replace an existing model file")
    run.add_argument("--quiet", action="store_true", help="print nothing but errors")
    train.set_defaults(handler=_train)

    gen = sub.add_parser(
        "generate", help="make a block of a trained model's volume (.npy, .tif or .zarr)",
        formatter_class=formatter_class,
        description="Make the block [origin, origin + size) of the model's unbounded volume. A .zarr\n"
                    "output is written block by block on a Dask cluster (local by default), resumable\n"
                    "(a rerun skips finished blocks), and opens in napari.\n\nexamples:\n"
                    "  npmrf3d neural generate gravel.pt --size 256 --out gravel.npy\n"
                    "  npmrf3d neural generate gravel.pt --size 1024 --out gravel.zarr\n"
                    "  npmrf3d neural generate gravel.pt --size 1024 --out /shared/g.zarr --scheduler tcp://HOST:8786")
    gen.add_argument("model", metavar="MODEL", help="a model file of 'npmrf3d neural train'")
    gen.add_argument("--size", default=",".join(map(str, _d("size"))), metavar="N",
                     help="N for an N^3 block or N1,N2,N3")
    gen.add_argument("--origin", default="0,0,0", metavar="X,Y,Z", help="integer coordinate of the first voxel (negative: --origin=-64,0,0)")
    gen.add_argument("--out", required=True, metavar="FILE", help=f"output, one of {', '.join(VOLUME_SUFFIXES)}")
    gen.add_argument("--seed", type=int, default=None, metavar="S",
                     help="noise seed: another volume of the same texture (default: none = the model's)")
    gen.add_argument("--block", type=int, default=ZARR_BLOCK, metavar="N", help="Zarr: block and chunk side")
    gen.add_argument("--scheduler", default=None, metavar="ADDRESS",
                     help="Zarr: a running Dask scheduler's address, or local (default: none = a local cluster of --workers)")
    gen.add_argument("--workers", type=int, default=ZARR_WORKERS, metavar="N", help="Zarr: local worker processes")
    gen.add_argument("--threads", type=positive_int, default=None, metavar="N", help="torch threads (default: none = torch's choice)")
    gen.add_argument("--overwrite", action="store_true",
                     help="replace an existing output (a Zarr volume: made afresh beside it, and put in its place "
                          "once complete)")
    gen.add_argument("--quiet", action="store_true", help="print nothing but errors")
    gen.set_defaults(handler=_generate)
