"""Big volumes of the neural generator into Zarr, block by block, on a Dask cluster.

The run is :func:`npmrf3d.io.zarr_blocks.write_volume`'s, the executor of every Zarr volume made
in blocks: the output locked, an old volume kept until the new one is complete, the array and its
block markers, the blocks made in this process or as tasks of a Dask cluster. A task here loads
the model (once per worker process), generates its block with
:func:`npmrf3d.methods.neural.engine.generate_block` (tiles of the model's canonical grid: the
result does not depend on the block size or the worker) and writes it; a rerun of the same
command skips the finished blocks (resume after an interruption); a Zarr folder made by another
model or size is refused.

On a real cluster (``scheduler="tcp://HOST:8786"``) the model file and the output folder must be
on storage every worker sees.
"""

from __future__ import annotations

import os
import pathlib

import torch

from ...errors import ParameterError
from ...io.zarr_blocks import DONE, block_box, block_indices, write_block, write_volume
from . import model_identity
from .config import ZARR_BLOCK, ZARR_WORKERS
from .engine import generate_block, load_model

__all__ = ["DONE", "block_indices", "write_zarr"]

#: The models loaded in this process, by their file's digest.
_MODELS: dict[str, object] = {}


def _write_block(out: str, index, block: int, size, model_path: str, digest: str, threads: int | None) -> tuple:
    """One task: generate block ``index`` and write it and its marker (``threads``: torch's
    threads in a worker; None in the process that called :func:`write_zarr`, whose own setting
    stays)."""
    if threads is not None:
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
        processes with one thread each (``workers`` 1: every block made in this process).
    overwrite : bool
        Replace a volume of another model or size: the new one is made beside it and takes its
        place only once complete (an interrupted or failed run keeps the old one).
    progress : callable, optional
        ``progress(done, total)`` after each finished block (and once before the first).

    Returns
    -------
    dict
        ``blocks`` (total), ``skipped`` (already done), ``written``.
    """
    model = load_model(model_path)
    if block % model.config.tile:
        raise ParameterError(f"block must be a multiple of the model's tile {model.config.tile} "
                             f"(each tile is computed once); got {block}")
    size = tuple(int(n) for n in size)
    identity = model_identity(model_path)
    digest = identity["npmrf3d_model_sha256"]
    _MODELS[digest] = model
    here = scheduler is None and workers == 1
    summary = write_volume(pathlib.Path(out), size=size, channels=model.channels, block=block, attrs=identity,
                           task=_write_block, args=(block, size, os.fspath(model_path), digest, None if here else 1),
                           overwrite=overwrite, scheduler=scheduler, workers=workers, progress=progress)
    return {key: summary[key] for key in ("blocks", "skipped", "written")}
