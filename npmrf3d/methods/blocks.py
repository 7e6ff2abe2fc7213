"""Volumes of any size made block by block: in memory, or into a Zarr array on a Dask cluster.

A registered method with ``aprons`` (:class:`npmrf3d.config.SynthesisMethod`; the block-local
configurations of the coherent samplers, ``blockwise=True``) makes any block of its volume from
the block's dependency cone (:mod:`npmrf3d.model.regions`), every random number a hash of the
seed and a grid position: a volume made as blocks equals, bit for bit, the volume made at once
with the same seed, whatever the block size, the order of the blocks or the worker that makes
them. :func:`make_block` makes one block; :func:`synthesize_blocks` a whole volume in memory;
:func:`write_zarr` a volume of any size that fits on disk, each block a task of a local Dask
cluster (``workers``) or of a running scheduler, into a chunked Zarr array: the run is
:func:`npmrf3d.io.zarr_blocks.write_volume`'s (resumable, the run's record in its attributes),
given this module's block task, the largest blocks first and the first block made in this
process while the cluster starts; it sums the tasks' seconds and peak memory.

The cost of a block is its cone: the block grown at every level by that level's apron
(iterations times the window's reach), so blocks much larger than the aprons waste least
(:func:`block_plan` reports the share).
"""

from __future__ import annotations

import dataclasses
import json
import os
import pathlib
import resource
import time
from collections.abc import Callable, Mapping

import numpy as np

from .. import _validation as check
from .._kernels._jit import use_threads
from ..config import SynthesisMethod
from ..io.zarr_blocks import block_box, block_indices, clamp_block, volume_attrs, write_block, write_volume
from ..io.checkpoints import exemplar_digest
from ..model.pyramid import level_shape
from ..model.regions import RegionPlan, plan_region
from ..resources import Estimate, available_memory, check_memory, format_bytes, format_seconds
from . import METHODS
from ._api import settled

__all__ = ["BlockPlan", "block_plan", "blockwise_method", "make_block", "run_identity", "shared_exemplars",
           "synthesize_blocks", "write_zarr", "zarr_attrs"]


def blockwise_method(method: SynthesisMethod, config, per_view) -> tuple[int, ...]:
    """The method's aprons for ``config``; a clear error when it cannot run in blocks."""
    aprons = None if method.aprons is None else method.aprons(config, per_view)
    if aprons is None:
        check.fail(f"method {method.name} with these settings cannot be made in blocks: only the "
                   f"block-local coherent samplers can (blockwise=True, fixed iterations, no per-voxel "
                   f"temperatures)")
    return tuple(None if a is None else int(a) for a in aprons)


def make_block(method: SynthesisMethod, per_view: Mapping[str, np.ndarray], config, origin, shape,
               start) -> np.ndarray:
    """Block ``origin .. origin + shape - 1`` of the volume ``config`` makes (its ``size`` and
    ``seed``; the seed must be set), from its dependency cone alone: ``(*shape, C)`` float32.
    ``start`` is the checkpoint of the levels that run whole, shared by all blocks: made by the
    first block that finds none, read by the others."""
    if config.seed is None:
        raise ValueError("a block needs the run's seed")
    per_view = shared_exemplars(per_view)
    config = settled(method, config, per_view)
    plan = plan_region(config.size, config.levels, blockwise_method(method, config, per_view), origin, shape,
                       start=start)
    return method.run(per_view, config, np.random.default_rng(config.seed), region=plan).volume


def run_identity(method: SynthesisMethod, config, per_view) -> str:
    """What makes a Zarr volume this run's and no other's (JSON): the method, its configuration
    (seed included, settled on the exemplars) and each view's exemplar digest."""
    config = settled(method, config, per_view)
    return json.dumps({"method": method.name, "config": config.to_dict(),
                       "exemplars": {v: exemplar_digest(a) for v, a in per_view.items()}}, sort_keys=True, default=str)


def zarr_attrs(method: SynthesisMethod, config, per_view, block: int) -> dict:
    """The identifying attributes of ``config``'s Zarr volume in blocks of ``block`` (clamped to
    the volume, :func:`npmrf3d.io.zarr_blocks.clamp_block`)."""
    return volume_attrs({"npmrf3d_run": run_identity(method, config, per_view)}, config.size,
                        clamp_block(block, config.size))


