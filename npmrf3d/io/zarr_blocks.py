"""A volume as a chunked Zarr array written block by block: create, resume, write a block.

The volume ``[0, size)^3`` is cut into ``block``-sided cubes aligned with the Zarr chunks, so a
block writes whole chunks of its own and two writers never touch the same file. After a block's
values are written, an empty marker ``.npmrf3d-done/I.J.K`` inside the array's folder says it
is finished; a rerun of the same command makes only the blocks without a marker (a block cut
off half-way is made again whole). The array's attributes say what made it (the run's
identity): a folder made by another run is refused, not mixed (the refusal names what
differs). :func:`claim_volume` holds the output's lock for a whole run and keeps an old volume
until the one replacing it is complete; :func:`write_volume` runs a whole volume's block tasks
under it, in the caller's order, in this process or on a Dask cluster (or the first block here
while the cluster starts): the one executor of every volume made in blocks. The array is Zarr
format 2, ``(N1, N2, N3, C)`` float32, which napari opens directly (``napari vol.zarr``; C = 3
shows as RGB). Used by the block runner of the synthesis methods (:mod:`npmrf3d.methods.blocks`) and
the neural generator (:mod:`npmrf3d.methods.neural.zarr_volume`).
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import os
import pathlib
import shutil
import time

import numpy as np
import zarr

from .._cluster import ClusterStart
from ..errors import ParameterError
from .runs import OutputLock, glob_escape, new_staging, replace_folder

__all__ = ["DONE", "NEXT", "block_box", "block_indices", "claim_volume", "clamp_block", "differences",
           "finished_blocks", "next_folder", "open_blocks", "read_attributes", "volume_attrs", "write_block",
           "write_volume"]

#: The folder of finished-block markers inside the array's folder.
DONE = ".npmrf3d-done"
#: What each identifying attribute is, for the refusal of a folder made by another run.
_WHAT = {"npmrf3d_size": "size", "npmrf3d_block": "block", "npmrf3d_model_sha256": "model"}


def block_indices(size, block: int) -> list[tuple[int, int, int]]:
    """Block indices ``(I, J, K)`` covering ``size`` with cubes of side ``block``.

    >>> block_indices((4, 4, 2), 2)
    [(0, 0, 0), (0, 1, 0), (1, 0, 0), (1, 1, 0)]
    """
    counts = [-(-int(n) // block) for n in size]
    return list(itertools.product(*(range(c) for c in counts)))


def block_box(index, block: int, size) -> tuple[tuple[int, int, int], tuple[int, int, int]]:
    """The first voxel and the shape of block ``index`` (the last blocks along an axis may be
    shorter).

    >>> block_box((1, 0, 2), 4, (6, 4, 10))
    ((4, 0, 8), (2, 4, 2))
    """
    origin = tuple(int(i) * block for i in index)
    return origin, tuple(min(block, int(n) - o) for o, n in zip(origin, size))


def volume_attrs(attrs: dict, size, block: int) -> dict:
    """The identifying attributes of a volume: ``attrs`` (the run's identity, JSON values) with
    its size and block."""
    return {**attrs, "npmrf3d_size": [int(n) for n in size], "npmrf3d_block": int(block)}


def clamp_block(block: int, size) -> int:
    """The side of the blocks of a ``size`` volume asked for as ``block``: at most the volume's
    largest side (one block then holds it all).

    >>> clamp_block(2000, (16, 16, 8)), clamp_block(8, (16, 16, 16))
    (16, 8)
    """
    return max(1, min(int(block), max(int(n) for n in size)))


def open_blocks(out, *, size, channels: int, block: int, attrs: dict, overwrite: bool = False,
                record: dict | None = None) -> None:
    """Create the Zarr array ``out`` for a ``size`` volume of ``channels`` channels in chunks of
    ``block``, with ``attrs`` (the run's identity) and ``record`` (what is said about it); or,
    when ``out`` holds an array of this run (the same ``attrs`` items, which must be JSON
    values), keep it to resume. The array appears whole (made beside ``out`` and renamed into
    place), never without its attributes. A folder that is not a Zarr volume of npmrf3d is
    refused (:class:`npmrf3d.ParameterError`), and so is a volume of another run unless
    ``overwrite``, which removes it at once (:func:`claim_volume` keeps it until the new one
    is complete)."""
    out = pathlib.Path(out)
    attrs = volume_attrs(attrs, size, block)
    existing = _holds(out)
    if existing is not None:
        if not overwrite:
            _refuse_other(out, attrs, existing)
            return
        shutil.rmtree(out)
    staging = new_staging(out)
    try:
        array = zarr.create_array(staging, shape=(*(int(n) for n in size), int(channels)),
                                  chunks=(block, block, block, int(channels)), dtype="float32",
                                  zarr_format=2, fill_value=0.0, overwrite=True)
        array.attrs.update({**attrs, **({} if record is None else {"npmrf3d_record": record})})
        os.makedirs(staging / DONE, exist_ok=True)
        replace_folder(staging, out)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _holds(out: pathlib.Path) -> dict | None:
    """The identifying attributes of the npmrf3d volume at ``out``; None when there is nothing
    there (or an empty folder); refused when something else is."""
    if not out.exists():
        return None
    if not out.is_dir():
        raise ParameterError(f"output '{out}' exists and is not a folder; choose another --out")
    if not any(out.iterdir()):
        return None
    existing = read_attributes(out)
    if existing is None or "npmrf3d_size" not in existing:
        raise ParameterError(f"output '{out}' exists and is not a Zarr volume of npmrf3d (it is left "
                             f"untouched); choose another --out")
    return existing


def _refuse_other(out: pathlib.Path, attrs: dict, existing: dict) -> None:
    """Refuse the volume at ``out`` when its identity differs from ``attrs``, naming what differs."""
    differ = differences(attrs, existing)
    if differ:
        listed = differ[0] if len(differ) == 1 else f"{', '.join(differ[:-1])} and {differ[-1]}"
        raise ParameterError(f"output '{out}' holds a volume of another {listed}; "
                             f"pass --overwrite or choose another --out")


def differences(attrs: dict, existing: dict) -> list[str]:
    """What differs between this run's identifying ``attrs`` and an ``existing`` volume's, each
    as ``what (ITS VALUE, this run: VALUE)``; a run's settings field by field.

    >>> differences({"npmrf3d_size": [8, 8, 8], "npmrf3d_block": 8}, {"npmrf3d_size": [8, 8, 8], "npmrf3d_block": 4})
    ['block (4, this run: 8)']
    """
    found = []
    for key, value in attrs.items():
        old = existing.get(key)
        if old == value:
            continue
        if key == "npmrf3d_run":
            found.extend(_run_differences(value, old))
        else:
            found.append(f"{_WHAT.get(key, key)} ({_show(old)}, this run: {_show(value)})")
    return list(dict.fromkeys(found))  # the size is in the settings too


def _run_differences(new: str, old) -> list[str]:
    """The fields of two run identities (:func:`npmrf3d.methods.blocks.run_identity`) that differ."""
    try:
        new, old = json.loads(new), json.loads(old)
    except (TypeError, ValueError):
        return ["run (made by another version of npmrf3d)"]
    found = []
    if new.get("method") != old.get("method"):
        found.append(f"method ({old.get('method')}, this run: {new.get('method')})")
    else:
        mine, theirs = new.get("config") or {}, old.get("config") or {}
        for name in sorted(set(mine) | set(theirs)):
            if mine.get(name) != theirs.get(name):
                found.append(f"{name} ({_show(theirs.get(name))}, this run: {_show(mine.get(name))})")
    if new.get("exemplars") != old.get("exemplars"):
        found.append("exemplar")
    return found or ["run"]


def _show(value) -> str:
    if isinstance(value, list) and all(isinstance(v, int) for v in value):
        return "x".join(map(str, value))
    return str(value)


#: The marker of the folder beside a volume where a resumable run that replaces it is made:
#: ``.NAME.next-KEY.zarr``, the key from the output and the run's identity (:func:`next_folder`).
NEXT = ".next-"


def next_folder(out, attrs: dict) -> pathlib.Path:
    """Where a resumable run of identity ``attrs`` (:func:`volume_attrs`) that replaces the
    volume at ``out`` makes its volume: the same folder for the same command, so a rerun resumes
    it."""
    out = pathlib.Path(out).absolute()
    key = hashlib.sha256(json.dumps({"out": str(out), **attrs}, sort_keys=True, default=str).encode())
    return out.parent / f".{out.name}{NEXT}{key.hexdigest()[:16]}.zarr"


@contextlib.contextmanager
def claim_volume(out, *, attrs: dict, overwrite: bool = False, resume: bool = True):
    """``with claim_volume(out, attrs=..., ...) as place:`` the folder to make the Zarr volume
    of ``out`` in, under the exclusive :class:`npmrf3d.io.runs.OutputLock` of ``out`` (a second
    writer is refused at once).

    ``attrs`` is the run's identity with its size and block (:func:`volume_attrs`). Whatever is
    at ``out`` is refused unless it is nothing, an empty folder or a Zarr volume of npmrf3d, and
    a volume is refused unless ``overwrite`` or, for a ``resume``-able (block-wise) run, it is
    this run's (the refusal names what differs). A resumable run is made in place (created, or
    resumed); one that replaces a volume, in a ``NEXT`` folder beside it (:func:`next_folder`,
    resumed by the same command); a run made at once in a staging folder. A staged volume takes
    the place of ``out`` only once complete (the old one stays until then). On failure or
    interruption a staging folder, or a resumable volume without a finished block, is removed,
    so nothing is left that cannot be resumed. Once a volume is in place, the ``NEXT`` folders
    of other runs into ``out`` (abandoned replacements) are removed.
    """
    out = pathlib.Path(out)
    with OutputLock(out, what="output"):
        existing = _holds(out)
        if existing is not None and not overwrite:
            _refuse_other(out, attrs, existing)
            if not resume:
                raise ParameterError(f"output '{out}' already holds the volume of this run; pass "
                                     f"--overwrite to make it again or choose another --out")
        if not resume:
            place = new_staging(out)
        elif existing is None or not overwrite:
            place = out
        else:
            place = next_folder(out, attrs)
        mine = place != out or existing is None  # what this run made, and may take away again
        missing = _missing_folders(out) if place == out else []
        was_empty = place == out and out.is_dir()
        try:
            yield place
        except BaseException:
            if mine and not (resume and finished_blocks(place)):
                shutil.rmtree(place, ignore_errors=True)
                if was_empty:
                    out.mkdir(exist_ok=True)
                for folder in missing:
                    with contextlib.suppress(OSError):
                        folder.rmdir()
            raise
        if place != out:
            replace_folder(place, out)
        for other in out.absolute().parent.glob(glob_escape(f".{out.name}{NEXT}") + "*"):
            shutil.rmtree(other, ignore_errors=True)


def _missing_folders(out: pathlib.Path) -> list[pathlib.Path]:
    """``out`` and its ancestors that do not exist yet, deepest first."""
    missing = []
    folder = out.absolute()
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    return missing


def read_attributes(out) -> dict | None:
    """The attributes of the Zarr array at ``out``; None when there is none."""
    try:
        return dict(zarr.open_array(pathlib.Path(out), mode="r").attrs)
    except Exception:  # zarr raises several types for a folder that is not an array
        return None


def finished_blocks(out) -> set[tuple[int, int, int]]:
    """The indices of the blocks of ``out`` that have their marker."""
    done = pathlib.Path(out, DONE)
    if not done.is_dir():
        return set()
    found = set()
    for p in done.iterdir():
        parts = p.name.split(".")
        if len(parts) == 3 and all(x.isdigit() for x in parts):
            found.add(tuple(int(x) for x in parts))
    return found


def blocks_without_chunks(out) -> list[tuple[int, int, int]]:
    """The blocks of the volume at ``out`` that have their marker but no chunk file, sorted:
    read, they hold Zarr's fill value (0). A chunk deleted after its block was made is one;
    a block whose values were all 0 is another, since Zarr stores no chunk that holds only
    the fill value. A volume whose chunks are not its blocks has none."""
    array = zarr.open_array(pathlib.Path(out), mode="r")
    block = array.attrs.get("npmrf3d_block")
    if block is None or tuple(array.chunks[:3]) != (int(block),) * 3:
        return []
    separator = getattr(array.metadata, "dimension_separator", ".") or "."
    tail = [separator + "0"] * (array.ndim - 3)    # the one chunk along the channels
    return sorted(index for index in finished_blocks(out)
                  if not pathlib.Path(out, separator.join(map(str, index)) + "".join(tail)).is_file())


def write_block(out, index, block: int, values: np.ndarray) -> None:
    """Write block ``index`` (``values`` of its :func:`block_box` shape, with channels) into the
    array ``out``, then its marker. The chunk file is written even when every value is the fill
    value 0, so that a made block always has one and a lost chunk file is told from zeros."""
    array = zarr.open_array(pathlib.Path(out), mode="r+").with_config({"write_empty_chunks": True})
    origin, shape = block_box(index, block, array.shape[:3])
    array[tuple(slice(o, o + s) for o, s in zip(origin, shape))] = np.asarray(values, dtype=np.float32)
    pathlib.Path(out, DONE, ".".join(map(str, index))).touch()


def write_volume(out, *, size, channels: int, block: int, attrs: dict, task, args: tuple = (),
                 here_args: tuple | None = None, overwrite: bool = False, record: dict | None = None,
                 scheduler: str | None = None, workers: int = 1, order=None, first_here=None,
                 progress=None) -> dict:
    """Make the ``size`` volume of ``channels`` channels into the Zarr array ``out``, block by
    block: ``task(place, index, *args)`` makes block ``index`` and writes it into the array at
    ``place`` (:func:`write_block`), and returns what the caller wants back (picklable). The one
    executor of every volume made in blocks.

    The output is claimed for the whole run (:func:`claim_volume`: its lock; an old volume kept
    until the new one is complete, ``overwrite`` or not) and created or resumed
    (:func:`open_blocks` with the run's identity ``attrs`` and its ``record``); only the blocks
    without a marker are made, in the order of the key ``order(index)`` (None: their indices'),
    in this process one after another when ``workers`` is 1 and no ``scheduler`` is given, else
    as tasks of a local Dask cluster of ``workers`` processes or of the running scheduler at that
    address. With a cluster, ``first_here(place)`` true makes the first block in this process
    while the cluster starts in the background (a block that makes what the others read). A
    block made in this process gets ``here_args`` instead of ``args`` (None: ``args``; e.g. the
    threads of every core rather than a worker's share). ``progress(done, total)`` once before
    the first block and after each one.

    Returns
    -------
    dict
        ``blocks`` (total), ``skipped`` (already done), ``written``, ``results`` (what the tasks
        returned, in the order they finished), ``rest_seconds`` and ``rest_blocks`` (the wall
        time of the blocks after the first one made in this process, with what is left of the
        cluster's start, and their number; every block when none is made here first).
    """
    size = tuple(int(n) for n in size)
    here_args = args if here_args is None else here_args
    with claim_volume(out, attrs=volume_attrs(attrs, size, block), overwrite=overwrite) as place:
        open_blocks(place, size=size, channels=channels, block=block, attrs=attrs, record=record)
        indices = block_indices(size, block)
        finished = finished_blocks(place)
        todo = sorted((i for i in indices if i not in finished), key=order)
        if scheduler is None and workers == 1:
            here = todo
        else:
            here = todo[:1] if todo and first_here is not None and first_here(place) else []
        on_cluster = todo[len(here):]
        results = []

        def made(result) -> None:
            results.append(result)
            if progress is not None:
                progress(len(indices) - len(todo) + len(results), len(indices))

        if progress is not None:
            progress(len(indices) - len(todo), len(indices))
        # the cluster starts in the background: its workers' start-up overlaps the first block
        with ClusterStart(scheduler, workers) if on_cluster else contextlib.nullcontext() as cluster:
            if here:
                made(task(os.fspath(place), here[0], *here_args))
            t_rest = time.perf_counter()
            for index in here[1:]:
                made(task(os.fspath(place), index, *here_args))
            if on_cluster:
                from distributed import as_completed

                client = cluster.client()
                futures = [client.submit(task, os.fspath(place), index, *args, pure=False) for index in on_cluster]
                for future in as_completed(futures):
                    made(future.result())
            rest_seconds = time.perf_counter() - t_rest
    return {"blocks": len(indices), "skipped": len(indices) - len(todo), "written": len(todo), "results": results,
            "rest_seconds": rest_seconds, "rest_blocks": len(todo) - min(1, len(here))}
