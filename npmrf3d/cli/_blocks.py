"""Volumes in blocks from the command line: ``--out VOL.zarr``, ``--block``, ``--workers``,
``--scheduler`` and ``--blockwise`` of ``synth`` and the coherent samplers' commands.

An ``--out`` ending in ``.zarr`` writes the volume into a chunked Zarr array: made at once
when it fits in memory, or with ``--blockwise`` block by block
(:func:`npmrf3d.methods.blocks.write_zarr`) with the block-local sampler, on a local Dask
cluster or a running scheduler, where a rerun of the same command makes only the missing
blocks. The array's attributes hold the run record; ``preview.png`` inside the folder shows
the exemplar, the three centre slices and the cube's faces of a corner.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import sys

import numpy as np
import zarr
from tqdm import tqdm

from .._cluster import check_scheduler, probe_scheduler
from ..config import SynthesisConfig
from ..errors import ParameterError
from ..io.runs import run_record
from ..io.zarr_blocks import block_box, block_indices, open_blocks, write_block
from ..methods import check_resources
from ..methods.blocks import block_plan, run_identity, write_zarr
from ..plotting import preview_figure, save_figure
from ..resources import format_bytes
from ._common import PROG, dry_run, positive_int, say
from ._options import given
from ._progress import run_method

__all__ = ["DEFAULT_BLOCK", "add_block_options", "blockwise_requested", "run_zarr", "zarr_output"]

#: Side of the blocks (and Zarr chunks) when none is asked for: large against the default's
#: aprons (18 voxels a side at the finest level), so the cones repeat little work (512^3: 1.7x
#: the pyramid's voxels in cones against 2.0x with blocks of 128), and 1.45 GiB at most per
#: worker (measured at 512^3 with 2 threads).
DEFAULT_BLOCK = 192
#: Local workers when none is asked for: one, the command itself with every core as numba
#: threads (512^3 on 2 cores: 13.6 min); a block made in a Dask worker process takes 2-4 s more
#: (a 192^3 block of 512^3: 40.5-43 s against 38.2-39.6 s in the command's process).
DEFAULT_WORKERS = 1


def add_block_options(group: argparse._ArgumentGroup) -> None:
    """``--blockwise``, ``--whole-voxels``, ``--block``, ``--workers`` and ``--scheduler`` into ``group``."""
    group.add_argument(
        "--blockwise", action="store_true", default=False,
        help="the block-local sampler (the levels of at most --whole-voxels voxels made whole, once; "
             "the finer levels reading the histograms of a pilot block, random numbers hashed from voxel "
             "positions), which makes a volume of any size in blocks with --out VOL.zarr, bit for bit the "
             "volume it makes at once (docs/blocks.md)")
    group.add_argument(
        "--whole-voxels", type=positive_int, default=SynthesisConfig.whole_voxels, metavar="N",
        help="--blockwise: levels of at most N voxels (and the coarsest) run whole, once for all blocks, "
             "with the default's histograms; more repeats less work in the cones and makes the first "
             "block hold a larger level (default: %(default)s = 256^3)")
    group.add_argument(
        "--block", type=positive_int, default=DEFAULT_BLOCK, metavar="N",
        help="--out VOL.zarr --blockwise: side of the blocks and of the Zarr chunks; each worker "
             "holds one block's dependency cone (--dry-run shows its memory)")
    group.add_argument(
        "--workers", type=positive_int, default=DEFAULT_WORKERS, metavar="N",
        help="--out VOL.zarr --blockwise: processes of a local Dask cluster, the machine's cores "
             "shared among them as numba threads (at least one each); 1: no cluster, the command makes "
             "every block itself with every core (default: %(default)s)")
    group.add_argument(
        "--scheduler", default=None, metavar="ADDRESS",
        help="--out VOL.zarr --blockwise: a running Dask scheduler (tcp://HOST:8786) whose workers "
             "make the blocks; they must see the --out folder (the exemplar's values are sent with "
             "the tasks) (default: none = a local cluster of --workers)")


def zarr_output(args: argparse.Namespace) -> bool:
    """Whether ``--out`` names a Zarr volume (ends in ``.zarr``)."""
    return str(args.out).rstrip("/\\").lower().endswith(".zarr")


def blockwise_requested(args: argparse.Namespace) -> bool:
    """Whether ``--blockwise`` was given; the options of block runs without it (or without a
    Zarr ``--out``) are refused."""
    blocks = bool(args.blockwise) and zarr_output(args)
    for name in ("scheduler", "workers", "block"):
        if not blocks and (given(args, name) or (name == "scheduler" and args.scheduler is not None)):
            need = "--blockwise" if zarr_output(args) else "--out VOL.zarr --blockwise"
            raise ParameterError(f"--{name} applies to volumes made in blocks: add {need}")
    if given(args, "whole_voxels") and not args.blockwise:
        raise ParameterError("--whole-voxels applies to the block-local sampler: add --blockwise")
    return bool(args.blockwise)


def run_zarr(args: argparse.Namespace, argv: list[str], command: str, method, config, per_view: dict,
             sources: dict, title: str) -> int:
    """Make ``config``'s volume into the Zarr array ``--out``: at once when it is not
    ``blockwise`` (the memory checked first), else in blocks; ``--dry-run`` prints the estimate
    or the block plan."""
    if not getattr(config, "blockwise", False):
        return _zarr_at_once(args, argv, command, method, config, per_view, sources, title)
    if getattr(args, "checkpoint", None) is not None:
        raise ParameterError("--checkpoint does not apply to --out VOL.zarr --blockwise: the Zarr volume "
                             "keeps its finished blocks, and the same command resumes it")
    scheduler = check_scheduler(args.scheduler)
    if scheduler in ("local", "serial"):
        scheduler = None
    if scheduler is not None:
        probe_scheduler(scheduler)
    out = pathlib.Path(args.out)
    plan = block_plan(method, per_view, config, block=args.block)
    if args.dry_run:
        say(f"{method.name} {'x'.join(map(str, config.size))} into {out}: {plan.describe()}")
        return 0
    record = _record(command, argv, method, config, sources, block=args.block,
                     workers=None if scheduler else args.workers, scheduler=scheduler)
    bar = None
    if not args.quiet:
        say(f"{method.name}: {plan.describe()}")

    def progress(done, total):
        nonlocal bar
        if args.quiet:
            return
        if bar is None:
            bar = tqdm(total=total, initial=done, desc="blocks", unit="block", file=sys.stderr,
                       dynamic_ncols=True)
        else:
            bar.update(done - bar.n)

    try:
        threads = 1 if scheduler else max(1, (os.cpu_count() or 1) // args.workers)
        summary = write_zarr(method, per_view, config, out, block=args.block, record=record,
                             workers=args.workers, threads=threads, scheduler=scheduler,
                             overwrite=args.overwrite, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    array = zarr.open_array(out, mode="r+")
    array.attrs["npmrf3d_block_seconds"] = float(array.attrs.get("npmrf3d_block_seconds", 0.0)) + summary["seconds"]
    peak = max(int(array.attrs.get("npmrf3d_worker_peak_bytes", 0)), int(summary["worker_peak_bytes"]))
    array.attrs["npmrf3d_worker_peak_bytes"] = peak
    _preview(out, array, per_view, title, args.block)
    if not args.quiet:
        workers = f"; a worker's peak memory {format_bytes(peak)}" if peak else ""
        say(f"wrote {out}: {summary['written']} blocks written, {summary['skipped']} already done{workers}; "
            f"volume {'x'.join(map(str, array.shape))} (N1xN2xN3xC) float32, Zarr format 2 "
            f"(napari {out}), preview.png inside")
    return 0


def _record(command: str, argv, method, config, sources: dict, **extra) -> dict:
    """The run record a Zarr volume keeps in its attributes (as ``run.json`` holds it)."""
    record = run_record(command, None, exemplars=sources, method=method.name, argv=[PROG, *argv], **extra)
    record["config"], record["seed"] = json.loads(json.dumps(config.to_dict(), default=str)), config.seed
    return record


def _zarr_at_once(args, argv, command, method, config, per_view, sources, title) -> int:
    """The volume made at once (as a run folder would hold it) and written into the Zarr array
    ``--out`` in chunks of ``DEFAULT_BLOCK``, with the run record in its attributes."""
    check_resources(method, config, per_view, hint="lower --size, or make it in blocks with --blockwise "
                                                    "(the block-local sampler: docs/blocks.md)")
    if args.dry_run:
        return dry_run(method, config, per_view)
    out = pathlib.Path(args.out)
    block = min(DEFAULT_BLOCK, max(config.size))
    open_blocks(out, size=config.size, channels=next(iter(per_view.values())).shape[-1], block=block,
                attrs={"npmrf3d_run": run_identity(method, config, per_view)},
                record=_record(command, argv, method, config, sources), overwrite=args.overwrite)
    checkpoint = pathlib.Path(args.checkpoint) if getattr(args, "checkpoint", None) else None
    result = run_method(args, method, config, per_view, checkpoint=checkpoint)
    for index in block_indices(config.size, block):
        origin, shape = block_box(index, block, config.size)
        write_block(out, index, block, result.volume[tuple(slice(o, o + n) for o, n in zip(origin, shape))])
    array = zarr.open_array(out, mode="r+")
    array.attrs["npmrf3d_seconds"] = float(result.timings["total"])
    _preview(out, array, per_view, title, block)
    if not args.quiet:
        say(f"wrote {out}: volume {'x'.join(map(str, array.shape))} (N1xN2xN3xC) float32, Zarr format 2 "
            f"(napari {out}), preview.png inside; {result.timings['total']:.1f} s")
    return 0


def _preview(out: pathlib.Path, array, per_view: dict, title: str, block: int) -> None:
    """``preview.png`` in the Zarr folder: the exemplar(s) and the centre slices and faces of the
    volume's first corner, at most two blocks a side (a volume of any size is not read whole)."""
    side = [min(n, 2 * block) for n in array.shape[:3]]
    corner = np.asarray(array[: side[0], : side[1], : side[2]])
    fig = preview_figure(corner, per_view, title=f"{title} (the first {'x'.join(map(str, side))} corner)")
    save_figure(fig, out / "preview.png")
