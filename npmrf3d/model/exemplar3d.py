"""3D exemplars: telling a volume from an image, loading it, checking that it fits.

A *volume exemplar* is a float32 ``(D, H, W, C)`` array (a micro-CT crop, a stack of slices),
scaled as 2D exemplars are (``uint8 / 255``, ``uint16 / 65535`` but a label map's values kept,
``bool`` to 0/1, floats keep their units; :func:`npmrf3d._validation.value_scale`). A 2D method
refuses one, a 3D method refuses an image, each with a message that says how to state which is
meant (``exemplar_kind``, on the command line ``--exemplar-kind``).

How an array is recognised (:func:`interpret`; ``docs/scan_input.md``)
------------------------------------------------------------------
* A TIFF says it: tifffile's axes of the first series decide. ``Z`` (an ImageJ/Fiji stack,
  ``slices`` in its metadata) or ``Q``/``I`` (a plain multi-page TIFF, one page per slice) is the
  depth axis; ``C`` (ImageJ ``channels``) and ``S`` (samples: RGB) are channels; ``Y`` and ``X``
  the plane. An ImageJ file with channels but no slices is an image with channels (as ImageJ
  shows it) unless ``exemplar_kind="volume"`` reads its channels as slices (tifffile writes a
  plain 3-D array with ``imagej=True`` that way). Time series (``T`` > 1) are refused.
* An array without axes (``.npy``, in memory): 2-D is an image; 4-D is a volume with channels
  last; 3-D is an image with channels when the last axis is at most
  :data:`MAX_IMAGE_CHANNELS` (grey+alpha, RGB, RGBA) or a side is shorter than
  :data:`MIN_VOLUME_SIDE` (too small to be a useful volume; only where an image is expected), a volume when its three sides are
  within a factor :data:`CUBE_RATIO` of each other (a ``48 x 48 x 48`` crop), and otherwise
  ambiguous (``64 x 64 x 16``): refused, naming ``exemplar_kind``.
* ``exemplar_kind="image"`` or ``"volume"`` overrides every guess.

Voxel spacing: the 3D methods compare cubic neighbourhoods, so voxels must be cubes. A spacing
given by the caller or recorded in an ImageJ TIFF (``spacing`` and the X/Y resolution) that is
not isotropic (within 1 %) is refused with the resampling to do first.
"""

from __future__ import annotations

import os

import numpy as np

from .. import _validation as check
from ..errors import ParameterError
from ..io.files import read_stack

__all__ = ["CUBE_RATIO", "EXEMPLAR_KINDS", "MAX_IMAGE_CHANNELS", "MIN_VOLUME_SIDE", "check_spacing", "interpret",
           "load_volume_exemplar", "volume_fits"]

#: Values of ``exemplar_kind``: guess (``auto``), or say which is meant.
EXEMPLAR_KINDS = ("auto", "image", "volume")
#: A 3-D array whose last axis is at most this long is an image with channels.
MAX_IMAGE_CHANNELS = 4
#: A 3-D array with a side shorter than this is an image with channels (too small a volume).
MIN_VOLUME_SIDE = 16
#: A 3-D array whose longest side is at most this factor times its shortest is a volume.
CUBE_RATIO = 2.0
#: How to say which is meant, by what the caller's method takes (the kinds its command accepts).
_HOW = {"image": "if it is an image, say so with exemplar_kind='image' (command line: "
                 "--exemplar-kind image)",
        "volume": "if it is a volume, say so with exemplar_kind='volume' (command line: "
                  "--exemplar-kind volume)"}


def _canonical(array: np.ndarray, axes: str, kind: str, name: str) -> tuple[str, np.ndarray]:
    """(kind, array as (H, W, C) or (D, H, W, C)) from a TIFF series and its axes."""
    shape = dict(zip(axes, array.shape))
    for letter, n in shape.items():
        if letter not in "ZQICSYXT" and n > 1:
            check.fail(f"{name} has an axis '{letter}' of length {n} (axes {axes}, shape "
                       f"{array.shape}) that is neither depth, channel nor plane; save it as a "
                       f"(Z, Y, X[, C]) stack")
    if shape.get("T", 1) > 1:
        check.fail(f"{name} is a time series (T={shape['T']}, axes {axes}); give a single volume "
                   f"or image")
    keep = [a for a in axes if a in "ZQICSYX" and (shape[a] > 1 or a in "YX")]
    squeeze = tuple(i for i, a in enumerate(axes) if a not in keep)
    array = array.squeeze(axis=squeeze) if squeeze else array
    depth = [a for a in keep if a in "ZQI"]
    channels = [a for a in keep if a in "CS"]
    if not depth and kind == "volume" and "C" in channels:  # ImageJ channels read as slices
        depth, channels = ["C"], [a for a in channels if a != "C"]
    if kind == "image" and depth:
        channels, depth = depth + channels, []  # the pages become channels, as asked
    order = depth + ["Y", "X"] + channels
    out = np.transpose(array, [keep.index(a) for a in order])
    out = out.reshape(*out.shape[:len(depth) + 2], -1)
    if len(depth) > 1:
        check.fail(f"{name} has more than one depth axis (axes {axes}); save it as one stack")
    return ("volume" if depth else "image"), out


