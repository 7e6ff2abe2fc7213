"""The metrics' inputs: exemplars and volumes validated and scaled to the synthesiser's units,
and a volume's slices in the orientation of a view's exemplar.

Slices are oriented as in :mod:`npmrf3d.model.neighbourhood` so the exemplar's rows and columns
line up with the slice's: front slices are ``volume[:, :, k]`` (rows i, columns j), right slices
``volume[i]`` (rows j, columns k), top slices ``volume[:, j]`` (rows i, columns k). Integer inputs
are scaled as :func:`npmrf3d.model.exemplar.load_exemplar` does (``uint8 / 255``,
``uint16 / 65535``, ``bool`` to 0/1); float inputs are taken as they are. Grey level = mean of
the channels.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, NamedTuple

import numpy as np

from ... import _validation as check
from ...model.neighbourhood import VIEW_AXES, VIEWS


def view_slices(volume: np.ndarray, view: str) -> np.ndarray:
    """All slices of ``volume`` in one view, oriented like the exemplar.

    Parameters
    ----------
    volume : (N1, N2, N3, C) or (N1, N2, N3) ndarray
    view : {"front", "right", "top"}

    Returns
    -------
    (S, rows, cols, C) or (S, rows, cols) view of ``volume`` (no copy).

    Examples
    --------
    >>> import numpy as np
    >>> v = np.arange(24).reshape(2, 3, 4)
    >>> view_slices(v, "right")[1].tolist() == v[1].tolist()
    True
    >>> view_slices(v, "front").shape, view_slices(v, "top").shape
    ((4, 2, 3), (3, 2, 4))
    """
    row_axis, col_axis = VIEW_AXES[view]
    fixed = ({0, 1, 2} - {row_axis, col_axis}).pop()
    return np.moveaxis(volume, (fixed, row_axis, col_axis), (0, 1, 2))


def _scaled(array: np.ndarray) -> np.ndarray:
    """float64 copy, integers scaled like :func:`npmrf3d._validation.exemplar_array`."""
    if array.dtype == np.uint8:
        return array.astype(np.float64) / 255.0
    if array.dtype == np.uint16:
        return array.astype(np.float64) / 65535.0
    return array.astype(np.float64)


def as_exemplar(array: Any, name: str = "exemplar") -> np.ndarray:
    """Validated float64 ``(H, W, C)`` exemplar."""
    a = np.asarray(array)
    if a.dtype != object and (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        if a.ndim in (2, 3) and a.size and not np.iscomplexobj(a):
            a = a if a.ndim == 3 else a[:, :, None]
            out = _scaled(a)
            bad = ~np.isfinite(out)
            if bad.any():
                check.fail(f"{name} contains {int(bad.sum())} NaN or Inf values; "
                           "clean or mask them first")
            return out
    check.exemplar_array(a, name=name)  # raises the precise message
    raise AssertionError("unreachable")  # pragma: no cover


def as_volume(array: Any, name: str = "volume") -> np.ndarray:
    """Validated float64 ``(N1, N2, N3, C)`` volume."""
    a = np.asarray(array)
    if a.ndim not in (3, 4) or a.size == 0:
        check.fail(f"{name} must be a non-empty array of shape (N1, N2, N3) or (N1, N2, N3, C); "
                   f"got shape {a.shape}")
    out = as_values(a, name)
    return out if out.ndim == 4 else out[..., None]


def as_values(array: Any, name: str = "volume") -> np.ndarray:
    """Any non-empty finite real array as float64 (integers scaled as for exemplars)."""
    a = np.asarray(array)
    if a.dtype == object or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool) \
            or np.iscomplexobj(a) or a.size == 0:
        check.fail(f"{name} must be a non-empty array of real numbers; got dtype {a.dtype}, "
                   f"shape {a.shape}")
    out = _scaled(a)
    bad = ~np.isfinite(out)
    if bad.any():
        check.fail(f"{name} contains {int(bad.sum())} NaN or Inf values; clean or mask them first")
    return out


def grey_level(images: np.ndarray) -> np.ndarray:
    """Channel mean of ``(..., C)`` images, float64."""
    return np.asarray(images, dtype=np.float64).mean(axis=-1)


def exemplar_and_volume(exemplar: Any, volume: Any) -> tuple[np.ndarray, np.ndarray]:
    """The validated exemplar ``(H, W, C)`` and volume ``(N1, N2, N3, C)``, float64, with the same
    channels."""
    e, v = as_exemplar(exemplar), as_volume(volume)
    if e.shape[-1] != v.shape[-1]:
        check.fail(f"the exemplar has {e.shape[-1]} channel(s) but the volume has {v.shape[-1]}; "
                   f"compare arrays with the same channels")
    return e, v


def exemplar_and_slices(exemplar: Any, volume: Any, view: str) -> tuple[np.ndarray, np.ndarray]:
    """The validated exemplar ``(H, W, C)`` and the volume's slices ``(S, A, B, C)`` in ``view``
    (float64, the same channels)."""
    e, v = exemplar_and_volume(exemplar, volume)
    view = check.choice("view", view, VIEWS)
    return e, view_slices(v, view)


def exemplars_by_view(exemplars: Any, views: Any) -> dict[str, np.ndarray]:
    """View -> raw exemplar, with validated view names (canonical spelling, VIEWS order)."""
    if isinstance(exemplars, Mapping):
        if not exemplars:
            check.fail("exemplars must name at least one view; got an empty mapping")
        given = {}
        for key, value in exemplars.items():
            view = check.choice("exemplar view", key, VIEWS)
            if view in given:
                check.fail(f"exemplars name the {view} view twice")
            given[view] = value
        default_views: Iterable[str] = [v for v in VIEWS if v in given]
    else:
        given = {view: exemplars for view in VIEWS}
        default_views = VIEWS
    chosen = check.views(default_views if views is None else views, VIEWS)
    missing = [v for v in chosen if v not in given]
    if missing:
        check.fail(f"no exemplar for the {', '.join(missing)} view(s); exemplars are given for "
                   f"{', '.join(given)}")
    return {view: given[view] for view in chosen}


class ViewPair(NamedTuple):
    """One view's exemplar and the volume's slices orthogonal to it, as :func:`~npmrf3d.analysis.metrics.evaluate`
    passes them to every function of :data:`~npmrf3d.analysis.metrics.registry.METRIC_FUNCTIONS`."""

    exemplar: np.ndarray  # (H, W, C) float64
    slices: np.ndarray  # (S, A, B, C) float64
    grey_exemplar: np.ndarray  # (H, W)
    grey_slices: np.ndarray  # (S, A, B)
    joint_bins: int  # bins per channel of the joint colour histogram
