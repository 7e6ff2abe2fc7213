"""2D -> 3D ground truth: one slice of a real volume in, the real volume as the reference.

Materials scientists hold real 3-D scans (micro-CT, FIB-SEM ...) and ask whether a volume
synthesised from one 2-D section has the right 3-D structure. The ``groundtruth`` study
(:data:`npmrf3d.studies.catalog.GROUNDTRUTH`) takes one slice of a real volume as the exemplar,
synthesises volumes with several methods and compares each with the real volume:

* **two-point correlation along each axis** (:func:`two_point`): for a phase volume (at most
  :data:`MAX_PHASES` distinct values in the exemplar) ``S2(r) = P(x(s) = p and x(s + r e_a) = p)``
  for every phase ``p`` but the first (for a binary volume: the phase of the larger value);
  for a grey volume the normalised autocovariance ``rho(r)``. Lags ``0..max_lag``, the
  non-periodic estimator (mean over the pairs that lie inside the volume), so real scans
  and toroidal syntheses are measured alike. ``two_point_l2`` is the L2 distance of the
  curves to the real volume's, per axis and averaged. For a phase volume S2 is dominated by
  the phase fraction, so a structureless volume with the right fraction scores well (measured
  on real micro-CT slices: it ranked the shuffled control above structured volumes,
  ``docs/segmented.md``, "How the slices are scored"); ``two_point_shape_l2`` is the same distance of the normalised
  autocovariances (``two_point(..., normalised=True)``), which leaves the fraction to
  ``fraction_l1``. (For grey volumes the two are equal.)
* **phase / grey-level fractions** (:func:`fractions`): share of voxels per phase (each voxel
  assigned to the nearest phase value), or a :data:`GREY_BINS`-bin histogram over the real
  volume's range; ``fraction_l1`` is the L1 distance to the real volume's fractions.
* **slice metrics along all three axes**: the study metrics
  (:func:`npmrf3d.studies.execute.evaluate_metrics`) of each view's slices against the real
  volume's middle slice in that view.

Grey values are the mean over channels. Slices follow :mod:`npmrf3d.model.neighbourhood`:
across axis 0 ``volume[i]`` (rows j, columns k), across axis 1 ``volume[:, j]`` (rows i,
columns k), across axis 2 ``volume[:, :, k]`` (rows i, columns j).
"""

from __future__ import annotations

import numpy as np

from ..analysis import metrics
from ..errors import ParameterError
from ..io.files import read_volume
from ..methods.npmrf_coherent import SEGMENTED_MAX_VALUES
from ..model.exemplar import exemplar_slice

__all__ = [
    "GREY_BINS",
    "MAX_PHASES",
    "SLICE_COUNTS",
    "compare",
    "exemplar_slice",
    "exemplar_slices",
    "fit_size",
    "fractions",
    "load_reference",
    "phases_of",
    "pooled_exemplar",
    "reference_slices",
    "two_point",
]

#: An exemplar with at most this many distinct grey values is a phase image (the rule by which
#: ``synth``'s default takes its segmented preset).
MAX_PHASES = SEGMENTED_MAX_VALUES
#: Bins of the grey-level fractions of non-phase volumes.
GREY_BINS = 16
#: Largest lag of the two-point correlations (capped at half the smallest side).
MAX_LAG = 32


def load_reference(path) -> np.ndarray:
    """The real volume as float32 ``(N1, N2, N3, C)`` (``.npy`` or ``.tif``, see
    :func:`npmrf3d.io.read_volume`); one holding NaN or Inf is refused."""
    volume = read_volume(path)
    bad = int(np.count_nonzero(~np.isfinite(volume)))
    if bad:
        raise ParameterError(f"volume file '{path}' contains {bad} NaN or Inf values; clean or "
                             f"mask them first")
    return volume


def reference_slices(volume: np.ndarray) -> dict[str, np.ndarray]:
    """The real volume's middle slice in each view (front, right, top), as exemplar images."""
    return {"front": exemplar_slice(volume, 2), "right": exemplar_slice(volume, 0),
            "top": exemplar_slice(volume, 1)}


#: How many slices of the real volume the ground-truth study's methods see: one for every
#: view, or each view's own middle slice (an anisotropic material needs the three).
SLICE_COUNTS = (1, 3)


