"""The exemplar model: loading, channels, label sets, decimation and patches.

An exemplar is a float32 ``(H, W, C)`` array: 8-bit images are scaled to ``[0, 1]``, 16-bit to
``[0, 1]``, float data keeps its units, and so does a label map (an 8- or 16-bit image whose
values are all at most :data:`npmrf3d._validation.LABEL_MAX`: a 0/1 mask stays 0/1). Synthesis
works on the exemplar's *label image*: every pixel replaced by its label (its own value, a
re-quantised grey level, or the nearest palette colour), so each patch centre is a label and the
label histogram identity of docs/model.md, section 2 holds exactly.

Coarse levels (docs/model.md, section 7) use **all** ``2^l x 2^l`` decimation phases of the
exemplar as samples: the level-``l`` exemplar is the set of images ``Y[a::2^l, b::2^l]``, and
patches are taken from each of them (never across phases). Same statistics, ``4^l`` times more
samples.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from scipy.cluster.vq import kmeans2, vq

from .. import _validation as check
from .. import data
from ..errors import InputNote, ParameterError
from ..io.files import read_stack
from .exemplar3d import interpret
from .neighbourhood import window_offsets

__all__ = [
    "BUNDLED_PREFIX",
    "decimation_phases",
    "etr_available",
    "etr_path",
    "exemplar_slice",
    "exemplar_source",
    "extract_patches",
    "load_exemplar",
    "make_labels",
    "named_exemplar",
    "pack_rows",
    "resolve_exemplars",
]

#: Prefix of a bundled exemplar on the command line (``bundled:gravel64``).
BUNDLED_PREFIX = "bundled:"
#: Where Debian's extremetuxracer-data package puts its terrain photographs (GPL-2+).
ETR_DIR = Path("/usr/share/games/etr/terrains")
ETR_PREFIX = "etr:"
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".gif", ".tif", ".tiff", ".npy")


def load_exemplar(source=None, *, name: str = "exemplar", exemplar_kind: str = "auto") -> np.ndarray:
    """Load an exemplar as a float32 ``(H, W, C)`` array.

    Parameters
    ----------
    source : str, Path, ndarray or None
        A PNG/JPEG/TIFF/``.npy`` file, an array ``(H, W)`` or ``(H, W, C)``, or None for the
        bundled default exemplar (:data:`npmrf3d.data.DEFAULT_EXEMPLAR`).
    name : str
        How the exemplar is called in error messages (e.g. ``"exemplar for view top"``).
    exemplar_kind : {"auto", "image", "volume"}
        ``auto``: an array or file recognised as a volume (a ``48 x 48 x 48`` crop, a TIFF stack;
        rules in :mod:`npmrf3d.model.exemplar3d`) is refused, since these methods take a 2D image;
        ``image`` reads any 3-D array as ``(H, W, C)``.

    Returns
    -------
    (H, W, C) float32 ndarray
        uint8 data divided by 255, uint16 by 65535 (but a label map, every value at most
        :data:`npmrf3d._validation.LABEL_MAX`, keeps its values), bool as 0/1, floats
        unchanged; a CMYK JPEG is read as RGB. A masked array with masked values is refused.
        An image file's alpha channel is no data channel: fully opaque, it is dropped (an
        :class:`~npmrf3d.errors.InputNote` says so); with transparent pixels the file is refused.

    Examples
    --------
    >>> load_exemplar(np.zeros((8, 9), dtype=np.uint8)).shape
    (8, 9, 1)
    """
    if source is None:
        source = data.path(data.DEFAULT_EXEMPLAR)
    if isinstance(source, Mapping):
        check.fail(f"{name} is a dict ({', '.join(map(str, source)) or 'empty'}); give one "
                   f"exemplar per view as exemplars={{view: array or path}}, not as the exemplar")
    axes = None
    if isinstance(source, (str, Path)):
        array, info = read_stack(source, what="exemplar file")
        axes = info["axes"]
        name = f"{name} '{source}'"
        if info.get("alpha"):
            array = _without_alpha(array, name)
    else:
        array = np.asarray(check.unmasked(source, name))
    if array.ndim in (3, 4) and array.dtype != object and array.size:
        kind, shaped = interpret(array, axes=axes, kind=exemplar_kind, name=name)
        if kind == "volume":
            dims = "x".join(map(str, shaped.shape[:3]))
            check.fail(f"{name} of shape {array.shape} is a volume ({dims} voxels, "
                       f"{shaped.shape[3]} channel(s)), and this method makes a volume from a 2D "
                       f"image: for a 3D exemplar use the volume-lh method (npmrf3d volume "
                       f"FILE)" + ("" if array.ndim == 4 else ", or read it as an image with "
                                   "exemplar_kind='image' (command line: --exemplar-kind image)"))
        array = shaped
    return check.exemplar_array(array, name=name)


def _without_alpha(array: np.ndarray, name: str) -> np.ndarray:
    """An image file's channels without its alpha (the last channel): a fully opaque alpha is
    dropped with an :class:`~npmrf3d.errors.InputNote`; transparent pixels are refused, since
    the methods would copy the alpha as one more data channel and what a transparent pixel
    shows depends on the background it is flattened onto."""
    alpha = array[..., -1]
    full = True if array.dtype == bool else (
        np.iinfo(array.dtype).max if np.issubdtype(array.dtype, np.integer) else 1.0)
    transparent = int(np.count_nonzero(alpha != full))
    if transparent:
        check.fail(f"{name} has an alpha channel with {transparent} of {alpha.size} pixels not "
                   f"fully opaque, which would be synthesised as one more colour channel; flatten "
                   f"it onto a background first (e.g. ImageMagick: magick IN.png -background "
                   f"white -alpha remove -alpha off OUT.png) or save it without alpha")
    warnings.warn(f"{name}: its alpha channel is fully opaque and was dropped", InputNote,
                  stacklevel=3)
    return array[..., :-1]


# --------------------------------------------------------------------------- exemplar sources
#
# The three ways a run names its exemplar, in one place: a command-line argument (a file or
# ``bundled:NAME``), a study's exemplar name (bundled, ``etr:NAME`` or a file, optionally
# cropped) and a slice of a real volume (the ground-truth study). Each resolves to a float32
# (H, W, C) array; :func:`resolve_exemplars` then gives every constrained view its own.


def exemplar_source(text: str | None) -> tuple[Path | None, str | None]:
    """(file to load, what ``run.json`` records) for an EXEMPLAR or ``--exemplar-VIEW`` argument.

    >>> exemplar_source("bundled:gravel64")[1]
    'bundled:gravel64'
    >>> exemplar_source(None)
    (None, None)

    ``etr:NAME`` is an installed Extreme Tux Racer terrain photograph (:func:`etr_path`).
    """
    if text is None:
        return None, None
    if text.startswith(BUNDLED_PREFIX):
        name = text[len(BUNDLED_PREFIX):]
        return data.path(name), f"{BUNDLED_PREFIX}{name}"
    if text.startswith(ETR_PREFIX):
        return etr_path(text), text
    if not text.strip():
        raise ParameterError("exemplar file name is empty")
    return Path(text), text


def etr_available(folder: Path | None = None) -> list[str]:
    """Names ``etr:<stem>`` of the installed Extreme Tux Racer terrain photographs (may be empty)."""
    folder = ETR_DIR if folder is None else Path(folder)
    if not folder.is_dir():
        return []
    return sorted(f"{ETR_PREFIX}{p.stem}" for p in folder.iterdir()
                  if p.suffix.lower() in IMAGE_SUFFIXES)


def etr_path(name: str) -> Path:
    """The file of the ``etr:NAME`` exemplar (an installed Extreme Tux Racer terrain photograph).

    Raises
    ------
    ParameterError
        The Debian package is not installed, or it has no terrain called ``NAME`` (the message
        lists the installed names).
    """
    stem = name[len(ETR_PREFIX):] if name.startswith(ETR_PREFIX) else name
    if not ETR_DIR.is_dir():
        raise ParameterError(
            f"exemplar {name!r} is an Extreme Tux Racer terrain photograph, read at run time "
            f"from {ETR_DIR}, which does not exist: install Debian's extremetuxracer-data "
            f"package (apt-get install extremetuxracer-data; GPL-2+, so it is not bundled with "
            f"npmrf3d) or choose another exemplar")
    files = [p for p in sorted(ETR_DIR.iterdir())
             if p.stem == stem and p.suffix.lower() in IMAGE_SUFFIXES]
    if not files:
        installed = etr_available()
        raise ParameterError(
            f"unknown {ETR_PREFIX} exemplar {name!r}: no terrain photograph {stem!r} in {ETR_DIR}; "
            + (f"the available ones are {', '.join(installed)}" if installed
               else "the folder holds none (reinstall extremetuxracer-data)"))
    return files[0]


def named_exemplar(name: str, crop: int | None = None) -> np.ndarray:
    """A study exemplar as float32 ``(H, W, C)``; ``crop`` keeps the top-left ``crop x crop``.

    ``name`` is a bundled name, ``etr:NAME`` (an installed Extreme Tux Racer terrain) or an
    image file path.

    Raises
    ------
    ParameterError
        Unknown name, missing file, or an ``etr:`` name without the Debian package installed.

    Examples
    --------
    >>> named_exemplar("gravel64", crop=16).shape
    (16, 16, 1)
    """
    if name in data.available():
        image = load_exemplar(data.path(name))
    elif name.startswith(ETR_PREFIX):
        image = load_exemplar(etr_path(name))
    elif Path(name).suffix.lower() in IMAGE_SUFFIXES:
        image = load_exemplar(name)
    else:
        raise ParameterError(
            f"unknown exemplar {name!r}: use a bundled name ({', '.join(data.available())}), "
            f"'etr:NAME' for an installed Extreme Tux Racer terrain, or an image file path")
    if crop is not None:
        image = np.ascontiguousarray(image[:crop, :crop])
    return image


def exemplar_slice(volume: np.ndarray, axis: int = 0, index: int | None = None) -> np.ndarray:
    """The slice across ``axis`` at ``index`` (default: the middle) of a ``(N1, N2, N3, C)``
    volume as an ``(H, W, C)`` exemplar image.

    >>> v = np.arange(24, dtype=np.float32).reshape(2, 3, 4, 1)
    >>> exemplar_slice(v, 2, 0)[..., 0].tolist()
    [[0.0, 4.0, 8.0], [12.0, 16.0, 20.0]]
    """
    if axis not in (0, 1, 2):
        raise ParameterError(f"slice axis must be 0, 1 or 2; got {axis!r}")
    n = volume.shape[axis]
    index = n // 2 if index is None else int(index)
    if not 0 <= index < n:
        raise ParameterError(f"slice index must be in [0, {n - 1}] for axis {axis}; got {index}")
    return np.ascontiguousarray(np.take(volume, index, axis=axis))


def resolve_exemplars(exemplar, exemplars: Mapping | None, views: tuple[str, ...], *,
                      window: int, levels: int, toroidal: bool = False,
                      exemplar_kind: str = "auto") -> dict[str, np.ndarray]:
    """One float32 (H, W, C) exemplar per constrained view, validated against the window.

    Parameters
    ----------
    exemplar : path, array or None
        Used for every view without an entry in ``exemplars`` (None: the bundled default).
    exemplars : mapping view -> path or array, optional
    views : tuple of str
        The constrained views (validated).
    window, levels : int
        Every exemplar must hold a whole window at the coarsest level.
    toroidal : bool
        Whether exemplar patches may wrap around (relaxes the size requirement).
    exemplar_kind : {"auto", "image"}
        How 3-D arrays are read (:func:`load_exemplar`); ``auto`` refuses volumes.

    Views given the same source share one array (so the label set is built once per source).
    Every source is a 2D image; 3D exemplars are loaded by :func:`npmrf3d.model.exemplar3d.load_volume_exemplar`
    (the ``volume-lh`` method).
    """
    if exemplars is not None and not isinstance(exemplars, Mapping):
        check.fail(f"exemplars must be a dict view -> array or path (e.g. {{'top': 'top.png'}}); "
                   f"got a {type(exemplars).__name__}")
    exemplars = dict(exemplars or {})
    named = [key for key in exemplars if not isinstance(key, str)]
    if named:
        check.fail(f"exemplars must be keyed by view names ({', '.join(views)}); got the key "
                   f"{check.shown(named[0])}")
    unknown = set(exemplars) - set(views)
    if unknown:
        check.fail(f"exemplars given for views that are not constrained: {', '.join(sorted(unknown))}; "
                   f"constrained views are {', '.join(views)}")
    if exemplar is not None and all(v in exemplars for v in views):
        given = f" '{exemplar}'" if isinstance(exemplar, (str, Path)) else ""
        check.fail(f"the exemplar{given} is not used: every constrained view "
                   f"({', '.join(views)}) has its own exemplar; give either the exemplar or "
                   f"one per view")
    out, cache = {}, {}
    for v in views:
        source = exemplars.get(v, exemplar)
        key = id(source) if not isinstance(source, (str, Path)) else str(source)
        if key not in cache:
            cache[key] = load_exemplar(source, name=f"exemplar for view {v}" if v in exemplars else "exemplar",
                                       exemplar_kind=exemplar_kind)
        out[v] = cache[key]
    channels = {a.shape[2] for a in out.values()}
    if len(channels) > 1:
        check.fail(f"all exemplars must have the same number of channels; got {sorted(channels)}")
    for v, a in out.items():
        check.exemplar_fits(a, window=window, levels=levels, toroidal=toroidal,
                            name="exemplar" if len(out) == 1 or v not in exemplars else f"exemplar for view {v}")
    return out


# --------------------------------------------------------------------------- label sets


def make_labels(
    exemplars: list[np.ndarray], *, grey_levels: int | None = None, palette: int | None = None,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Build one label set shared by all exemplars and their label images.

    Parameters
    ----------
    exemplars : list of (H, W, C) float32 ndarrays (same C)
    grey_levels : int, optional
        Re-quantise every channel to this many evenly spaced levels between the pooled min and
        max before taking distinct values (e.g. 32, as in the paper's grey-level study).
    palette : int, optional
        Reduce to at most this many colours by k-means (``scipy.cluster.vq.kmeans2``, seeded
        by ``rng``); each pixel takes its nearest palette colour.
    rng : numpy Generator

    Returns
    -------
    labels : (K, C) float32 ndarray, sorted lexicographically
    label_images : list of (H, W) int32 ndarrays, one per exemplar
    """
    pixels = np.concatenate([e.reshape(-1, e.shape[2]) for e in exemplars]).astype(np.float64)
    if grey_levels is not None:
        lo, hi = pixels.min(), pixels.max()
        span = hi - lo if hi > lo else 1.0
        steps = np.rint((pixels - lo) / span * (grey_levels - 1))
        pixels = lo + steps * span / (grey_levels - 1)
    if palette is not None:
        distinct = np.unique(pixels, axis=0)
        if len(distinct) > palette:
            centres, _ = kmeans2(pixels, palette, minit="++", seed=rng)
            codes, _ = vq(pixels, centres)
            pixels = centres[codes]
    labels, inverse = np.unique(pixels.astype(np.float32), axis=0, return_inverse=True)
    inverse = inverse.reshape(-1).astype(np.int32)
    images, start = [], 0
    for e in exemplars:
        size = e.shape[0] * e.shape[1]
        images.append(inverse[start:start + size].reshape(e.shape[:2]))
        start += size
    return labels.astype(np.float32), images


