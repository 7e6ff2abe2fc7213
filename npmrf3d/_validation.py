"""Every user-facing check and its message, in one module.

Each function checks one parameter and raises :class:`npmrf3d.errors.ParameterError` whose
message names the parameter, the rule and the value received.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Iterable

import numpy as np

from .errors import ParameterError

WINDOW_MIN, WINDOW_MAX = 3, 15
#: An 8- or 16-bit image whose values all lie in ``0..LABEL_MAX`` is a label map (a
#: segmentation, a phase image): its values are kept, not scaled to [0, 1]. As an intensity
#: image it would be all but black (at most 6% of the 8-bit range).
LABEL_MAX = 15


def fail(message: str):
    raise ParameterError(message)


def shown(value, limit: int = 80) -> str:
    """``repr(value)`` on one line (its runs of white space made one space), at most ``limit``
    characters (cut with ``...``): how a message quotes a value received, whatever its type.

    >>> shown("a")
    "'a'"
    >>> shown(np.arange(100).reshape(10, 10))[:30]
    'array([[ 0, 1, 2, 3, 4, 5, 6, '
    """
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def choice(parameter: str, value, valid: Iterable[str]) -> str:
    """Return the canonical spelling of ``value`` among ``valid`` (case-insensitive)."""
    valid = list(valid)
    lookup = {v.lower(): v for v in valid}
    if not isinstance(value, str) or value.lower() not in lookup:
        fail(f"{parameter} must be one of {', '.join(valid)}; got {shown(value)}")
    return lookup[value.lower()]


def boolean(parameter: str, value) -> bool:
    """``True`` or ``False`` (numpy booleans accepted; nothing else)."""
    if not isinstance(value, (bool, np.bool_)):
        fail(f"{parameter} must be True or False; got {shown(value)}")
    return bool(value)


def integer(parameter: str, value, *, low: int | None = None, high: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        fail(f"{parameter} must be an integer; got {shown(value)}")
    value = int(value)
    if (low is not None and value < low) or (high is not None and value > high):
        bounds = f"between {low} and {high}" if high is not None else f">= {low}"
        fail(f"{parameter} must be {bounds}; got {value}")
    return value


def real(parameter: str, value, *, low: float | None = None, high: float | None = None,
         low_open: bool = False, high_open: bool = False) -> float:
    """A finite float in [low, high] (open ends where asked): a Python or numpy integer or
    float; a bool or a string is refused, as :func:`integer` refuses them."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        fail(f"{parameter} must be a number; got {shown(value)}")
    value = float(value)
    bad = not math.isfinite(value)
    if low is not None:
        bad |= value <= low if low_open else value < low
    if high is not None:
        bad |= value >= high if high_open else value > high
    if bad:
        lo = "" if low is None else f"{'(' if low_open else '['}{low}"
        hi = "" if high is None else f"{high}{')' if high_open else ']'}"
        rng = f"in {lo or '(-inf'}, {hi or 'inf)'}"
        fail(f"{parameter} must be a finite number {rng}; got {value}")
    return value