def exemplar_slices(volume: np.ndarray, slices: int = 1, axis: int = 0,
                    index: int | None = None) -> dict[str, np.ndarray]:
    """View -> exemplar image: with ``slices=1`` the slice across ``axis`` at ``index`` for
    every view; with ``slices=3`` each view's middle slice (:func:`reference_slices`, the
    plane of the view's axes), so no view is asked to look like a plane it was not cut from.

    >>> v = np.arange(64, dtype=np.float32).reshape(4, 4, 4, 1)
    >>> sorted(exemplar_slices(v, 3)), float(exemplar_slices(v, 1)["top"][0, 0, 0])
    (['front', 'right', 'top'], 32.0)
    """
    if slices not in SLICE_COUNTS:
        raise ParameterError(f"slices must be 1 or 3; got {slices!r}")
    if slices == 3:
        if index is not None:
            raise ParameterError("a slice index picks one slice; the three slices are each "
                                 "view's middle slice (give --slices 1 with --slice-index)")
        return reference_slices(volume)
    one = exemplar_slice(volume, axis, index)
    return {"front": one, "right": one, "top": one}


def pooled_exemplar(per_view: dict[str, np.ndarray]) -> np.ndarray:
    """One ``(N, 1, C)`` image of every distinct exemplar's pixels (one array given for several
    views counts once): what decides the phases and feeds the structureless control."""
    distinct = list({id(a): a for a in per_view.values()}.values())
    if len(distinct) == 1:
        return distinct[0]
    return np.concatenate([a.reshape(-1, 1, a.shape[-1]) for a in distinct])


def fit_size(shape, size: int, levels: int) -> int:
    """``size`` limited to the real volume's smallest side, rounded down to a multiple of
    ``2**(levels - 1)``.

    >>> fit_size((50, 64, 64), 64, 2)
    50
    >>> fit_size((50, 64, 64), 64, 3)
    48
    """
    step = 2 ** (levels - 1)
    side = min(int(size), *(int(n) for n in shape[:3]))
    side -= side % step
    if side < step:
        raise ParameterError(f"the real volume {tuple(shape[:3])} is too small for {levels} levels")
    return side


def _grey(volume: np.ndarray) -> np.ndarray:
    v = np.asarray(volume, dtype=np.float64)
    return v.mean(axis=-1) if v.ndim == 4 else v


def phases_of(exemplar: np.ndarray) -> np.ndarray | None:
    """Sorted distinct grey values of the exemplar if there are at most :data:`MAX_PHASES`
    (a phase image), else None."""
    values = np.unique(_grey(exemplar))
    return values if len(values) <= MAX_PHASES else None


def _standardised(field: np.ndarray) -> np.ndarray:
    x = field - field.mean()
    var = float((x * x).mean())
    return x / np.sqrt(var) if var > 0 else np.zeros_like(x)


def _nearest_phase(grey: np.ndarray, phases: np.ndarray) -> np.ndarray:
    edges = (phases[1:] + phases[:-1]) / 2
    return np.searchsorted(edges, grey)


def two_point(volume: np.ndarray, axis: int, max_lag: int, phases: np.ndarray | None, *,
              normalised: bool = False) -> np.ndarray:
    """Two-point correlation along ``axis`` for lags ``0..max_lag``.

    Returns
    -------
    (P, max_lag + 1) float64 ndarray
        Phase volumes: one row ``S2`` per phase but the first (``S2(0)`` is the phase
        fraction); with ``normalised`` the normalised autocovariance of each phase's indicator
        ``I`` instead, the mean over the pairs of ``(I(s) - phi)(I(s + r) - phi) / (phi -
        phi^2)`` (``phi`` the volume's fraction; 1 at lag 0; ``(S2(r) - phi^2) / (phi - phi^2)``
        but for the pairs cut at the faces), which does not depend on the fraction. Grey
        volumes: one row, the normalised autocovariance (1 at lag 0, 0 for a constant volume),
        with or without ``normalised``.

    Examples
    --------
    >>> v = np.zeros((4, 2, 2)); v[::2] = 1
    >>> two_point(v, 0, 2, np.array([0.0, 1.0]))[0].tolist()
    [0.5, 0.0, 0.5]
    """
    return _curves(_fields(volume, phases, normalised), axis, max_lag)


def _fields(volume: np.ndarray, phases: np.ndarray | None, normalised: bool) -> list[np.ndarray]:
    """The fields :func:`two_point` correlates: the standardised grey volume, or each phase's
    indicator but the first (standardised with ``normalised``)."""
    grey = _grey(volume)
    if grey.ndim != 3:
        raise ParameterError(f"expected a 3-D volume; got shape {np.shape(volume)}")
    if phases is None:
        return [_standardised(grey)]
    labels = _nearest_phase(grey, phases)
    fields = [(labels == p).astype(np.float64) for p in range(1, len(phases))] or \
             [(labels == 0).astype(np.float64)]
    return [_standardised(f) for f in fields] if normalised else fields


