"""A volume as a chunked Zarr array written block by block: create, resume, write a block.

The volume ``[0, size)^3`` is cut into ``block``-sided cubes aligned with the Zarr chunks, so a
block writes whole chunks of its own and two writers never touch the same file. After a block's
values are written, an empty marker ``.npmrf3d-done/I.J.K`` inside the array's folder says it
is finished; a rerun of the same command makes only the blocks without a marker (a block cut
off half-way is made again whole). The array's attributes say what made it (the run's
identity): a folder made by another run is refused, not mixed. The array is Zarr format 2,
``(N1, N2, N3, C)`` float32, which napari opens directly (``napari vol.zarr``; C = 3 shows as
RGB). Used by the block runner of the synthesis methods (:mod:`npmrf3d.methods.blocks`) and
the neural generator (:mod:`npmrf3d.methods.neural.zarr_volume`).
"""

from __future__ import annotations

import itertools
import os
import pathlib
import shutil

import numpy as np
import zarr

from ..errors import ParameterError

__all__ = ["DONE", "block_box", "block_indices", "finished_blocks", "open_blocks", "read_attributes",
           "write_block"]

#: The folder of finished-block markers inside the array's folder.
DONE = ".npmrf3d-done"
#: What each identifying attribute is, for the refusal of a folder made by another run.
_WHAT = {"npmrf3d_size": "size", "npmrf3d_block": "block", "npmrf3d_model_sha256": "model",
         "npmrf3d_run": "method, settings, seed or exemplar"}


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


def open_blocks(out, *, size, channels: int, block: int, attrs: dict, overwrite: bool = False,
                record: dict | None = None) -> None:
    """Create the Zarr array ``out`` for a ``size`` volume of ``channels`` channels in chunks of
    ``block``, with ``attrs`` (the run's identity) and ``record`` (what is said about it); or,
    when ``out`` holds an array of this run (the same ``attrs`` items, which must be JSON
    values), keep it to resume. Anything else at ``out`` is refused
    (:class:`npmrf3d.ParameterError`) unless ``overwrite``."""
    out = pathlib.Path(out)
    attrs = {**attrs, "npmrf3d_size": [int(n) for n in size], "npmrf3d_block": int(block)}
    if out.exists():
        if overwrite:
            shutil.rmtree(out) if out.is_dir() else out.unlink()
        else:
            existing = read_attributes(out)
            if existing is None:
                raise ParameterError(f"output '{out}' exists and is not a Zarr volume of npmrf3d; "
                                     f"pass --overwrite or choose another --out")
            differ = [_WHAT.get(k, k) for k, v in attrs.items() if existing.get(k) != v]
            if differ:
                raise ParameterError(f"output '{out}' holds a volume of another {' and '.join(differ)}; "
                                     f"pass --overwrite or choose another --out")
            return
    array = zarr.create_array(out, shape=(*(int(n) for n in size), int(channels)),
                              chunks=(block, block, block, int(channels)), dtype="float32",
                              zarr_format=2, fill_value=0.0)
    array.attrs.update({**attrs, **({} if record is None else {"npmrf3d_record": record})})
    os.makedirs(out / DONE, exist_ok=True)


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


def write_block(out, index, block: int, values: np.ndarray) -> None:
    """Write block ``index`` (``values`` of its :func:`block_box` shape, with channels) into the
    array ``out``, then its marker."""
    array = zarr.open_array(pathlib.Path(out), mode="r+")
    origin, shape = block_box(index, block, array.shape[:3])
    array[tuple(slice(o, o + s) for o, s in zip(origin, shape))] = np.asarray(values, dtype=np.float32)
    pathlib.Path(out, DONE, ".".join(map(str, index))).touch()