def per_level(name: str, value, levels: int, *, low: int | None = None,
              high: int | None = None) -> tuple[int, ...]:
    """One integer for every level, or one per level (coarsest first), each in [low, high]."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (int(value),) * levels
    try:
        value = tuple(value)
    except TypeError:
        fail(f"{name} must be a positive integer or one per level; got {shown(value)}")
    if len(value) != levels:
        if levels == 1:
            fail(f"{name} must be one integer (one level); got {len(value)}: {shown(value)}")
        fail(f"{name} must be one integer or {levels} integers (one per level, coarsest "
             f"first); got {len(value)}: {shown(value)}")
    return tuple(integer(name, v, low=low, high=high) for v in value)


def window(value) -> int:
    w = integer("window", value)
    if w % 2 == 0 or not WINDOW_MIN <= w <= WINDOW_MAX:
        fail(f"window must be an odd integer between {WINDOW_MIN} and {WINDOW_MAX}; got {w}")
    return w


def exemplar_array(array, *, name: str = "exemplar") -> np.ndarray:
    """Validate and convert an exemplar to float32 ``(H, W, C)``."""
    a = _numbers(array, name)
    if a.ndim not in (2, 3):
        fail(f"{name} must be a 2D image (H, W) or (H, W, C); got an array of shape {a.shape}")
    if a.size == 0:
        fail(f"{name} is empty; got an array of shape {a.shape}")
    if a.ndim == 2:
        a = a[:, :, None]
    return _scaled(a, name)


def volume_array(array, *, name: str = "exemplar") -> np.ndarray:
    """Validate and convert a volume exemplar ``(D, H, W, C)`` to float32, scaled as
    :func:`exemplar_array` scales images."""
    a = _numbers(array, name)
    if a.ndim != 4 or a.size == 0:
        fail(f"{name} must be a non-empty volume (D, H, W, C); got an array of shape {a.shape}")
    return _scaled(a, name)


def unmasked(array, name: str):
    """``array``, or a masked array's data when nothing is masked; a masked array with masked
    values is refused (every value is used, so its mask would be silently ignored)."""
    if isinstance(array, np.ma.MaskedArray):
        masked = int(np.count_nonzero(np.ma.getmaskarray(array)))
        if masked:
            fail(f"{name} is a masked array with {masked} masked values, and every value is "
                 f"used: crop it to a region without them or fill them first")
        return array.data
    return array


def _numbers(array, name: str) -> np.ndarray:
    """``array`` (not masked: :func:`unmasked`) as an ndarray of numbers."""
    a = np.asarray(unmasked(array, name))
    if a.dtype == object or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        fail(f"{name} must hold numbers; got dtype {a.dtype}")
    return a


def value_scale(a: np.ndarray) -> float:
    """What integer data is divided by to become an exemplar's values: 255 for 8-bit and 65535
    for 16-bit images (to [0, 1]), 1 for a label map among them (every value at most
    :data:`LABEL_MAX`) and for every other dtype.

    >>> value_scale(np.array([0, 200], np.uint8)), value_scale(np.array([0, 1], np.uint8))
    (255.0, 1.0)
    """
    full = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(a.dtype)
    if full is None or (a.size and int(a.max()) <= LABEL_MAX):
        return 1.0
    return full


def _scaled(a: np.ndarray, name: str) -> np.ndarray:
    """float32 copy, divided by :func:`value_scale` (uint8 / 255, uint16 / 65535, but a label
    map's values kept; bool 0/1, other numbers unchanged); no NaN/Inf."""
    if np.issubdtype(a.dtype, np.complexfloating):
        fail(f"{name} must be real-valued; got dtype {a.dtype}")
    scale = value_scale(a)
    out = a.astype(np.float32)
    if scale != 1.0:
        out = out / np.float32(scale)
    bad = ~np.isfinite(out)
    if bad.any():
        fail(f"{name} contains {int(bad.sum())} NaN or Inf values; replace them (e.g. by the "
             f"nearest valid pixel) or crop them away first")
    return np.ascontiguousarray(out)


def exemplar_fits(exemplar: np.ndarray, *, window: int, levels: int, toroidal: bool, name: str) -> None:
    """The window must fit in the exemplar at the coarsest level (its decimation phases)."""
    f = 2 ** (levels - 1)
    h, w = exemplar.shape[0] // f, exemplar.shape[1] // f
    need = 1 if toroidal else window
    if min(h, w) < need:
        fail(
            f"{name} of size {exemplar.shape[0]}x{exemplar.shape[1]} is too small for window "
            f"{window} with {levels} levels: the coarsest level sees {h}x{w} pixels; use a larger "
            f"exemplar, a smaller window or fewer levels"
        )


def size(value, *, levels: int, window: int | None = None,
         coarsest: int | None = None) -> tuple[int, int, int]:
    """Volume size: one int (a cube) or three; divisible by ``2**(levels - 1)``; the coarsest
    level holds ``window // 2 + 1`` voxels per side, or ``coarsest`` where the method's rule is
    not a window's (the message then names no window)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        dims = (int(value),) * 3
    else:
        try:
            dims = tuple(int(integer("size", v)) for v in value)
        except TypeError:
            fail(f"size must be an integer or three integers; got {shown(value)}")
        if len(dims) != 3:
            fail(f"size must be an integer or three integers; got {shown(value)}")
    f = 2 ** (levels - 1)
    need = coarsest if coarsest is not None else window // 2 + 1
    for n in dims:
        if n < 1:
            fail(f"size must be positive; got {shown(value)}")
        if n % f:
            fail(f"size {n} is not divisible by 2**(levels-1) = {f} (levels={levels}); "
                 f"choose a multiple of {f} or fewer levels")
        if n // f < need:
            what = f"window {window} with {levels} levels" if coarsest is None else f"{levels} levels"
            fail(f"size {n} is too small for {what}: the coarsest level has {n // f} voxels per "
                 f"side, needs at least {need}; choose a larger size or fewer levels")
    return dims


def views(value, valid: tuple[str, ...]) -> tuple[str, ...]:
    if isinstance(value, str):
        value = [v.strip() for v in value.split(",") if v.strip()]
    if not isinstance(value, Iterable):
        fail(f"views must be view names ({', '.join(valid)}), as a list or a comma-separated "
             f"string; got {shown(value)}")
    value = list(value)
    if not value:
        fail(f"views must name 1 to 3 of {', '.join(valid)}; got an empty list")
    out = tuple(choice("view", v, valid) for v in value)
    if len(set(out)) != len(out):
        fail(f"views must not repeat a view; got {', '.join(out)}")
    return out


def rng(value) -> np.random.Generator:
    if value is None or isinstance(value, (np.random.Generator, int, np.integer)) and not isinstance(value, bool):
        if isinstance(value, (int, np.integer)) and value < 0:
            fail(f"seed must be a non-negative integer; got {value}")
        return np.random.default_rng(value)
    fail(f"rng must be None, an integer seed or a numpy Generator; got {shown(value)}")


def progress(value):
    """None or a callable (called as the run goes)."""
    if value is not None and not callable(value):
        fail(f"progress must be a callable or None; got {shown(value)}")
    return value


def checkpoint(value):
    """None or a file path (a ``str`` or an :class:`os.PathLike`; bytes are refused)."""
    if value is None:
        return None
    if not isinstance(value, (str, os.PathLike)) or isinstance(os.fspath(value), bytes):
        fail(f"checkpoint must be a file path (str or pathlib.Path) or None; got {shown(value)}")
    if not str(value).strip():
        fail("checkpoint must name a file; got an empty string")
    return value


def triple(parameter: str, value, *, low: int | None = None) -> tuple[int, int, int]:
    """One integer (repeated on the three axes) or three integers, each >= ``low``."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (int(value),) * 3
    try:
        items = tuple(value)
    except TypeError:
        fail(f"{parameter} must be an integer or three integers; got {shown(value)}")
    if len(items) != 3:
        fail(f"{parameter} must be an integer or three integers; got {shown(value)}")
    return tuple(integer(parameter, v, low=low) for v in items)