def interpret(array, *, axes: str | None = None, kind: str = "auto", name: str = "exemplar",
              expect: str = "image") -> tuple[str, np.ndarray]:
    """Decide whether ``array`` is an image or a volume (rules in the module docstring).

    Parameters
    ----------
    array : ndarray
        As stored (any dtype).
    axes : str, optional
        tifffile's axes string of the array (a TIFF); None for ``.npy`` files and arrays.
    kind : {"auto", "image", "volume"}
        ``exemplar_kind``: guess, or say which is meant.
    name : str
        How the array is called in messages.
    expect : {"image", "volume"}
        What the caller's method takes. The :data:`MIN_VOLUME_SIDE` rule (a small 3-D array is an
        image with channels) applies only when an image is expected; a 3D method reads a small
        cube as a small volume (and :func:`volume_fits` judges its size).

    Returns
    -------
    kind : {"image", "volume"}
    array : ndarray, ``(H, W, C)`` for an image, ``(D, H, W, C)`` for a volume (dtype unchanged)

    Examples
    --------
    >>> interpret(np.zeros((48, 48, 48)))[0], interpret(np.zeros((64, 64, 3)))[0]
    ('volume', 'image')
    >>> interpret(np.zeros((20, 30, 3)), kind="volume")[1].shape
    (20, 30, 3, 1)
    """
    kind = check.choice("exemplar_kind", kind, EXEMPLAR_KINDS)
    a = np.asarray(array)
    if a.ndim not in (2, 3, 4) or a.size == 0:
        check.fail(f"{name} must be an image (H, W[, C]) or a volume (D, H, W[, C]); got an array "
                   f"of shape {a.shape}")
    if axes is not None and len(axes) == a.ndim:
        return _canonical(a, axes, kind, name)
    if a.ndim == 2:
        if kind == "volume":
            check.fail(f"{name} of shape {a.shape} is a 2D image; a volume needs three axes "
                       f"(D, H, W) or four (D, H, W, C)")
        return "image", a[:, :, None]
    if a.ndim == 4:
        if kind == "image":
            check.fail(f"{name} of shape {a.shape} has four axes, a volume with channels; an image "
                       f"has two (H, W) or three (H, W, C)")
        return "volume", a
    if kind == "auto":
        small = expect == "image" and min(a.shape) < MIN_VOLUME_SIDE
        if a.shape[2] <= MAX_IMAGE_CHANNELS or small:
            kind = "image"
        elif max(a.shape) <= CUBE_RATIO * min(a.shape):
            kind = "volume"
        else:
            check.fail(f"{name} of shape {a.shape} is ambiguous: an image with {a.shape[2]} "
                       f"channels or a volume of {a.shape[0]} slices; {_HOW[expect]}")
    return kind, (a if kind == "image" else a[..., None])


def check_spacing(spacing, *, name: str = "spacing") -> tuple[float, float, float] | None:
    """None, or an isotropic ``(z, y, x)`` voxel size; an anisotropic one is refused.

    >>> check_spacing(0.5)
    (0.5, 0.5, 0.5)
    """
    if spacing is None:
        return None
    values = (spacing,) * 3 if np.ndim(spacing) == 0 else tuple(spacing)
    if len(values) != 3:
        check.fail(f"{name} must be one number or three (z, y, x); got {spacing!r}")
    values = tuple(check.real(name, v, low=0.0, low_open=True) for v in values)
    if max(values) > 1.01 * min(values):
        factors = tuple(round(v / min(values), 3) for v in values)
        check.fail(f"{name} {values} (z, y, x) is anisotropic: the 3D methods compare cubic "
                   f"neighbourhoods, so voxels must be cubes; resample the scan to isotropic "
                   f"voxels first, e.g. scipy.ndimage.zoom(volume, {factors}, order=1)")
    return values


