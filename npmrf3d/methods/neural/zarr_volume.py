"""Big volumes of the neural generator into Zarr, block by block, on a Dask cluster.

The array, its blocks and their markers are :mod:`npmrf3d.io.zarr_blocks`'s. A task loads the
model (once per worker process), generates its block with
:func:`npmrf3d.methods.neural.engine.generate_block` (tiles of the model's canonical grid: the
result does not depend on the block size or the worker) and writes it; a rerun of the same
command skips the finished blocks (resume after an interruption); a Zarr folder made by another
model or size is refused.

On a real cluster (``scheduler="tcp://HOST:8786"``) the model file and the output folder must be
on storage every worker sees.
"""

from __future__ import annotations

import hashlib
import os
import pathlib

import torch
from dask.distributed import Client, as_completed

from ..._cluster import local_cluster
from ...errors import ParameterError
from ...io.zarr_blocks import DONE, block_box, block_indices, finished_blocks, open_blocks, write_block
from .config import ZARR_BLOCK, ZARR_WORKERS
from .engine import generate_block, load_model

__all__ = ["DONE", "block_indices", "write_zarr"]

_MODELS: dict[str, object] = {}


def _digest(path) -> str:
    return hashlib.sha256(pathlib.Path(path).read_bytes()).hexdigest()


def _write_block(model_path: str, digest: str, out: str, index, block: int, size, threads: int) -> tuple:
    """One task: generate block ``index`` and write it and its marker (runs on a worker)."""
    torch.set_num_threads(threads)
    model = _MODELS.get(digest)
    if model is None:
        model = _MODELS[digest] = load_model(model_path)
    origin, shape = block_box(index, block, size)
    write_block(out, index, block, generate_block(model, origin, shape))
    return index

def write_zarr(model_path, out, *, size, block: int = ZARR_BLOCK, scheduler: str | None = None,
               workers: int = ZARR_WORKERS, overwrite: bool = False, progress=None) -> dict:
    """Write the ``size`` volume of the model at ``model_path`` into the Zarr array ``out``.

    Parameters
    ----------
    model_path : path
        A model file of ``npmrf3d neural train``.
    out : path
        The Zarr folder (created; resumed when it holds this model's unfinished volume).
    size : three ints
    block : int
        Side of the blocks (and Zarr chunks) the tasks write.
    scheduler : str, optional
        Address of a running Dask scheduler; None starts a local cluster of ``workers``
        processes with one thread each.
    progress : callable, optional
        ``progress(done, total)`` after each finished block (and once before the first).

    Returns
    -------
    dict
        ``blocks`` (total), ``skipped`` (already done), ``written``, ``dashboard`` (a link or None).
    """
    model = load_model(model_path)
    if block % model.config.tile:
        raise ParameterError(f"block must be a multiple of the model's tile {model.config.tile} "
                             f"(each tile is computed once); got {block}")
    out = pathlib.Path(out)
    size = tuple(int(n) for n in size)
    digest = _digest(model_path)
    open_blocks(out, size=size, channels=model.channels, block=block,
                attrs={"npmrf3d_model_sha256": digest}, overwrite=overwrite)
    indices = block_indices(size, block)
    finished = finished_blocks(out)
    todo = [i for i in indices if i not in finished]
    cluster = None
    if scheduler is None:
        cluster = local_cluster(workers, dashboard_address=None)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    done = len(indices) - len(todo)
    try:
        if progress is not None:
            progress(done, len(indices))
        futures = [client.submit(_write_block, os.fspath(model_path), digest, os.fspath(out), i,
                                 block, size, 1, pure=False) for i in todo]
        for future in as_completed(futures):
            future.result()
            done += 1
            if progress is not None:
                progress(done, len(indices))
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return {"blocks": len(indices), "skipped": len(indices) - len(todo), "written": len(todo)}
