"""The volume file a metrics run reads (docs/metrics.md): a ``.npy`` or TIFF file, integers
scaled like exemplars, or a Zarr volume folder (``--out VOL.zarr``), refused in one line when its
blocks are not all made or when made blocks lost their chunk files (:func:`check_chunks`)."""

from __future__ import annotations

import pathlib
from typing import Any

import numpy as np
import zarr

from ... import io
from ...errors import ParameterError
from ...io.zarr_blocks import block_indices, blocks_without_chunks, finished_blocks

__all__ = ["check_chunks", "read_volume", "stored_dtype", "zarr_volume"]


def stored_dtype(path: pathlib.Path) -> np.dtype | None:
    """dtype of the array stored in a .npy or TIFF file (None if it cannot be told)."""
    try:
        if path.suffix.lower() == ".npy":
            return np.load(path, mmap_mode="r", allow_pickle=False).dtype
        import tifffile

        with tifffile.TiffFile(path) as tif:
            return tif.series[0].dtype
    except Exception:  # read_volume reports unreadable files with a clear message
        return None


def zarr_volume(path: pathlib.Path) -> tuple[np.ndarray, dict[str, Any] | None]:
    """The float32 (N1, N2, N3, C) array of a Zarr volume folder, and its made blocks that hold
    no chunk file (``blocks``, ``block``, ``total``; None when there are none), which
    :func:`check_chunks` judges once the exemplars are read. A volume whose blocks are not
    all made, or a folder that is no Zarr volume, is refused in one line."""
    try:
        array = zarr.open_array(path, mode="r")
    except Exception:  # zarr raises several types for a folder that is not an array
        inside = [name for name in ("volume.npy", "volume.tif") if (path / name).is_file()]
        hint = (f"; its volume is '{path / inside[0]}'" if inside else
                "; give a .npy or .tif volume file, or a Zarr volume folder made with --out VOL.zarr")
        raise ParameterError(f"volume '{path}' is a folder and not a Zarr volume{hint}") from None
    size, block = array.attrs.get("npmrf3d_size"), array.attrs.get("npmrf3d_block")
    without = None
    if size is not None and block is not None:
        indices = block_indices(size, int(block))
        done = len(finished_blocks(path) & set(indices))
        if done < len(indices):
            missing = len(indices) - done
            raise ParameterError(f"Zarr volume '{path}' is not complete ({done} of {len(indices)} "
                                 f"blocks made): {_blocks(missing)} missing; run the command that "
                                 "makes it again to finish it")
        gone = blocks_without_chunks(path)
        without = {"blocks": gone, "block": int(block), "total": len(indices)} if gone else None
    if array.ndim not in (3, 4):
        raise ParameterError(f"Zarr volume '{path}' must hold an array of shape (N1, N2, N3) or "
                             f"(N1, N2, N3, C); got shape {array.shape}")
    data = np.asarray(array[...])
    volume = io.as_volume(data if data.ndim == 4 else data[..., np.newaxis], name=f"Zarr volume '{path}'")
    return volume, without


def _blocks(count: int) -> str:
    return f"{count} block{'s' if count != 1 else ''}"


def check_chunks(path: str, volume: np.ndarray, without: dict[str, Any] | None,
                  exemplars: dict[str, np.ndarray]) -> str | None:
    """Refuse a Zarr volume whose made blocks hold no chunk file (read as zeros), unless zeros
    are a value of this volume: Zarr stores no chunk whose values are all 0, so a block of
    zeros is told from a deleted chunk only by zeros found elsewhere, in the rest of the volume
    or in an exemplar. Then the note returned says the blocks were read as zeros."""
    if without is None:
        return None
    block, count = without["block"], len(without["blocks"])
    zero = ~np.any(volume != 0, axis=-1)
    for index in without["blocks"]:
        zero[tuple(slice(i * block, (i + 1) * block) for i in index)] = False
    if zero.any() or any((~np.any(e != 0, axis=-1)).any() for e in exemplars.values()):
        return (f"{_blocks(count)} of Zarr volume '{path}' hold no chunk file and were read as "
                "zeros (Zarr stores no chunk of zeros, and zeros occur elsewhere in the volume or "
                "its exemplar)")
    raise ParameterError(
        f"Zarr volume '{path}' is missing {count} of {without['total']} blocks: they are marked "
        "as made but their chunk files are gone (read as zeros, a value found nowhere else in "
        "the volume or its exemplar); make it again with --overwrite")


def read_volume(text: str) -> tuple[np.ndarray, str, dict[str, Any] | None]:
    """The volume as float (N1, N2, N3, C), integers scaled like exemplars; its stored dtype;
    and a Zarr volume's made blocks without chunk files (:func:`zarr_volume`)."""
    if not text.strip():
        raise ParameterError("volume file name is empty")
    path = pathlib.Path(text)
    without = None
    if path.is_dir():
        volume, without = zarr_volume(path)
        dtype = np.dtype(np.float32)
    else:
        volume = io.read_volume(path)
        dtype = stored_dtype(path)
    bad = int((~np.isfinite(volume)).sum())
    if bad:
        raise ParameterError(f"volume file '{path}' contains {bad} NaN or Inf values; "
                             "clean or mask them first")
    if dtype == np.uint8:
        volume = volume / np.float32(255.0)
    elif dtype == np.uint16:
        volume = volume / np.float32(65535.0)
    return volume, str(dtype) if dtype is not None else "unknown", without