def shared_exemplars(per_view: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``per_view`` with views of equal exemplars sharing one array: the methods treat an
    exemplar shared by views once (random numbers are drawn per distinct exemplar), and a task
    sent to a worker arrives with a copy per view."""
    seen: dict[str, np.ndarray] = {}
    return {v: seen.setdefault(exemplar_digest(a), a) for v, a in per_view.items()}


def synthesize_blocks(method: SynthesisMethod, per_view, config, *, block: int, start) -> np.ndarray:
    """The whole volume of ``config``, made as blocks of side ``block`` one after the other
    (``start``: the shared checkpoint of :func:`make_block`)."""
    size = tuple(config.size)
    out = None
    for index in block_indices(size, block):
        origin, shape = block_box(index, block, size)
        values = make_block(method, per_view, config, origin, shape, start)
        if out is None:
            out = np.empty((*size, values.shape[-1]), dtype=np.float32)
        out[tuple(slice(o, o + s) for o, s in zip(origin, shape))] = values
    return out


@dataclasses.dataclass(frozen=True)
class BlockPlan:
    """What a block run costs: the blocks, the largest cone, one block's memory estimate and the
    share of the work that is the cones' overlap."""

    blocks: int
    cone: RegionPlan
    memory: Estimate
    overhead: float
    block: int
    seconds: float | None = None

    def describe(self) -> str:
        frames = " < ".join("x".join(map(str, f.shape)) for f in reversed(self.cone.frames) if f is not None)
        whole = sum(f is None for f in self.cone.frames)
        plural = "s" * (self.blocks != 1)
        if whole == len(self.cone.frames):
            return (f"{self.blocks} block{plural} of {self.block}; every level made once, whole, by the first "
                    f"block, the others cut from it; {self.memory.describe()}")
        shared = ("the coarsest level made once, whole; " if whole == 1 else
                  f"the coarsest {whole} levels made once, whole; " if whole else "")
        return (f"{self.blocks} block{plural} of {self.block}; {shared}each block made from a cone of {frames} "
                f"voxels, {self.overhead:.1f}x the voxels of the volume's own levels; one block "
                f"{self.memory.describe()}")

    def total(self, workers: int = 1, scheduler: str | None = None) -> str:
        """What the whole run needs: its time (the work of every cone, at the estimate's rate)
        and the memory of the workers that hold a cone at once."""
        time = ("" if self.seconds is None else
                f"roughly {format_seconds(self.seconds)} of work on 2 cores for the {self.blocks} "
                f"block{'s' * (self.blocks != 1)}, ")
        if scheduler is not None:
            held = f"about {format_bytes(self.memory.bytes)} in each worker of the scheduler"
        elif workers == 1:
            held = f"at most about {format_bytes(self.memory.bytes)} (one block at a time)"
        else:
            held = (f"at most about {format_bytes(workers * self.memory.bytes)} ({workers} workers "
                    f"holding a block each)")
        return f"in all: {time}{held}"


def block_plan(method: SynthesisMethod, per_view, config, *, block: int) -> BlockPlan:
    """The :class:`BlockPlan` of making ``config``'s volume in blocks of side ``block`` (at most
    the volume's largest side): the memory of the first (largest) block's cone from the
    method's estimate at the cone's finest region, the voxels of all cones against the
    pyramid's, and the whole run's time (the method's estimate of the volume made at once,
    times that share)."""
    config = settled(method, config, per_view)
    size = tuple(config.size)
    block = clamp_block(block, size)
    aprons = blockwise_method(method, config, per_view)
    levels = config.levels
    indices = block_indices(size, block)
    biggest = None
    whole = sum(int(np.prod(level_shape(size, level))) for level, a in enumerate(aprons) if a is None)
    cone_voxels = whole
    for index in indices:
        plan = plan_region(size, levels, aprons, *block_box(index, block, size))
        voxels = sum(int(np.prod(f.shape)) for f in plan.frames if f is not None)
        cone_voxels += voxels
        if biggest is None or voxels > biggest[0]:
            biggest = (voxels, plan)
    pyramid = sum(int(np.prod(level_shape(size, level))) for level in range(levels))
    cone = biggest[1]
    # the larger of the finest region and the finest whole level, each as a one-level run
    sizes = ([f.shape for f in cone.frames[:1] if f is not None]
             + [level_shape(size, level) for level, f in enumerate(cone.frames) if f is None][:1])
    memory = max((method.resources(dataclasses.replace(config, size=shape, levels=1), per_view) for shape in sizes),
                 key=lambda e: e.bytes)
    # the whole run's time: the volume made at once, scaled by the cones' share of repeated voxels
    at_once = method.resources(config, per_view).seconds
    seconds = None if at_once is None else at_once * cone_voxels / pyramid
    return BlockPlan(len(indices), cone, memory, cone_voxels / pyramid, block, seconds)


#: The checkpoint of the levels that run whole, inside the Zarr folder (shared by all blocks).
START = ".npmrf3d-coarse.npz"


def _task(out: str, index, method_name: str, per_view, config, block: int, threads: int) -> tuple[float, int]:
    """One block's task (:func:`npmrf3d.io.zarr_blocks.write_volume`): make block ``index`` and
    write it and its marker into ``out``; its seconds and the process's peak resident memory so
    far (bytes)."""
    t0 = time.perf_counter()
    use_threads(threads)
    origin, shape = block_box(index, block, config.size)
    write_block(out, index, block, make_block(METHODS[method_name], per_view, config, origin, shape,
                                              os.path.join(out, START)))
    return time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def write_zarr(method: SynthesisMethod, per_view, config, out, *, block: int, record: dict,
               workers: int = 1, threads: int = 1, scheduler: str | None = None, overwrite: bool = False,
               memory_per_worker: int | None = None,
               progress: Callable[[int, int], None] | None = None) -> dict:
    """Make ``config``'s volume (its seed set) into the Zarr array ``out``, block by block.

    Parameters
    ----------
    method, per_view, config
        A registered method with aprons, its exemplars and a configuration with ``blockwise``.
    out : path
        The Zarr folder: created, or resumed when it holds this run's unfinished volume, under
        its lock (:func:`npmrf3d.io.zarr_blocks.claim_volume`: a second writer is refused).
    block : int
        Side of the blocks and of the Zarr chunks (at most the volume's largest side).
    overwrite : bool
        Replace a volume of another run: the new one is made beside it (resumed by the same
        call) and takes its place only once complete.
    record : dict
        The run's record (JSON values), kept in the array's attributes.
    workers, threads : int
        A local cluster of ``workers`` processes with ``threads`` numba threads each (ignored
        with ``scheduler``); one worker makes every block in this process.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://HOST:8786``); every worker must see ``out``.
    memory_per_worker : int, optional
        Bytes one worker may use; a block whose estimate exceeds it is refused before anything
        is written. None: the machine's available memory divided by ``workers``.
    progress : callable, optional
        ``progress(done, total)`` once before the first block and after each one.

    Returns
    -------
    dict
        ``blocks``, ``skipped`` (already done), ``written``, ``seconds`` (of the blocks made,
        summed over workers), ``rest_seconds`` and ``rest_blocks`` (the wall time of the blocks
        after the first, with what is left of the cluster's start, and their number),
        ``worker_peak_bytes`` (the largest peak resident memory of a process that made blocks:
        this one with one local worker), ``plan`` (:meth:`BlockPlan.describe`) and the estimate
        of one block (``block_bytes``, ``block_memory``).
    """
    block = clamp_block(block, config.size)
    plan = block_plan(method, per_view, config, block=block)
    if memory_per_worker is None:
        available = available_memory()
        memory_per_worker = None if available is None else available // max(1, workers if scheduler is None else 1)
    check_memory(plan.memory, available=memory_per_worker,
                 hint="use a smaller --block (each worker holds one block's cone), or fewer --workers")
    size = tuple(config.size)
    # one local worker: every block is made here, one after another with every core (a worker
    # process would only add its start and Dask's bookkeeping); else the first, which makes the
    # shared coarse levels, is made here with every core the cluster would use while the cluster
    # starts. The largest blocks first, so that the last ones, which a worker may make while the
    # others have nothing left, are the smallest (the order changes no voxel).
    summary = write_volume(
        out, size=size, channels=next(iter(per_view.values())).shape[-1], block=block,
        attrs={"npmrf3d_run": run_identity(method, config, per_view)}, task=_task,
        args=(method.name, per_view, config, block, threads),
        here_args=(method.name, per_view, config, block, workers * threads),
        overwrite=overwrite, record=json.loads(json.dumps(record, default=str)), scheduler=scheduler,
        workers=workers, order=lambda index: -int(np.prod(block_box(index, block, size)[1])),
        first_here=lambda place: not pathlib.Path(place, START).exists(), progress=progress)
    made = summary["results"]
    return {"blocks": summary["blocks"], "skipped": summary["skipped"], "written": summary["written"],
            "seconds": sum(seconds for seconds, _ in made), "rest_seconds": summary["rest_seconds"],
            "rest_blocks": summary["rest_blocks"], "worker_peak_bytes": max((peak for _, peak in made), default=0),
            "plan": plan.describe(), "block_bytes": plan.memory.bytes, "block_memory": format_bytes(plan.memory.bytes)}
