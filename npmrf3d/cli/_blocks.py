"""Volumes into Zarr from the command line: ``--out VOL.zarr`` of every command that makes a
volume, and ``--block``, ``--workers``, ``--scheduler`` and ``--blockwise`` of the commands whose
samplers run in blocks.

An ``--out`` ending in ``.zarr`` writes the volume into a chunked Zarr array (:func:`run_zarr`,
the one place every such command calls): made at once when it fits in memory, or with
``--blockwise`` block by block (:func:`npmrf3d.methods.blocks.write_zarr`) with the block-local
sampler, on a local Dask cluster or a running scheduler, where a rerun of the same command
makes only the missing blocks. The output is locked for the whole run (a second writer is
refused), and a volume replaced with ``--overwrite`` stays until the new one is complete
(:func:`npmrf3d.io.zarr_blocks.claim_volume`). The array's attributes hold the run record;
``preview.png`` inside the folder shows the exemplar, the three centre slices and the cube's
faces of a corner.
"""

from __future__ import annotations

import argparse
import contextlib
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
from ..io.files import json_text
from ..io.runs import OutputLock, run_record
from ..io.zarr_blocks import (
    block_box,
    block_indices,
    claim_volume,
    clamp_block,
    next_folder,
    open_blocks,
    read_attributes,
    volume_attrs,
    write_block,
)
from ..methods import check_resources
from ..methods.blocks import block_plan, run_identity, write_zarr, zarr_attrs
from ..plotting import preview_figure, save_figure
from ..resources import available_memory, format_bytes, format_seconds
from ._common import PROG, claim_output, dry_run, positive_int, say, write_result
from ._options import given
from ._progress import run_method

__all__ = ["DEFAULT_BLOCK", "add_block_options", "blockwise_requested", "kept_on_interrupt", "run_to_output",
           "run_zarr", "zarr_output"]

#: Side of the blocks (and Zarr chunks) when none is asked for: large against the default's
#: aprons (18 voxels a side at the finest level), so the cones repeat little work (512^3: 1.7x
#: the pyramid's voxels in cones against 2.0x with blocks of 128), and 1.45 GiB at most per
#: worker (measured at 512^3 with 2 threads).
DEFAULT_BLOCK = 192
#: Block sides that ``--dry-run`` weighs against the one asked for (:func:`larger_blocks`): a
#: larger block's cone repeats less of its neighbours' work (1024^3: 2.2x the pyramid's voxels
#: in blocks of 192, 1.3x in blocks of 512), at the price of its memory and of larger chunks.
LARGER_BLOCKS = (256, 384, 512)
#: Local workers when none is asked for: one, the command itself with every core as numba
#: threads (512^3 on 2 cores: 13.6 min); a block made in a Dask worker process takes 2-4 s more
#: (a 192^3 block of 512^3: 40.5-43 s against 38.2-39.6 s in the command's process).
DEFAULT_WORKERS = 1


def add_block_options(group: argparse._ArgumentGroup, *, sampler: bool = True) -> None:
    """``--block``, ``--workers`` and ``--scheduler`` into ``group``; with ``sampler`` also
    ``--blockwise`` and ``--whole-voxels`` (a command whose configuration has those fields makes
    them options itself)."""
    if sampler:
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
        help="--out VOL.zarr --blockwise: side of the blocks and of the Zarr chunks (at most the "
             "volume's largest side); each worker holds one block's dependency cone (--dry-run shows "
             "its memory)")
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


def run_to_output(args: argparse.Namespace, argv: list[str], command: str, method, config, per_view: dict,
                  sources: dict, title: str, *, out: pathlib.Path, checkpoint: pathlib.Path | None,
                  preview: dict | None = None, record: dict | None = None, **run_options) -> int:
    """Run ``method`` and write its volume where ``--out`` says: a Zarr array (:func:`run_zarr`)
    or the run folder ``out`` (under its lock), or with ``--dry-run`` say what it would need.
    ``preview``, ``record`` and ``run_options`` as :func:`run_zarr` takes them."""
    if zarr_output(args):
        return run_zarr(args, argv, command, method, config, per_view, sources, title, preview=preview,
                        record=record, **run_options)
    if args.dry_run:
        return dry_run(method, config, per_view)
    with claim_output(out, args.overwrite):
        result = run_method(args, method, config, per_view, checkpoint=checkpoint, **run_options)
        write_result(out, args, argv, command, result, per_view if preview is None else preview, sources,
                     title, method=method.name, **(record or {}))
    return 0