def _curves(fields: list[np.ndarray], axis: int, max_lag: int) -> np.ndarray:
    """Mean of ``f(s) f(s + r e_axis)`` over the pairs inside the volume, ``r = 0..max_lag``
    (NaN where ``r`` is not shorter than the axis), one row per field."""
    n = fields[0].shape[axis]
    out = np.zeros((len(fields), max_lag + 1))
    for row, f in enumerate(fields):
        for r in range(max_lag + 1):
            if r >= n:
                out[row, r] = np.nan
                continue
            a = np.take(f, np.arange(0, n - r), axis=axis)
            b = np.take(f, np.arange(r, n), axis=axis)
            out[row, r] = float((a * b).mean())
    return out


def fractions(volume: np.ndarray, phases: np.ndarray | None, value_range: tuple[float, float]) -> np.ndarray:
    """Phase fractions (nearest phase value) or a :data:`GREY_BINS`-bin grey histogram over
    ``value_range`` (values outside are clipped into the end bins), summing to 1."""
    grey = _grey(volume).ravel()
    if phases is not None:
        counts = np.bincount(_nearest_phase(grey, phases), minlength=len(phases))
    else:
        lo, hi = value_range
        hi = hi if hi > lo else lo + 1.0
        counts = np.histogram(np.clip(grey, lo, hi), bins=GREY_BINS, range=(lo, hi))[0]
    return counts / max(counts.sum(), 1)


def compare(volume: np.ndarray, real: np.ndarray, exemplar: np.ndarray, *,
            max_lag: int | None = None) -> dict:
    """All ground-truth measures of ``volume`` against the real volume.

    Parameters
    ----------
    volume, real : (N1, N2, N3, C) ndarrays
        Synthesised and real volume (sizes may differ).
    exemplar : (H, W, C) ndarray
        The slice the volume was made from (decides whether this is a phase image).
    max_lag : int, optional
        Largest lag (default: ``min(32, smallest side // 2)`` over both volumes).

    Returns
    -------
    dict
        ``two_point`` and ``two_point_real`` (axis -> curves), ``two_point_l2`` (axis -> float),
        ``two_point_l2_mean``, ``fractions``, ``fractions_real``, ``fraction_l1``, ``phases``
        (list or None), ``max_lag`` and ``slice_metrics`` (see the module docstring).
    """
    phases = phases_of(exemplar)
    if max_lag is None:
        max_lag = max(1, min(MAX_LAG, min(volume.shape[:3]) // 2, min(real.shape[:3]) // 2))
    grey_real = _grey(real)
    value_range = (float(grey_real.min()), float(grey_real.max()))
    out: dict = {"phases": None if phases is None else phases.tolist(), "max_lag": int(max_lag),
                 "two_point": {}, "two_point_real": {}, "two_point_l2": {}, "two_point_shape_l2": {}}
    # each volume's fields once; grey fields are normalised already, so their shape curves are the curves
    raw = _fields(volume, phases, False), _fields(real, phases, False)
    normalised = raw if phases is None else (_fields(volume, phases, True), _fields(real, phases, True))
    for axis in range(3):
        mine, theirs = (_curves(f, axis, max_lag) for f in raw)
        out["two_point"][f"axis{axis}"] = mine.tolist()
        out["two_point_real"][f"axis{axis}"] = theirs.tolist()
        out["two_point_l2"][f"axis{axis}"] = float(np.sqrt(np.nansum((mine - theirs) ** 2)))
        shape, shape_real = (mine, theirs) if phases is None else (_curves(f, axis, max_lag) for f in normalised)
        out["two_point_shape_l2"][f"axis{axis}"] = float(np.sqrt(np.nansum((shape - shape_real) ** 2)))
    out["two_point_l2_mean"] = float(np.mean(list(out["two_point_l2"].values())))
    out["two_point_shape_l2_mean"] = float(np.mean(list(out["two_point_shape_l2"].values())))
    mine_f = fractions(volume, phases, value_range)
    real_f = fractions(real, phases, value_range)
    out["fractions"] = mine_f.tolist()
    out["fractions_real"] = real_f.tolist()
    out["fraction_l1"] = float(np.abs(mine_f - real_f).sum())
    slices = reference_slices(real)
    out["slice_metrics"] = metrics.evaluate(volume, slices, views=list(slices))
    return out