def decimation_phases(image: np.ndarray, level: int) -> list[np.ndarray]:
    """All ``4**level`` decimation phases ``image[a::2**level, b::2**level]``."""
    f = 2 ** level
    return [image[a::f, b::f] for a in range(f) for b in range(f)]


def extract_patches(
    label_image: np.ndarray, labels: np.ndarray, window: int, *, toroidal: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Neighbour vectors and centre labels of every exemplar patch.

    Parameters
    ----------
    label_image : (H, W) int ndarray
    labels : (K, C) float32 ndarray
    window : int, odd
    toroidal : bool
        If True every pixel is a patch centre (the exemplar wraps around); otherwise only pixels
        whose whole window lies inside: ``n = (H - w + 1)(W - w + 1)``.

    Returns
    -------
    patches : (n, (w*w - 1) * C) float32 ndarray, ``patches[p, m*C + c]`` is channel c of the
        m-th neighbour (order of :func:`npmrf3d.model.neighbourhood.window_offsets`)
    centres : (n,) int32 ndarray, label index of each patch centre
    """
    r = window // 2
    values = labels[label_image]  # (H, W, C)
    h, w = label_image.shape
    if toroidal:
        rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    else:
        rows, cols = np.meshgrid(np.arange(r, h - r), np.arange(r, w - r), indexing="ij")
    rows, cols = rows.ravel(), cols.ravel()
    offsets = window_offsets(window)
    rr = (rows[:, None] + offsets[None, :, 0]) % h
    cc = (cols[:, None] + offsets[None, :, 1]) % w
    patches = values[rr, cc].reshape(len(rows), -1)
    return np.ascontiguousarray(patches, dtype=np.float32), label_image[rows, cols].astype(np.int32)


def pack_rows(exemplars) -> tuple[np.ndarray, np.ndarray]:
    """The pixels of ``exemplars`` (``(H, W, C)`` arrays, one per view) as the rows of one
    float32 array, an array given for several views once, and each view's first row in it.

    >>> a, b = np.zeros((2, 2, 1)), np.ones((1, 3, 1))
    >>> rows, offsets = pack_rows([a, b, a])
    >>> rows.shape, offsets.tolist()
    ((7, 1), [0, 4, 0])
    """
    flat, offsets, seen = [], [], {}
    start = 0
    for ex in exemplars:
        if id(ex) not in seen:
            seen[id(ex)] = start
            flat.append(ex.reshape(-1, ex.shape[2]))
            start += flat[-1].shape[0]
        offsets.append(seen[id(ex)])
    return np.ascontiguousarray(np.concatenate(flat), dtype=np.float32), np.array(offsets, dtype=np.int64)
