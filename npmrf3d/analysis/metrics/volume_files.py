"""The volume file a metrics run reads (docs/metrics.md): a ``.npy`` or TIFF file, integers
scaled like exemplars, or a Zarr volume folder (``--out VOL.zarr``), refused in one line when its
blocks are not all made or when made blocks lost their chunk files (:func:`zarr_volume`)."""

from __future__ import annotations

import pathlib
import numpy as np
import zarr

from ... import io
from ...errors import ParameterError
from ...io.zarr_blocks import block_indices, blocks_without_chunks, finished_blocks

__all__ = ["read_volume", "stored_dtype", "zarr_volume"]


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


def zarr_volume(path: pathlib.Path) -> np.ndarray:
    """The float32 (N1, N2, N3, C) array of a Zarr volume folder. A volume whose blocks are not
    all made, whose made blocks lost their chunk files (every made block writes one, zeros
    included: :func:`npmrf3d.io.zarr_blocks.write_block`), or a folder that is no Zarr volume, is
    refused in one line."""
    try:
        array = zarr.open_array(path, mode="r")
    except Exception:  # zarr raises several types for a folder that is not an array
        inside = [name for name in ("volume.npy", "volume.tif") if (path / name).is_file()]
        hint = (f"; its volume is '{path / inside[0]}'" if inside else
                "; give a .npy or .tif volume file, or a Zarr volume folder made with --out VOL.zarr")
        raise ParameterError(f"volume '{path}' is a folder and not a Zarr volume{hint}") from None
    size, block = array.attrs.get("npmrf3d_size"), array.attrs.get("npmrf3d_block")
    if size is not None and block is not None:
        indices = block_indices(size, int(block))
        done = len(finished_blocks(path) & set(indices))
        if done < len(indices):
            missing = len(indices) - done
            raise ParameterError(f"Zarr volume '{path}' is not complete ({done} of {len(indices)} "
                                 f"blocks made): {_blocks(missing)} missing; run the command that "
                                 "makes it again to finish it")
        gone = blocks_without_chunks(path)
        if gone:
            raise ParameterError(
                f"Zarr volume '{path}' is missing {len(gone)} of {len(indices)} blocks: they are "
                "marked as made but their chunk files are gone; make it again with --overwrite")
    if array.ndim not in (3, 4):
        raise ParameterError(f"Zarr volume '{path}' must hold an array of shape (N1, N2, N3) or "
                             f"(N1, N2, N3, C); got shape {array.shape}")
    data = np.asarray(array[...])
    volume = io.as_volume(data if data.ndim == 4 else data[..., np.newaxis], name=f"Zarr volume '{path}'")
    return volume


def _blocks(count: int) -> str:
    return f"{count} block{'s' if count != 1 else ''}"


def read_volume(text: str) -> tuple[np.ndarray, str]:
    """The volume as float (N1, N2, N3, C), integers scaled like exemplars, and its stored dtype
    (a Zarr volume folder: :func:`zarr_volume`)."""
    if not text.strip():
        raise ParameterError("volume file name is empty")
    path = pathlib.Path(text)
    if path.is_dir():
        volume = zarr_volume(path)
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
    return volume, str(dtype) if dtype is not None else "unknown"
