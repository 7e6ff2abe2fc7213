"""Reading and writing exemplars, volumes and JSON: the bottom of the file layer.

(Why over 400 lines: small readers and writers, each with the checks and messages of
one validation and a numpydoc docstring; they share the atomic-write and error helpers.)

Public through :mod:`npmrf3d.io` (which adds the run folders of :mod:`npmrf3d.io.runs`); the
model layer and :mod:`npmrf3d.plotting` import this module directly, so that reading an
exemplar never imports matplotlib and no arrow points back up.

Conventions
-----------
* An exemplar is a float32 array of shape ``(H, W, C)``; :func:`read_array` returns the
  stored array unchanged (any dtype, 2-D or 3-D) and leaves the conversion to the caller.
* A volume is a float32 array of shape ``(N1, N2, N3, C)`` indexed ``volume[i, j, k, c]``.
  On disk it is either a ``.npy`` file (the array itself) or an ImageJ hyperstack TIFF
  with axes ``ZCYX`` (``Z`` = i, ``C`` = c, ``Y`` = j, ``X`` = k), see
  :func:`write_volume_tiff`.
* Every file is written atomically (temporary name in the same folder, then
  :func:`os.replace`), and a run folder is staged completely before it is moved into
  place (:func:`npmrf3d.io.runs.write_run`), so an interrupted or failed write never leaves partial output.
"""

from __future__ import annotations

import dataclasses
import errno
import importlib.metadata
import json
import math
import os
import pathlib
import platform
import re
import secrets
import shutil
import stat
import sys
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from .. import data
from ..errors import ParameterError

__all__ = [
    "IMAGE_EXTENSIONS",
    "TIFF_EXTENSIONS",
    "as_volume",
    "atomic_write",
    "check_regular_target",
    "package_versions",
    "read_array",
    "read_stack",
    "read_volume",
    "to_jsonable",
    "write_json",
    "write_npy",
    "write_volume_tiff",
]

#: Extensions read with imageio's Pillow plugin.
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".gif")
#: Extensions read and written with tifffile.
TIFF_EXTENSIONS = (".tif", ".tiff")

_READABLE_EXTENSIONS = (*IMAGE_EXTENSIONS, *TIFF_EXTENSIONS, ".npy")
_VERSIONED_PACKAGES = (
    "numpy",
    "numba",
    "scipy",
    "matplotlib",
    "tifffile",
    "imageio",
    "tqdm",
    "npmrf3d",
)


# --------------------------------------------------------------------------- reading