def load_volume_exemplar(source, *, exemplar_kind: str = "auto", spacing=None,
                         name: str = "exemplar") -> np.ndarray:
    """Load a 3D exemplar as a float32 ``(D, H, W, C)`` array.

    Parameters
    ----------
    source : str, Path or ndarray
        A ``.npy`` file or TIFF stack (ImageJ/Fiji hyperstack, multi-page TIFF), or an array
        ``(D, H, W)`` / ``(D, H, W, C)``; grey, colour or multi-channel, 8/16-bit or float.
    exemplar_kind : {"auto", "image", "volume"}
        ``auto`` recognises the volume (module docstring); ``volume`` insists.
    spacing : float or (z, y, x), optional
        Voxel size; must be isotropic (otherwise a :class:`~npmrf3d.errors.ParameterError` with
        the resampling to do). Without it, the spacing an ImageJ TIFF records is checked.
    name : str
        How the exemplar is called in messages.

    Raises
    ------
    ParameterError
        A 2D image, an ambiguous array, NaN/Inf, non-numbers, an unreadable file, anisotropic
        voxels.

    Examples
    --------
    >>> load_volume_exemplar(np.zeros((8, 8, 8), dtype=np.uint8)).shape
    (8, 8, 8, 1)
    """
    axes = file_spacing = None
    if isinstance(source, (str, os.PathLike)):
        array, info = read_stack(source, what="exemplar file")
        axes, file_spacing = info["axes"], info["spacing"]
        name = f"{name} '{source}'"
    else:
        array = np.asarray(check.unmasked(source, name))
    if spacing is not None:
        check_spacing(spacing)
    elif file_spacing is not None:
        check_spacing(file_spacing, name=f"voxel spacing recorded in {name}")
    stored = array
    kind, array = interpret(array, axes=axes, kind=exemplar_kind, name=name, expect="volume")
    if kind != "volume":
        check.fail(f"{name} is a 2D image, and this method needs a volume (D, H, W[, C]): its "
                   f"shape {np.shape(stored)} reads as {_image_words(axes, array)}; give a volume "
                   f"(a multi-page TIFF, an ImageJ stack or an array (D, H, W[, C])), or use a 2D "
                   f"method (npmrf3d synth){_as_volume_hint(stored, axes)}")
    return check.volume_array(array, name=name)


def _image_words(axes: str | None, image: np.ndarray) -> str:
    """What an array read as an image ``(H, W, C)`` is, in words: pixels, channels and why."""
    pixels = f"{image.shape[0]}x{image.shape[1]} pixels"
    channels = image.shape[2]
    if channels == 1:
        return pixels + (f" (TIFF axes {axes}, no depth axis)" if axes is not None else "")
    why = (f"TIFF axes {axes}, no depth axis" if axes is not None else
           f"a 3-D array whose last axis is at most {MAX_IMAGE_CHANNELS} holds channels")
    return f"{pixels} with {channels} channels ({why})"


def _as_volume_hint(stored: np.ndarray, axes: str | None) -> str:
    """How to read ``stored`` as a volume instead, if ``exemplar_kind="volume"`` would."""
    try:
        kind, _ = interpret(stored, axes=axes, kind="volume", expect="volume")
    except ParameterError:
        return ""
    if kind != "volume":
        return ""
    return (f"; to read it as a volume of {np.shape(stored)[0]} slices, say so with "
            f"exemplar_kind='volume' (command line: --exemplar-kind volume)")


def volume_fits(volume: np.ndarray, *, window: int, name: str = "exemplar") -> None:
    """Every side of ``volume`` must be at least twice the ``window``: the window's border of
    ``window // 2`` voxels is not a valid centre (the vector-field deformation method discards
    it), and what is left must still hold more than one window.

    >>> volume_fits(np.zeros((8, 12, 12, 1)), window=5)
    Traceback (most recent call last):
    ...
    npmrf3d.errors.ParameterError: exemplar of size 8x12x12 is too small for window 5: every side needs at least 10 voxels; use a larger exemplar or a smaller window
    """
    need = 2 * window
    if min(volume.shape[:3]) < need:
        dims = "x".join(map(str, volume.shape[:3]))
        check.fail(f"{name} of size {dims} is too small for window {window}: every side needs at "
                   f"least {need} voxels; use a larger exemplar or a smaller window")
