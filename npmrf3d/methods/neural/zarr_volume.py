"""Big volumes into Zarr, block by block, on a Dask cluster.

The volume ``[0, size)^3`` is cut into ``block``-sided cubes aligned with the Zarr chunks, so
every task writes whole chunks of its own and tasks never touch the same file. A task loads
the model (once per worker process), generates its block with
:func:`npmrf3d.methods.neural.engine.generate_block` (tiles of the model's canonical grid: the result
does not depend on the block size or the worker) and writes it, then an empty marker file
``.npmrf3d-done/I.J.K`` inside the array's folder. A rerun of the same command skips the blocks
with a marker (resume after an interruption); a Zarr folder made by another model or size is
refused. The array is Zarr format 2, ``(N1, N2, N3, C)`` float32, which napari opens directly
(``napari vol.zarr``; C = 3 shows as RGB).

On a real cluster (``scheduler="tcp://HOST:8786"``) the model file and the output folder must be
on storage every worker sees.
"""

from __future__ import annotations

import hashlib
import itertools
import os
import pathlib
import shutil

import torch
import zarr
from dask.distributed import Client, as_completed

from ..._cluster import local_cluster
from ...errors import ParameterError
from .config import ZARR_BLOCK, ZARR_WORKERS
from .engine import generate_block, load_model

__all__ = ["block_indices", "write_zarr"]

DONE = ".npmrf3d-done"
_MODELS: dict[str, object] = {}


def _digest(path) -> str:
    return hashlib.sha256(pathlib.Path(path).read_bytes()).hexdigest()


def block_indices(size, block: int) -> list[tuple[int, int, int]]:
    """Block indices ``(I, J, K)`` covering ``size`` with cubes of side ``block``."""
    counts = [-(-int(n) // block) for n in size]
    return list(itertools.product(*(range(c) for c in counts)))


def _write_block(model_path: str, digest: str, out: str, index, block: int, size, threads: int) -> tuple:
    """One task: generate block ``index`` and write it and its marker (runs on a worker)."""
    torch.set_num_threads(threads)
    model = _MODELS.get(digest)
    if model is None:
        model = _MODELS[digest] = load_model(model_path)
    origin = tuple(i * block for i in index)
    shape = tuple(min(block, n - o) for o, n in zip(origin, size))
    values = generate_block(model, origin, shape)
    array = zarr.open_array(out, mode="r+")
    array[tuple(slice(o, o + s) for o, s in zip(origin, shape))] = values
    pathlib.Path(out, DONE, ".".join(map(str, index))).touch()
    return index


def _prepare(model_path, out: pathlib.Path, size, block: int, channels: int, overwrite: bool):
    attrs = {"npmrf3d_model_sha256": _digest(model_path), "npmrf3d_size": list(size),
             "npmrf3d_block": block}
    if out.exists():
        if overwrite:
            shutil.rmtree(out) if out.is_dir() else out.unlink()
        else:
            try:
                existing = dict(zarr.open_array(out, mode="r").attrs)
            except Exception:
                raise ParameterError(f"output '{out}' exists and is not a Zarr array of this "
                                     f"command; pass --overwrite or choose another --out") from None
            if any(existing.get(k) != v for k, v in attrs.items()):
                raise ParameterError(f"output '{out}' holds a volume of another model, size or "
                                     f"block; pass --overwrite or choose another --out")
            return attrs
    array = zarr.create_array(out, shape=(*size, channels), chunks=(block, block, block, channels),
                              dtype="float32", zarr_format=2, fill_value=0.0)
    array.attrs.update(attrs)
    os.makedirs(out / DONE, exist_ok=True)
    return attrs


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
    _prepare(model_path, out, size, block, model.channels, overwrite)
    digest = _digest(model_path)
    indices = block_indices(size, block)
    finished = {tuple(int(x) for x in p.name.split(".")) for p in (out / DONE).iterdir()}
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