def _reason(exc: BaseException) -> str:
    """One-line description of ``exc`` (its first line, or its type name when empty)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def broken_link(path: str | os.PathLike[str]) -> str | None:
    """Why ``path`` is a symbolic link that leads nowhere (its target missing, or a loop of
    links), as words to follow the path's name in a message; None when it is not one.

    >>> broken_link("/") is None
    True
    """
    path = pathlib.Path(path)
    if not path.is_symlink() or path.exists():
        return None
    try:
        path.resolve(strict=True)
    except RuntimeError:  # a loop of links (Python before 3.13)
        return "is a symbolic link in a loop of links"
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "is a symbolic link in a loop of links"
    return f"is a symbolic link to '{os.readlink(path)}', which does not exist"


def _existing_file(path: str | os.PathLike[str], what: str) -> pathlib.Path:
    """Return ``path`` as a Path, or raise ParameterError if it is not an existing file."""
    path = pathlib.Path(path)
    link = broken_link(path)
    if link is not None:
        raise ParameterError(f"{what} '{path}' {link}")
    if not path.exists():
        hint = (f" (the bundled exemplar of that name is 'bundled:{path}')"
                if str(path) in data.available() else "")
        raise ParameterError(f"{what} '{path}' does not exist{hint}")
    if not path.is_file():
        raise ParameterError(f"{what} '{path}' is not a file (it is a directory or special file)")
    return path


def _suffix(path: pathlib.Path, allowed: tuple[str, ...], what: str) -> str:
    """Lower-case extension of ``path``; ParameterError unless it is one of ``allowed``."""
    suffix = path.suffix.lower()
    if suffix not in allowed:
        found = f"unsupported extension '{path.suffix}'" if path.suffix else "no extension"
        raise ParameterError(
            f"{what} '{path}' has {found}; expected one of {', '.join(allowed)}"
        )
    return suffix


def _load_npy(path: pathlib.Path) -> np.ndarray:
    with open(path, "rb") as handle:
        return np.load(handle, allow_pickle=False)


def read_array(path: str | os.PathLike[str], *, what: str = "input file") -> np.ndarray:
    """Load an image or array file and return it as stored.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.png``, ``.jpg``/``.jpeg``, ``.bmp`` or ``.gif`` image (read with imageio's
        Pillow plugin; only the first frame of an animated GIF; a CMYK or YCbCr image in RGB,
        as Pillow's ``convert("RGB")`` gives it), a ``.tif``/``.tiff`` file
        (tifffile, first series) or a ``.npy`` array (``allow_pickle=False``).
    what : str, optional
        How the file is named in error messages, e.g. ``"exemplar file"``.

    Returns
    -------
    numpy.ndarray
        The stored array with its stored dtype, e.g. ``(H, W)`` for a grey PNG,
        ``(H, W, 3)`` for an RGB PNG.

    Raises
    ------
    ParameterError
        If the file is missing, is a directory, has an unknown extension or cannot be decoded.
    """
    path = _existing_file(path, what)
    suffix = _suffix(path, _READABLE_EXTENSIONS, what)
    try:
        if suffix in IMAGE_EXTENSIONS:
            return _read_image(path)
        if suffix in TIFF_EXTENSIONS:
            import tifffile

            return tifffile.imread(path)
        return _load_npy(path)
    except Exception as exc:  # any decoder failure is a user-facing unreadable file
        cause = exc.__cause__ if exc.__cause__ is not None else exc
        raise ParameterError(f"{what} '{path}' cannot be read: {_reason(cause)}") from exc


#: Pillow modes read as RGB, converted as Pillow's ``convert("RGB")`` converts them (a CMYK
#: JPEG, as image viewers show it), not kept as their raw channels.
_READ_AS_RGB = ("CMYK", "YCbCr", "RGBX")


def _pillow_mode(path: pathlib.Path) -> str:
    """The Pillow mode of an image file (``L``, ``RGB``, ``CMYK``, ...; the header only)."""
    from PIL import Image

    with Image.open(path) as image:
        return image.mode


def _read_image(path: pathlib.Path) -> np.ndarray:
    """The first frame of an image file, by imageio's Pillow plugin, in RGB for the modes of
    :data:`_READ_AS_RGB`."""
    import imageio.v3 as iio

    mode = "RGB" if _pillow_mode(path) in _READ_AS_RGB else None
    return iio.imread(path, plugin="pillow", index=0, mode=mode)


def read_stack(path: str | os.PathLike[str], *, what: str = "input file") -> tuple[np.ndarray, dict]:
    """Like :func:`read_array`, plus what the file says about its axes.

    Returns
    -------
    array : numpy.ndarray
        As stored (a TIFF's first series).
    info : dict
        ``axes``: tifffile's axes string of a TIFF's first series (``"ZYX"``, ``"QYX"`` for a plain
        multi-page stack, ``"YXS"`` for an RGB page, ``"ZCYX"`` for an ImageJ hyperstack, ...), None
        for other files; ``spacing``: ``(z, y, x)`` voxel size from ImageJ metadata (``spacing``
        and the X/Y resolution tags) when the file records it, else None; ``alpha`` (images read
        by Pillow only): whether the last channel is the image's alpha.
    """
    path = _existing_file(path, what)
    suffix = _suffix(path, _READABLE_EXTENSIONS, what)
    if suffix not in TIFF_EXTENSIONS:
        array = read_array(path, what=what)
        alpha = suffix in IMAGE_EXTENSIONS and _has_alpha(path, array)
        return array, {"axes": None, "spacing": None, "alpha": alpha}
    try:
        import tifffile

        with tifffile.TiffFile(path) as tif:
            series = tif.series[0]
            array, axes = series.asarray(), series.axes
            spacing = _imagej_spacing(tif)
    except Exception as exc:  # any decoder failure is a user-facing unreadable file
        raise ParameterError(f"{what} '{path}' cannot be read: {_reason(exc)}") from exc
    return array, {"axes": axes, "spacing": spacing}


def _has_alpha(path: pathlib.Path, array: np.ndarray) -> bool:
    """Whether the last channel of an image read by Pillow is its alpha (grey + alpha, RGBA, or a
    palette or grey image with a transparent colour, which imageio reads as RGBA)."""
    if array.ndim != 3 or array.shape[2] not in (2, 4):
        return False
    try:
        return _pillow_mode(path) not in _READ_AS_RGB
    except Exception:  # read once already; without its mode, channels are taken as they are
        return False


def _imagej_spacing(tif) -> tuple[float, float, float] | None:
    """(z, y, x) voxel size of an ImageJ TIFF that records a z spacing, else None."""
    meta = tif.imagej_metadata if tif.is_imagej else None
    if not meta or "spacing" not in meta:
        return None
    tags = tif.pages[0].tags

    def size(tag):  # pixels per unit -> unit per pixel
        if tag not in tags:
            return 1.0
        num, den = tags[tag].value
        return float(den) / float(num) if num else 1.0

    return (float(meta["spacing"]), size("YResolution"), size("XResolution"))


def _tiff_volume(path: pathlib.Path) -> np.ndarray:
    """Read a TIFF volume as ``(N1, N2, N3, C)`` (not yet float32)."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        series = tif.series[0]
        if not tif.is_imagej:
            return series.asarray()
        # ImageJ hyperstack: expand to the full TZCYXS order and fold it into ZYXC.
        data = series.asarray().reshape(series.get_shape(False))
        axes = series.get_axes(False)
    if axes != "TZCYXS":  # pragma: no cover - tifffile always reports this order for ImageJ
        raise ParameterError(f"volume file '{path}' has unexpected ImageJ axes '{axes}'")
    n_t, n_z = data.shape[:2]
    if n_t > 1 and n_z > 1:
        raise ParameterError(
            f"volume file '{path}' is a time series of volumes (T={n_t}, Z={n_z}); "
            "expected a single volume"
        )
    data = data.reshape((n_t * n_z, *data.shape[2:]))  # a plain stack saved as frames is Z
    z, c, y, x, s = data.shape
    return data.transpose(0, 2, 3, 1, 4).reshape(z, y, x, c * s)


def read_volume(path: str | os.PathLike[str]) -> np.ndarray:
    """Load a volume written by :func:`write_volume_tiff` or :func:`numpy.save`.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.npy`` file holding ``(N1, N2, N3)`` or ``(N1, N2, N3, C)``, an ImageJ
        hyperstack TIFF (axes ``ZCYX`` or ``ZYX``), or a plain TIFF holding ``ZYX`` or
        ``ZYXC`` data.

    Returns
    -------
    numpy.ndarray
        float32 array of shape ``(N1, N2, N3, C)``.

    Raises
    ------
    ParameterError
        If the file cannot be read or does not hold a 3-D (optionally multi-channel) volume.
    """
    what = "volume file"
    path = _existing_file(path, what)
    suffix = _suffix(path, (*TIFF_EXTENSIONS, ".npy"), what)
    try:
        data = _tiff_volume(path) if suffix in TIFF_EXTENSIONS else _load_npy(path)
    except ParameterError:
        raise
    except Exception as exc:
        raise ParameterError(f"{what} '{path}' cannot be read: {_reason(exc)}") from exc
    if data.ndim not in (3, 4):
        raise ParameterError(
            f"{what} '{path}' must hold an array of shape (N1, N2, N3) or (N1, N2, N3, C); "
            f"got shape {data.shape}"
        )
    return as_volume(data if data.ndim == 4 else data[..., np.newaxis], name=f"{what} '{path}'")


def as_volume(volume: Any, *, name: str = "volume") -> np.ndarray:
    """Check that ``volume`` is a real-valued 4-D array and return it as float32.

    Parameters
    ----------
    volume : array_like
        Array of shape ``(N1, N2, N3, C)``.
    name : str, optional
        How the array is named in error messages.

    Returns
    -------
    numpy.ndarray
        float32 array of shape ``(N1, N2, N3, C)`` (no copy if it already is one).

    Raises
    ------
    ParameterError
        If the array is not 4-D, is empty or is not real-valued numeric.
    """
    array = np.asarray(volume)
    if array.ndim != 4 or array.size == 0:
        raise ParameterError(
            f"{name} must be a non-empty array of shape (N1, N2, N3, C); got shape {array.shape}"
        )
    if not (np.issubdtype(array.dtype, np.number) or array.dtype == bool) or np.iscomplexobj(
        array
    ):
        raise ParameterError(f"{name} must hold real numbers; got dtype {array.dtype}")
    return array.astype(np.float32, copy=False)


# --------------------------------------------------------------------------- writing


def atomic_write(
    path: str | os.PathLike[str], writer: Callable[[pathlib.Path], object]
) -> pathlib.Path:
    """Write a file atomically through a temporary name in the same folder.

    Parameters
    ----------
    path : str or os.PathLike
        Final file name. Its folder must exist. A symbolic link is written through (the file it
        points to is replaced, the link stays); a path that is not a regular file (a folder, a
        device, a FIFO, a socket) is refused, never replaced.
    writer : callable
        ``writer(tmp_path)`` must create the file ``tmp_path``. The temporary name is
        ``.<stem>.tmp-<random><suffix>`` so writers that look at the extension still work.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ParameterError
        If the folder of ``path`` does not exist, or ``path`` is not a regular file.
    OSError
        A failed write (a full disk), naming ``path``; the temporary file is removed first.
    Exception
        Whatever else ``writer`` raises; the temporary file is removed first.
    """
    path = pathlib.Path(path)
    check_regular_target(path)
    target = pathlib.Path(os.path.realpath(path)) if path.is_symlink() else path
    if not target.parent.is_dir():
        raise ParameterError(f"output folder '{target.parent}' for '{path.name}' does not exist")
    tmp = target.with_name(f".{target.stem}.tmp-{secrets.token_hex(4)}{target.suffix}")
    try:
        writer(tmp)
        os.replace(tmp, target)
    except OSError as exc:
        failure = _write_failure(exc, path, tmp)
        tmp.unlink(missing_ok=True)
        if failure is exc:
            raise
        raise failure from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


_FILE_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"),
               (stat.S_ISBLK, "a block device"), (stat.S_ISFIFO, "a FIFO"),
               (stat.S_ISSOCK, "a socket"))


def check_regular_target(path: str | os.PathLike[str], what: str = "output file") -> None:
    """Refuse to write ``path`` (by a rename over it) unless it is missing or a regular file
    (through a symbolic link: what the link points to). ParameterError, one line."""
    try:
        mode = os.stat(path).st_mode
    except OSError:  # missing (or a dangling link): a new file
        return
    if stat.S_ISREG(mode):
        return
    kind = next((name for test, name in _FILE_KINDS if test(mode)), "not a regular file")
    raise ParameterError(f"{what} '{path}' is {kind}, not a regular file, and is never "
                         f"replaced; choose another name")


_SHORT_WRITE = re.compile(r"(\d+) requested and (\d+) written")


def _write_failure(exc: OSError, path: pathlib.Path, tmp: pathlib.Path) -> OSError:
    """``exc`` as an error naming ``path`` (not its temporary name). A short write, which numpy
    and tifffile report as ``N requested and M written`` with no error number, is a full disk
    (or quota) when the disk has no room left for the rest."""
    if exc.filename not in (None, str(tmp), tmp):
        return exc
    code, reason = exc.errno, exc.strerror or _reason(exc)
    short = _SHORT_WRITE.search(str(exc)) if code is None else None
    if short is not None:
        missing = int(short.group(1)) - int(short.group(2))
        try:
            full = shutil.disk_usage(tmp.parent).free < missing
        except OSError:
            full = False
        if full:
            code, reason = errno.ENOSPC, os.strerror(errno.ENOSPC)
    return OSError(code, reason, str(path))


#: ImageJ colour tables (red, green, blue) of a three-channel volume's composite display.
_RGB_LUTS = tuple(np.stack([np.arange(256, dtype=np.uint8) * (row == c) for row in range(3)])
                  for c in range(3))


def write_volume_tiff(path: str | os.PathLike[str], volume: np.ndarray) -> pathlib.Path:
    """Write a volume as an ImageJ hyperstack TIFF that opens in Fiji and napari.

    Parameters
    ----------
    path : str or os.PathLike
        Output ``.tif`` file (written atomically).
    volume : numpy.ndarray
        Array of shape ``(N1, N2, N3, C)``; stored as float32 with ImageJ axes ``ZCYX``:
        axis i becomes Z (slices), the C channels become ImageJ channels, j is Y and k is X.
        Three channels are a colour volume: a composite hyperstack (ImageJ ``mode``
        ``composite``) with red, green and blue colour tables and one display range for all
        three (0 to 1 for values within it, else the volume's range), so that Fiji shows colour;
        the values are stored unchanged (:func:`read_volume` gives them back).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    import tifffile

    volume = as_volume(volume)
    zcyx = np.ascontiguousarray(volume.transpose(0, 3, 1, 2))
    metadata: dict[str, Any] = {"axes": "ZCYX"}
    if volume.shape[3] == 3:
        lo, hi = float(volume.min()), float(volume.max())
        if (0.0 <= lo and hi <= 1.0) or not (math.isfinite(lo) and math.isfinite(hi)):
            lo, hi = 0.0, 1.0  # a photograph's range (NaN or Inf: no range to read)
        metadata.update(mode="composite", LUTs=list(_RGB_LUTS),
                        Ranges=(lo, hi if hi > lo else lo + 1.0) * 3)
    return atomic_write(
        path,
        lambda tmp: tifffile.imwrite(tmp, zcyx, imagej=True, metadata=metadata),
    )


def write_npy(path: str | os.PathLike[str], array: np.ndarray) -> pathlib.Path:
    """Write ``array`` as a ``.npy`` file (no pickled objects), atomically; a full disk is an
    OSError naming ``path`` (:func:`atomic_write`)."""
    return atomic_write(path, lambda tmp: np.save(tmp, array, allow_pickle=False))


def to_jsonable(obj: Any) -> Any:
    """Convert ``obj`` recursively to plain JSON types.

    Dataclass instances become dicts (:func:`dataclasses.asdict`), tuples and sets become
    lists, numpy scalars and arrays become Python scalars and (nested) lists, paths become
    strings, and dict keys that are numpy scalars become Python scalars.

    Raises
    ------
    TypeError
        If an object of another type is met.
    """
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return to_jsonable(dataclasses.asdict(obj))
    if isinstance(obj, Mapping):
        return {to_jsonable(key): to_jsonable(value) for key, value in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(item) for item in obj]
    if isinstance(obj, (set, frozenset)):
        return sorted(to_jsonable(item) for item in obj)
    if isinstance(obj, (np.generic, np.ndarray)):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise TypeError(f"cannot convert a value of type {type(obj).__name__} to JSON: {obj!r}")


def json_text(obj: Any) -> str:
    return json.dumps(to_jsonable(obj), indent=2) + "\n"


def write_json(path: str | os.PathLike[str], obj: Any) -> pathlib.Path:
    """Write ``obj`` as indented JSON, atomically (see :func:`to_jsonable`).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    TypeError
        If ``obj`` holds something that cannot be converted; nothing is written then.
    """
    text = json_text(obj)
    return atomic_write(path, lambda tmp: tmp.write_text(text, encoding="utf-8"))


# --------------------------------------------------------------------------- provenance


def _version(distribution: str) -> str:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        if distribution == "npmrf3d":  # running from a source checkout (already imported)
            return getattr(sys.modules.get("npmrf3d"), "__version__", "not installed")
        return "not installed"


def package_versions() -> dict[str, Any]:
    """Versions of Python and the libraries a run depends on, plus the machine.

    Returns
    -------
    dict
        Keys ``python``, ``numpy``, ``numba``, ``scipy``, ``matplotlib``, ``tifffile``,
        ``imageio``, ``tqdm``, ``npmrf3d`` (version strings, ``"not installed"`` when
        missing), ``platform`` (str) and ``cpu_count`` (int or None).
    """
    versions: dict[str, Any] = {"python": platform.python_version()}
    versions.update({name: _version(name) for name in _VERSIONED_PACKAGES})
    versions["platform"] = platform.platform()
    versions["cpu_count"] = os.cpu_count()
    return versions