def run_zarr(args: argparse.Namespace, argv: list[str], command: str, method, config, per_view: dict,
             sources: dict, title: str, *, preview: dict | None = None, record: dict | None = None,
             **run_options) -> int:
    """Make ``config``'s volume into the Zarr array ``--out``: at once when it is not
    ``blockwise`` (the memory checked first), else in blocks; ``--dry-run`` prints the estimate
    or the block plan. ``preview``: the images the preview shows beside the volume (default:
    the exemplars); ``record``: further fields of the run record; ``run_options``: what the
    method's run takes besides (as :func:`npmrf3d.cli._progress.run_method`)."""
    preview = per_view if preview is None else preview
    if not getattr(config, "blockwise", False):
        return _zarr_at_once(args, argv, command, method, config, per_view, sources, title, preview,
                             record or {}, run_options)
    if getattr(args, "checkpoint", None) is not None:
        raise ParameterError("--checkpoint does not apply to --out VOL.zarr --blockwise: the Zarr volume "
                             "keeps its finished blocks, and the same command resumes it")
    scheduler = check_scheduler(args.scheduler)
    if scheduler in ("local", "serial"):
        scheduler = None
    if scheduler is not None:
        probe_scheduler(scheduler)
    out = pathlib.Path(args.out)
    block = clamp_block(args.block, config.size)
    plan = block_plan(method, per_view, config, block=block)
    clamped = (f" (--block {args.block} is more than the volume's largest side: one block holds it)"
               if block < args.block and given(args, "block") else "")
    if args.dry_run:
        say(f"{method.name} {'x'.join(map(str, config.size))} into {out}: {plan.describe()}{clamped}")
        say(plan.total(args.workers, scheduler))
        available = available_memory()
        if available is not None and scheduler is None:
            fits = "fits" if plan.memory.bytes * args.workers <= available else "does NOT fit"
            say(f"available memory: {format_bytes(available)} (the run {fits})")
            faster = larger_blocks(method, per_view, config, plan, available // args.workers)
            if faster:
                say("larger blocks repeat less work in their cones (the same volume, larger Zarr chunks): "
                    + "; ".join(f"--block {p.block}: roughly {format_seconds(p.seconds)}, "
                                f"{format_bytes(p.memory.bytes)} a block" for p in faster))
        return 0
    run = _record(command, argv, method, config, sources, block=block,
                  workers=None if scheduler else args.workers, scheduler=scheduler, **(record or {}))
    bar = None

    def progress(done, total):
        nonlocal bar
        if args.quiet:
            return
        if bar is None:  # the output is claimed and checked: the plan, then the bar
            say(f"{method.name}: {plan.describe()}{clamped}")
            bar = tqdm(total=total, initial=done, desc="blocks", unit="block", file=sys.stderr,
                       dynamic_ncols=True)
        else:
            bar.update(done - bar.n)

    attrs = zarr_attrs(method, config, per_view, block)
    with OutputLock(out, what="output"), kept_on_interrupt(args, out, attrs):
        try:
            threads = 1 if scheduler else max(1, (os.cpu_count() or 1) // args.workers)
            summary = write_zarr(method, per_view, config, out, block=block, record=run,
                                 workers=args.workers, threads=threads, scheduler=scheduler,
                                 overwrite=args.overwrite, progress=progress)
        finally:
            if bar is not None:
                bar.close()
        array = zarr.open_array(out, mode="r+")
        array.attrs["npmrf3d_block_seconds"] = float(array.attrs.get("npmrf3d_block_seconds", 0.0)) + summary["seconds"]
        peak = max(int(array.attrs.get("npmrf3d_worker_peak_bytes", 0)), int(summary["worker_peak_bytes"]))
        array.attrs["npmrf3d_worker_peak_bytes"] = peak
        _preview(out, array, preview, title, block)
    if not args.quiet:
        workers = f"; a worker's peak memory {format_bytes(peak)}" if peak else ""
        say(f"wrote {out}: {summary['written']} blocks written, {summary['skipped']} already done{workers}; "
            f"volume {'x'.join(map(str, array.shape))} (N1xN2xN3xC) float32, Zarr format 2 "
            f"(napari {out}), preview.png inside")
    return 0


def larger_blocks(method, per_view, config, plan, memory: int) -> list:
    """The block plans of :data:`LARGER_BLOCKS` sides above ``plan``'s (at most the volume's
    largest side) whose block fits in ``memory`` bytes and whose whole run is estimated at least
    a tenth faster than the smaller block's before it, fastest last."""
    largest = max(int(n) for n in config.size)
    faster, best = [], plan.seconds
    for side in (s for s in LARGER_BLOCKS if plan.block < s <= largest):
        larger = block_plan(method, per_view, config, block=side)
        if best is None or larger.seconds is None or larger.memory.bytes > memory:
            break
        if larger.seconds <= 0.9 * best:
            faster.append(larger)
            best = larger.seconds
    return faster


@contextlib.contextmanager
def kept_on_interrupt(args: argparse.Namespace, out: pathlib.Path, attrs: dict):
    """Around a resumable Zarr run into ``out`` of identity ``attrs``: when it replaces a volume
    (``--overwrite``), its finished blocks are kept beside it
    (:func:`npmrf3d.io.zarr_blocks.next_folder`), so after Ctrl-C ``args.out`` names that folder
    for the line that says what is kept (the volume at ``out`` is untouched)."""
    replacing = args.overwrite and read_attributes(out) is not None
    try:
        yield
    except KeyboardInterrupt:
        if replacing:
            args.out = str(next_folder(out, attrs))
        raise


def _record(command: str, argv, method, config, sources: dict, result=None, **extra) -> dict:
    """The run record a Zarr volume keeps in its attributes (as ``run.json`` holds it), as JSON
    values."""
    record = run_record(command, result, exemplars=sources, method=method.name, argv=[PROG, *argv], **extra)
    if record["config"] is None:
        record["config"], record["seed"] = config.to_dict(), config.seed
    return json.loads(json_text(record))


def _zarr_at_once(args, argv, command, method, config, per_view, sources, title, preview, record,
                  run_options) -> int:
    """The volume made at once (as a run folder would hold it) and written into the Zarr array
    ``--out`` in chunks of ``DEFAULT_BLOCK``, with the run record in its attributes; made in a
    staging folder that takes the place of ``--out`` only once complete."""
    blocks = "" if method.aprons is None else ", or make it in blocks with --blockwise (docs/blocks.md)"
    check_resources(method, config, per_view, hint=f"lower --size{blocks}; --dry-run shows the estimate")
    if args.dry_run:
        return dry_run(method, config, per_view)
    vars(args).pop("block", None)  # an interrupted at-once run keeps no blocks: said as any run's
    out = pathlib.Path(args.out)
    block = clamp_block(DEFAULT_BLOCK, config.size)
    identity = {"npmrf3d_run": run_identity(method, config, per_view)}
    checkpoint = pathlib.Path(args.checkpoint) if getattr(args, "checkpoint", None) else None
    with claim_volume(out, attrs=volume_attrs(identity, config.size, block), overwrite=args.overwrite,
                      resume=False) as place:
        result = run_method(args, method, config, per_view, checkpoint=checkpoint, **run_options)
        open_blocks(place, size=config.size, channels=result.volume.shape[-1], block=block, attrs=identity,
                    record=_record(command, argv, method, config, sources, result, **record))
        for index in block_indices(config.size, block):
            origin, shape = block_box(index, block, config.size)
            write_block(place, index, block, result.volume[tuple(slice(o, o + n) for o, n in zip(origin, shape))])
        array = zarr.open_array(place, mode="r+")
        array.attrs["npmrf3d_seconds"] = float(result.timings["total"])
        _preview(place, array, preview, title, block)
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
