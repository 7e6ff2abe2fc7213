"""Input-versus-output measures (SPEC.md section 7), per constrained view.

Why one module of ~880 lines: each public metric here is a few lines on top of shared helpers
(value ranges, histograms, slices in view orientation, settings) that ``docs/metrics.md``
documents as one unit and ``tests/test_metrics.py`` checks against independent
implementations; :data:`METRIC_FUNCTIONS` is the registry :func:`evaluate` loops over. Split
it (e.g. ``metrics/histograms.py``, ``metrics/texture.py``) when a new family of metrics comes.

The exemplar of a view is compared with *all* the volume's slices orthogonal to that view
(pooled). Slices are oriented as in :mod:`npmrf3d.model.neighbourhood` so the exemplar's rows and
columns line up with the slice's: front slices are ``volume[:, :, k]`` (rows i, columns j),
right slices ``volume[i]`` (rows j, columns k), top slices ``volume[:, j]`` (rows i, columns k).

One entry point, :func:`evaluate`, returns the four numbers of :data:`METRICS` per view and
their mean over the views; every setting (bins, epsilon, lags, scales, patch size, seed) is in
:class:`MetricSettings` and is returned with the numbers. ``docs/metrics.md`` gives the
definitions. Lower is better for every metric; 0 means "indistinguishable by this measure".

Units: images are compared in the units the synthesiser uses, so integer inputs are scaled as
:func:`npmrf3d.model.exemplar.load_exemplar` does (``uint8 / 255``, ``uint16 / 65535``, ``bool`` to
0/1); float inputs are taken as they are. Grey level = mean of the channels.

Examples
--------
>>> import numpy as np
>>> from npmrf3d import metrics
>>> exemplar = np.random.default_rng(0).random((16, 16))
>>> stacked = np.stack([exemplar] * 8)           # every right slice volume[i] is the exemplar
>>> result = metrics.evaluate(stacked, {"right": exemplar})
>>> sorted(result["per_view"]) == ["right"] and sorted(result["mean"]) == sorted(metrics.METRICS)
True
>>> [round(result["mean"][name], 6) for name in metrics.METRICS[:3]]
[0.0, 0.0, 0.0]
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any, NamedTuple

import numpy as np
from scipy import ndimage

from .. import _validation as check
from ..model.neighbourhood import VIEW_AXES, VIEWS

__all__ = [
    "DEFAULT_SETTINGS",
    "METRICS",
    "MIN_SIDE",
    "MetricSettings",
    "SHAPE_REFERENCES",
    "autocorrelation",
    "autocorrelation_error",
    "channel_histogram_kl",
    "effective_max_lag",
    "evaluate",
    "histogram_kl",
    "joint_histogram_kl",
    "kl_divergence",
    "largest_value_share",
    "orientation_field",
    "orientation_histogram",
    "orientation_kl",
    "patch_sample",
    "multiscale_sliced_wasserstein",
    "sliced_wasserstein",
    "structure_tensor",
    "two_point_correlation",
    "two_point_shape_error",
    "view_histograms",
    "view_slices",
    "wasserstein_1d",
]

#: The metric names, in the order of the report's columns.
METRICS: tuple[str, ...] = ("histogram_kl", "autocorrelation_l2", "orientation_kl",
                            "sliced_wasserstein")
#: Smallest side (pixels or voxels) of an exemplar or a volume that :func:`evaluate` accepts.
MIN_SIDE = 4
#: Largest number of cells of a joint colour histogram; more channels get fewer bins each.
MAX_JOINT_CELLS = 2**16


@dataclasses.dataclass(frozen=True)
class MetricSettings:
    """Every number that defines the metrics (``docs/metrics.md``).

    Attributes
    ----------
    bins : int
        Bins of the grey-level histogram and of each per-channel histogram, evenly spaced over
        the exemplar's range of that channel (volume values outside it count in the end bins).
    joint_bins : int
        Bins per channel of the joint colour histogram (C > 1); reduced to
        ``floor(MAX_JOINT_CELLS ** (1 / C))`` when ``joint_bins ** C`` would exceed
        ``MAX_JOINT_CELLS`` (C > 5).
    eps : float
        Added to every bin *probability* of both histograms before renormalising, so empty
        bins stay finite: ``p = (h / sum(h) + eps) / (1 + bins * eps)``.
    max_lag : int
        Largest autocorrelation lag along each axis (lags ``-L..L``); reduced per view to
        ``min(max_lag, side // 2)`` over the exemplar's and the slices' sides.
    gradient_sigma : float
        Gaussian pre-smoothing (pixels) before the 3x3 Sobel gradient of the structure tensor
        (0 = none).
    integration_sigma : float
        Gaussian integration scale (pixels) of the structure tensor's entries.
    orientation_bins : int
        Bins of the orientation histogram over ``[0, pi)``.
    coherence_weighting : bool
        Weight each pixel's orientation by its coherence ``(l1 - l2) / (l1 + l2)`` (0 in flat
        regions, 1 along a perfect edge); False = every pixel counts once.
    patch : int
        Side of the square patches compared by the sliced Wasserstein distance; reduced to the
        smallest side of the exemplar and the slices when larger.
    centre_patches : bool
        Subtract each patch's own mean (per channel) before projecting, so the distance measures
        local structure rather than the grey-level histogram (which ``histogram_kl`` covers).
        With raw patches, random projections of many pixels average independent values out and
        the distance becomes mostly a histogram distance (``docs/metrics.md``).
    projections : int
        Number of random unit directions of the sliced Wasserstein distance.
    max_patches : int
        At most this many patches per side of the comparison (a seeded random subset).
    seed : int
        Seed of the projections and of the patch subsets (fixed, so results are repeatable).
    """

    bins: int = 32
    joint_bins: int = 8
    eps: float = 1e-10
    max_lag: int = 32
    gradient_sigma: float = 1.0
    integration_sigma: float = 2.0
    orientation_bins: int = 18
    coherence_weighting: bool = True
    patch: int = 5
    centre_patches: bool = True
    projections: int = 64
    max_patches: int = 20_000
    seed: int = 0

    def __post_init__(self) -> None:
        check.integer("bins", self.bins, low=2)
        check.integer("joint_bins", self.joint_bins, low=2)
        check.real("eps", self.eps, low=0.0, high=1.0)
        check.integer("max_lag", self.max_lag, low=1)
        check.real("gradient_sigma", self.gradient_sigma, low=0.0)
        check.real("integration_sigma", self.integration_sigma, low=0.0, low_open=True)
        check.integer("orientation_bins", self.orientation_bins, low=2)
        for name in ("coherence_weighting", "centre_patches"):
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                check.fail(f"{name} must be True or False; got {value!r}")
        check.integer("patch", self.patch, low=1)
        check.integer("projections", self.projections, low=1)
        check.integer("max_patches", self.max_patches, low=2)
        check.integer("seed", self.seed, low=0)


DEFAULT_SETTINGS = MetricSettings()


# --------------------------------------------------------------------------- inputs


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


def _exemplar(array: Any, name: str = "exemplar") -> np.ndarray:
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


def _volume(array: Any, name: str = "volume") -> np.ndarray:
    """Validated float64 ``(N1, N2, N3, C)`` volume."""
    a = np.asarray(array)
    if a.ndim not in (3, 4) or a.size == 0:
        check.fail(f"{name} must be a non-empty array of shape (N1, N2, N3) or (N1, N2, N3, C); "
                   f"got shape {a.shape}")
    out = _values(a, name)
    return out if out.ndim == 4 else out[..., None]


def _values(array: Any, name: str = "volume") -> np.ndarray:
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


def _grey(images: np.ndarray) -> np.ndarray:
    """Channel mean of ``(..., C)`` images, float64."""
    return np.asarray(images, dtype=np.float64).mean(axis=-1)


def _pair(exemplar: Any, volume: Any) -> tuple[np.ndarray, np.ndarray]:
    e, v = _exemplar(exemplar), _volume(volume)
    if e.shape[-1] != v.shape[-1]:
        check.fail(f"the exemplar has {e.shape[-1]} channel(s) but the volume has {v.shape[-1]}; "
                   f"compare arrays with the same channels")
    return e, v


# --------------------------------------------------------------------------- histograms


def kl_divergence(p: Any, q: Any, *, eps: float = DEFAULT_SETTINGS.eps) -> float:
    """``KL(p || q)`` in nats of two histograms (counts or probabilities, same shape).

    Each histogram is normalised to sum 1, ``eps`` is added to every bin and the result is
    renormalised, so empty bins of ``q`` give a large but finite value. With ``eps = 0`` this
    is :func:`scipy.stats.entropy(p, q) <scipy.stats.entropy>`.

    Examples
    --------
    >>> kl_divergence([1, 1], [1, 1])
    0.0
    >>> round(kl_divergence([3, 1], [1, 1], eps=0), 4)   # 0.75 log 1.5 + 0.25 log 0.5
    0.1308
    """
    p = np.asarray(p, dtype=np.float64).ravel()
    q = np.asarray(q, dtype=np.float64).ravel()
    if p.shape != q.shape or p.size == 0:
        check.fail("histograms must have the same, non-zero number of bins; "
                   f"got {p.size} and {q.size}")
    if (p < 0).any() or (q < 0).any() or p.sum() <= 0 or q.sum() <= 0:
        check.fail("histograms must be non-negative with a positive total")
    p = (p / p.sum() + eps) / (1.0 + p.size * eps)
    q = (q / q.sum() + eps) / (1.0 + q.size * eps)
    mask = p > 0
    return float(max(0.0, (p[mask] * np.log(p[mask] / q[mask])).sum()))


def _channel_ranges(exemplar: np.ndarray) -> list[tuple[float, float]]:
    """(lo, hi) of each channel of ``(..., C)`` ``exemplar``; ``hi = lo + 1`` when constant."""
    flat = exemplar.reshape(-1, exemplar.shape[-1])
    out = []
    for lo, hi in zip(flat.min(axis=0), flat.max(axis=0)):
        lo, hi = float(lo), float(hi)
        out.append((lo, hi if hi > lo else lo + 1.0))
    return out


def _histogram(values: np.ndarray, bins: int, lo: float, hi: float) -> np.ndarray:
    return np.histogram(np.clip(values.ravel(), lo, hi), bins=bins, range=(lo, hi))[0]


def histogram_kl(exemplar: np.ndarray, volume: np.ndarray, *, bins: int = DEFAULT_SETTINGS.bins,
                 eps: float = DEFAULT_SETTINGS.eps) -> float:
    """``KL(exemplar || volume)`` of grey-level histograms (grey = mean of the channels).

    ``bins`` bins evenly spaced over the exemplar's grey range; volume values outside it count
    in the end bins; ``eps`` as in :func:`kl_divergence`. ``volume`` may be a whole volume
    ``(N1, N2, N3[, C])`` (all the voxels are every view's slices, pooled) or any stack of
    images with the exemplar's channels.
    """
    e, v = _exemplar(exemplar), _values(volume)
    if e.shape[-1] == 1 and v.shape[-1] != 1:  # a grey stack given without a channel axis
        v = v[..., None]
    if v.shape[-1] != e.shape[-1]:
        check.fail(f"the exemplar has {e.shape[-1]} channel(s) but the volume has {v.shape[-1]}; "
                   f"compare arrays with the same channels")
    ge, gv = _grey(e), _grey(v)
    (lo, hi), = _channel_ranges(ge[..., None])
    return kl_divergence(_histogram(ge, bins, lo, hi), _histogram(gv, bins, lo, hi), eps=eps)


def channel_histogram_kl(exemplar: np.ndarray, volume: np.ndarray, *,
                         bins: int = DEFAULT_SETTINGS.bins,
                         eps: float = DEFAULT_SETTINGS.eps) -> list[float]:
    """Per-channel ``KL(exemplar || volume)``, each channel binned over its exemplar range."""
    e, v = _pair(exemplar, volume)
    out = []
    for c, (lo, hi) in enumerate(_channel_ranges(e)):
        out.append(kl_divergence(_histogram(e[..., c], bins, lo, hi),
                                 _histogram(v[..., c], bins, lo, hi), eps=eps))
    return out


def _joint_bins(channels: int, bins: int) -> int:
    if bins**channels <= MAX_JOINT_CELLS:
        return bins
    return max(2, int(math.floor(MAX_JOINT_CELLS ** (1.0 / channels) + 1e-9)))


def _joint_histogram(values: np.ndarray, ranges: list[tuple[float, float]],
                     bins: int) -> np.ndarray:
    flat = values.reshape(-1, values.shape[-1])
    lo = np.array([r[0] for r in ranges])
    hi = np.array([r[1] for r in ranges])
    return np.histogramdd(np.clip(flat, lo, hi), bins=bins, range=list(ranges))[0]


def joint_histogram_kl(exemplar: np.ndarray, volume: np.ndarray, *,
                       bins: int = DEFAULT_SETTINGS.joint_bins,
                       eps: float = DEFAULT_SETTINGS.eps) -> float:
    """``KL(exemplar || volume)`` of joint histograms over all C channels.

    ``bins`` bins per channel over each channel's exemplar range (``bins ** C`` cells; fewer
    bins per channel when that exceeds :data:`MAX_JOINT_CELLS`). For C = 1 this is the grey
    histogram KL with ``bins`` bins.
    """
    e, v = _pair(exemplar, volume)
    ranges = _channel_ranges(e)
    b = _joint_bins(e.shape[-1], bins)
    return kl_divergence(_joint_histogram(e, ranges, b), _joint_histogram(v, ranges, b), eps=eps)


# --------------------------------------------------------------------------- autocorrelation


def autocorrelation(images: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation coefficients of grey images, averaged over images.

    Each image has its own mean removed; the autocovariance at lag ``(a, b)`` is the sum of
    ``x[r, c] * x[r + a, c + b]`` over all pixel pairs inside the image (non-periodic),
    divided by their number ``(H - |a|)(W - |b|)``; covariances are averaged over the images
    and divided by the averaged variance (the value at lag (0, 0)).

    Parameters
    ----------
    images : (S, H, W) or (H, W) ndarray
    max_lag : int
        Lags ``-max_lag..max_lag`` along both axes (``max_lag < min(H, W)``).

    Returns
    -------
    (2 max_lag + 1, 2 max_lag + 1) float64 ndarray, 1 at lag (0, 0), entry ``[L + a, L + b]``
    for lag ``(a, b)``; all zeros when the images are constant. Computed with a zero-padded FFT.

    Examples
    --------
    >>> import numpy as np
    >>> stripes = np.tile([0.0, 1.0], (8, 4))            # columns alternate 0, 1
    >>> ac = autocorrelation(stripes, 1)
    >>> ac.round(6).tolist()
    [[-1.0, 1.0, -1.0], [-1.0, 1.0, -1.0], [-1.0, 1.0, -1.0]]
    """
    x = np.asarray(images, dtype=np.float64)
    if x.ndim == 2:
        x = x[None]
    _, h, w = x.shape
    x = x - x.mean(axis=(1, 2), keepdims=True)
    spec = np.fft.rfft2(x, s=(2 * h, 2 * w))
    ac = np.fft.irfft2(spec * np.conj(spec), s=(2 * h, 2 * w)).sum(axis=0)
    ones = np.fft.rfft2(np.ones((h, w)), s=(2 * h, 2 * w))
    overlap = np.fft.irfft2(ones * np.conj(ones), s=(2 * h, 2 * w))
    lags = np.r_[np.arange(max_lag + 1), np.arange(-max_lag, 0)]
    ac = ac[np.ix_(lags, lags)] / np.maximum(np.rint(overlap[np.ix_(lags, lags)]), 1)
    ac = np.fft.fftshift(ac)
    centre = ac[max_lag, max_lag]
    if not centre > 1e-12 * max(1.0, float(np.abs(x).max(initial=0.0)) ** 2):
        return np.zeros_like(ac)
    return ac / centre


def effective_max_lag(max_lag: int, *shapes: tuple[int, ...]) -> int:
    """``min(max_lag, side // 2)`` over the first two sides of every ``(H, W, ...)`` shape.

    Examples
    --------
    >>> effective_max_lag(32, (128, 128), (40, 64))
    20
    """
    return int(min([max_lag] + [min(s[0], s[1]) // 2 for s in shapes]))


def autocorrelation_error(exemplar: np.ndarray, volume: np.ndarray, view: str,
                          max_lag: int = DEFAULT_SETTINGS.max_lag) -> float:
    """L2 distance between the grey autocorrelation of the exemplar and of the view's slices.

    The lag range is ``-L..L`` along both axes with ``L = effective_max_lag(max_lag, exemplar
    sides, slice sides)``; the distance is the square root of the sum of squared differences
    over the ``(2L + 1)^2`` coefficients.
    """
    e, v = _pair(exemplar, volume)
    view = check.choice("view", view, VIEWS)
    slices = _grey(view_slices(v, view))
    lag = effective_max_lag(check.integer("max_lag", max_lag, low=1), e.shape, slices.shape[1:])
    a = autocorrelation(_grey(e), lag)
    b = autocorrelation(slices, lag)
    return float(np.sqrt(((a - b) ** 2).sum()))


# --------------------------------------------------------------------------- orientation


def _sobel(x: np.ndarray, axis: int) -> np.ndarray:
    """3x3 Sobel derivative of ``(..., H, W)`` images along image axis ``axis`` (-2 or -1)."""
    other = -1 if axis == -2 else -2
    d = ndimage.correlate1d(x, [-1.0, 0.0, 1.0], axis=axis, mode="reflect")
    return ndimage.correlate1d(d, [1.0, 2.0, 1.0], axis=other, mode="reflect")


def _smooth(x: np.ndarray, sigma: float) -> np.ndarray:
    if sigma <= 0:
        return x
    return ndimage.gaussian_filter(x, sigma=(0.0,) * (x.ndim - 2) + (sigma, sigma), mode="reflect")


def structure_tensor(images: np.ndarray, *,
                     gradient_sigma: float = DEFAULT_SETTINGS.gradient_sigma,
                     integration_sigma: float = DEFAULT_SETTINGS.integration_sigma,
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Structure tensor ``(J_rr, J_rc, J_cc)`` of grey ``(H, W)`` or ``(S, H, W)`` images.

    Gradient: Gaussian pre-smoothing with ``gradient_sigma`` then the 3x3 Sobel operator
    (unnormalised); tensor entries: products of the derivatives smoothed with a Gaussian of
    ``integration_sigma``; every filter reflects at the borders (``mode="reflect"``) and
    works within each image only.
    """
    x = _smooth(np.asarray(images, dtype=np.float64), gradient_sigma)
    gr, gc = _sobel(x, -2), _sobel(x, -1)
    return (_smooth(gr * gr, integration_sigma), _smooth(gr * gc, integration_sigma),
            _smooth(gc * gc, integration_sigma))


def orientation_field(images: np.ndarray, *,
                      gradient_sigma: float = DEFAULT_SETTINGS.gradient_sigma,
                      integration_sigma: float = DEFAULT_SETTINGS.integration_sigma,
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Dominant gradient orientation and coherence per pixel.

    Returns
    -------
    angle : ndarray in ``[0, pi)``
        Direction of the structure tensor's largest eigenvector (the gradient, i.e. across
        stripes), measured from the column axis towards the row axis: 0 for vertical stripes
        (values change along a row), ``pi / 2`` for horizontal stripes.
    coherence : ndarray in ``[0, 1]``
        ``(l1 - l2) / (l1 + l2)`` of the eigenvalues, 0 where the tensor vanishes.

    Examples
    --------
    >>> import numpy as np
    >>> vertical = np.tile(np.sin(np.arange(32) / 2.0), (32, 1))
    >>> angle, coherence = orientation_field(vertical)
    >>> bool(np.allclose(angle[8:-8, 8:-8] % np.pi, 0, atol=1e-6) or
    ...      np.allclose(angle[8:-8, 8:-8], np.pi, atol=1e-6)), bool(coherence.min() > 0.99)
    (True, True)
    """
    jrr, jrc, jcc = structure_tensor(images, gradient_sigma=gradient_sigma,
                                     integration_sigma=integration_sigma)
    trace = jrr + jcc
    spread = np.sqrt((jcc - jrr) ** 2 + 4.0 * jrc**2)
    tiny = 1e-12 * float(trace.max(initial=0.0))
    coherence = np.where(trace > tiny, spread / np.where(trace > tiny, trace, 1.0), 0.0)
    angle = np.mod(0.5 * np.arctan2(2.0 * jrc, jcc - jrr), np.pi)
    return angle, np.clip(coherence, 0.0, 1.0)


def orientation_histogram(images: np.ndarray, *,
                          bins: int = DEFAULT_SETTINGS.orientation_bins,
                          gradient_sigma: float = DEFAULT_SETTINGS.gradient_sigma,
                          integration_sigma: float = DEFAULT_SETTINGS.integration_sigma,
                          coherence_weighting: bool = DEFAULT_SETTINGS.coherence_weighting,
                          ) -> np.ndarray:
    """Probabilities of ``bins`` equal angle bins over ``[0, pi)`` (uniform if no weight)."""
    angle, coherence = orientation_field(images, gradient_sigma=gradient_sigma,
                                         integration_sigma=integration_sigma)
    weights = coherence if coherence_weighting else np.ones_like(angle)
    hist = np.histogram(angle, bins=bins, range=(0.0, np.pi), weights=weights)[0]
    total = hist.sum()
    return hist / total if total > 0 else np.full(bins, 1.0 / bins)


def orientation_kl(exemplar: np.ndarray, volume: np.ndarray, view: str, *,
                   settings: MetricSettings = DEFAULT_SETTINGS) -> float:
    """``KL(exemplar || slices)`` of the orientation histograms (grey images, pooled slices)."""
    e, v = _pair(exemplar, volume)
    view = check.choice("view", view, VIEWS)
    kw = _orientation_kwargs(settings)
    return kl_divergence(orientation_histogram(_grey(e), **kw),
                         orientation_histogram(_grey(view_slices(v, view)), **kw), eps=settings.eps)


def _orientation_kwargs(s: MetricSettings) -> dict[str, Any]:
    return dict(bins=s.orientation_bins, gradient_sigma=s.gradient_sigma,
                integration_sigma=s.integration_sigma, coherence_weighting=s.coherence_weighting)


# --------------------------------------------------------------------------- sliced Wasserstein


def wasserstein_1d(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Exact 1-Wasserstein distance between the empirical distributions of samples.

    ``u`` (n, P) and ``v`` (m, P) hold P pairs of samples (columns) or are 1-D (one pair).
    ``W1 = integral over t in (0, 1) of |F_u^-1(t) - F_v^-1(t)|``, evaluated exactly on the
    pieces where both quantile functions are constant (breakpoints ``i/n`` and ``j/m``).

    Examples
    --------
    >>> float(wasserstein_1d(np.array([0.0, 1.0]), np.array([0.0, 1.0, 2.0])))
    0.5
    """
    u, v = np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64)
    one = u.ndim == 1
    u, v = np.sort(u.reshape(len(u), -1), axis=0), np.sort(v.reshape(len(v), -1), axis=0)
    n, m = len(u), len(v)
    # breakpoints k / lcm-free: merge i*m and j*n on the common grid of n*m (integers, exact)
    ends = np.union1d(np.arange(1, n + 1, dtype=np.int64) * m,
                      np.arange(1, m + 1, dtype=np.int64) * n)
    starts = np.r_[0, ends[:-1]]
    iu, iv = starts // m, starts // n           # quantile index in force on (start, end]
    widths = (ends - starts) / float(n * m)
    out = (widths[:, None] * np.abs(u[iu] - v[iv])).sum(axis=0)
    return out[0] if one else out


def patch_sample(images: np.ndarray, patch: int, max_patches: int,
                 rng: np.random.Generator) -> np.ndarray:
    """All ``patch x patch`` patches of ``(S, H, W, C)`` images, or a random subset of them.

    Returns
    -------
    (n, C * patch * patch) float64 ndarray, ``n <= max_patches``; patches are flattened in
    ``(C, row, col)`` order. A subset is drawn without replacement when there are more.
    """
    windows = np.lib.stride_tricks.sliding_window_view(images, (patch, patch), axis=(1, 2))
    s, nr, nc = windows.shape[:3]
    total = s * nr * nc
    if total <= max_patches:
        return windows.reshape(total, -1).astype(np.float64)
    index = np.sort(rng.choice(total, size=max_patches, replace=False))
    a, rest = np.divmod(index, nr * nc)
    b, c = np.divmod(rest, nc)
    return windows[a, b, c].reshape(max_patches, -1).astype(np.float64)


def sliced_wasserstein(exemplar: np.ndarray, volume: np.ndarray, view: str, *,
                       settings: MetricSettings = DEFAULT_SETTINGS) -> float:
    """Sliced 1-Wasserstein distance between the exemplar's and the slices' patches.

    Patches of side ``p = min(settings.patch, sides)`` with all C channels are flattened
    (each channel's patch mean removed when ``settings.centre_patches``); both patch sets
    (at most ``settings.max_patches`` each) are projected on ``settings.projections`` random
    unit directions drawn from ``settings.seed``; the result
    is the mean over directions of the exact 1-D W1 (:func:`wasserstein_1d`), in grey-value
    units.
    """
    e, v = _pair(exemplar, volume)
    view = check.choice("view", view, VIEWS)
    value, _ = _sliced_wasserstein(e, view_slices(v, view), settings)
    return value


def _sliced_wasserstein(e: np.ndarray, slices: np.ndarray, s: MetricSettings) -> tuple[float, int]:
    p = int(min(s.patch, e.shape[0], e.shape[1], slices.shape[1], slices.shape[2]))
    rng = np.random.default_rng(s.seed)
    directions = rng.standard_normal((p * p * e.shape[-1], s.projections))
    directions /= np.linalg.norm(directions, axis=0, keepdims=True)
    a = patch_sample(e[None], p, s.max_patches, rng)
    b = patch_sample(slices, p, s.max_patches, rng)
    if s.centre_patches:
        a, b = (_centred(x, e.shape[-1]) for x in (a, b))
    return float(wasserstein_1d(a @ directions, b @ directions).mean()), p


def _block_mean(images: np.ndarray, factor: int) -> np.ndarray:
    """Mean of each non-overlapping ``factor x factor`` block of ``(S, H, W, C)`` images
    (trailing rows and columns that do not fill a block are dropped)."""
    if factor == 1:
        return images
    s, h, w, c = images.shape
    h, w = h // factor * factor, w // factor * factor
    x = images[:, :h, :w].reshape(s, h // factor, factor, w // factor, factor, c)
    return x.mean(axis=(2, 4))


def multiscale_sliced_wasserstein(exemplar: np.ndarray, volume: np.ndarray, view: str, *,
                                  scales: tuple[int, ...] = (1, 2, 4), patch: int = 7,
                                  settings: MetricSettings = DEFAULT_SETTINGS) -> float:
    """Sliced Wasserstein distance of ``patch x patch`` patches, averaged over scales.

    At each scale ``s`` the exemplar and every slice of the view are reduced by the mean of
    each ``s x s`` block, then compared as in :func:`sliced_wasserstein` (patches of side
    ``min(patch, sides)``, channel means removed when ``settings.centre_patches``); the result
    is the mean over the scales, in exemplar value units (SPEC.md section 7: 7 x 7 patches at
    scales 1, 2 and 4 ranked pictures as the eye did). A scale whose reduced exemplar or
    slices would be smaller than :data:`MIN_SIDE` is skipped (at least scale 1 is kept).

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> image = rng.random((32, 32))
    >>> volume = np.repeat(image[:, :, None], 4, axis=2)   # every front slice is the image
    >>> round(multiscale_sliced_wasserstein(image, volume, "front"), 12)
    0.0
    >>> noise = rng.random((32, 32, 32))                    # same values, no arrangement
    >>> multiscale_sliced_wasserstein(image, noise, "front") > 0.001
    True
    """
    e, v = _pair(exemplar, volume)
    view = check.choice("view", view, VIEWS)
    check.integer("patch", patch, low=1)
    scales = tuple(check.integer("scale", s, low=1) for s in scales) or (1,)
    slices = view_slices(v, view)
    smallest = min(e.shape[0], e.shape[1], slices.shape[1], slices.shape[2])
    kept = [s for s in scales if smallest // s >= MIN_SIDE] or [1]
    s_patch = dataclasses.replace(settings, patch=patch)
    values = [_sliced_wasserstein(_block_mean(e[None], f)[0], _block_mean(slices, f), s_patch)[0]
              for f in kept]
    return float(np.mean(values))


def _centred(patches: np.ndarray, channels: int) -> np.ndarray:
    """Flattened ``(C, p, p)`` patches minus each channel's mean within the patch."""
    x = patches.reshape(len(patches), channels, -1)
    return (x - x.mean(axis=2, keepdims=True)).reshape(len(patches), -1)


# --------------------------------------------------------------------------- two-point correlation


def two_point_correlation(array: np.ndarray, phase: float = 1, *, threshold: float | None = None,
                          max_distance: int | None = None, periodic: bool = False) -> np.ndarray:
    """Two-point probability function ``S2`` of one phase along each axis.

    ``S2_a(r)`` is the probability that two points ``r`` pixels/voxels apart along axis ``a``
    both lie in the phase (``array == phase``, or ``array > threshold`` when a threshold is
    given). Non-periodic by default: only pairs inside the array are counted, each distance
    divided by its own number of pairs; ``periodic=True`` wraps around. ``S2(0)`` is the
    phase's volume fraction and, without long-range order, ``S2(r) -> fraction**2``.

    Parameters
    ----------
    array : ndarray, 2-D image or 3-D volume (any ndim >= 1) of labels or values
    phase : number
        The label of the phase (ignored when ``threshold`` is given).
    threshold : float, optional
        Phase = values above it, for grey images.
    max_distance : int, optional
        Largest distance; default ``min(shape) // 2``; at most ``min(shape) - 1``.
    periodic : bool

    Returns
    -------
    (ndim, max_distance + 1) float64 ndarray, row ``a`` = ``S2`` along axis ``a``.

    Examples
    --------
    >>> import numpy as np
    >>> two_point_correlation(np.tile([1, 0], (4, 2)), max_distance=2).tolist()
    [[0.5, 0.5, 0.5], [0.5, 0.0, 0.5]]
    """
    a = np.asarray(array)
    if a.ndim < 1 or a.size == 0 or a.dtype == object:
        check.fail(f"array must be a non-empty numeric array; got shape {a.shape}")
    indicator = (a > threshold) if threshold is not None else (a == phase)
    indicator = indicator.astype(np.float64)
    longest = min(a.shape) - 1
    r_max = min(a.shape) // 2 if max_distance is None else check.integer(
        "max_distance", max_distance, low=0, high=longest)
    out = np.empty((a.ndim, r_max + 1))
    for axis, n in enumerate(a.shape):
        size = n if periodic else 2 * n
        spec = np.fft.rfft(indicator, n=size, axis=axis)
        corr = np.fft.irfft(spec * np.conj(spec), n=size, axis=axis)
        counts = np.rint(np.moveaxis(corr, axis, 0)[: r_max + 1].reshape(r_max + 1, -1).sum(axis=1))
        pairs = a.size if periodic else (n - np.arange(r_max + 1)) * (a.size // n)
        out[axis] = counts / pairs
    return out


def _phase_shape_curves(grey: np.ndarray, phases: np.ndarray, max_distance: int) -> np.ndarray:
    """``(ndim, P - 1, max_distance + 1)``: along each axis, the normalised two-point curve
    ``(S2(r) - phi^2) / (phi - phi^2)`` of each phase but the first (``grey`` labelled by the
    nearest phase value; a phase absent or filling the array gives zeros)."""
    labels = np.searchsorted((phases[1:] + phases[:-1]) / 2, grey)
    out = np.zeros((grey.ndim, max(1, len(phases) - 1), max_distance + 1))
    for p in range(1, len(phases)) if len(phases) > 1 else (0,):
        s2 = two_point_correlation(labels, p, max_distance=max_distance)
        phi = float((labels == p).mean())
        if 0.0 < phi < 1.0:
            out[:, max(p - 1, 0)] = (s2 - phi * phi) / (phi - phi * phi)
    return out


#: References of :func:`two_point_shape_error`.
SHAPE_REFERENCES = ("views", "isotropic")


def two_point_shape_error(exemplars: Any, volume: Any, *, views: Any = None,
                          max_distance: int | None = None, reference: str = "views") -> float:
    """How far the volume's two-point correlation *shape* is from the exemplars', phase by phase.

    For a phase image (the exemplars' distinct grey values are the phases; grey = mean of the
    channels, every value labelled by the nearest phase), each phase but the first has along
    each axis the normalised curve ``(S2(r) - phi^2) / (phi - phi^2)`` (:func:`two_point_correlation`,
    non-periodic; 1 at ``r = 0``, 0 without correlation), which does not depend on the phase
    fraction. With ``reference="views"`` a view's exemplar rows and columns give the reference
    of the volume axes of its plane (:data:`npmrf3d.model.neighbourhood.VIEW_AXES`; an axis in several
    views' planes takes their mean); with ``"isotropic"`` every axis has one reference, the mean
    of all the exemplars' row and column curves: the estimate, from the slices alone, of an
    isotropic material's curve (a slice's rows and columns are two noisy samples of it). The
    error of an axis is the L2 norm over phases and distances ``0..max_distance`` of the
    volume's curves minus the reference; the result is the mean over the axes that have a
    reference. It needs nothing but the exemplars, so a run can be judged by it without ground
    truth (the segmented preset of ``synth`` keeps the better of two runs by it, isotropic).

    Parameters
    ----------
    exemplars : (H, W[, C]) array, or dict view -> array
    volume : (N1, N2, N3[, C]) array
    views : the views the exemplars constrain (default: all for one array, the dict's keys)
    max_distance : int, optional
        Default ``min(32, smallest exemplar side // 2, smallest volume side // 2)``.
    reference : {"views", "isotropic"}

    Examples
    --------
    >>> stripes = np.tile([0.0, 0.0, 1.0, 1.0], (8, 2))             # columns of period 4
    >>> stacked = np.broadcast_to(stripes[None], (8, 8, 8)).copy()   # every right slice is it
    >>> two_point_shape_error({"right": stripes}, stacked)
    0.0
    """
    reference = check.choice("reference", reference, SHAPE_REFERENCES)
    given = _exemplar_map(exemplars, views)
    distinct = {id(a): _grey(_exemplar(a, f"{v} exemplar")) for v, a in given.items()}  # one array, several views: once
    greys = {v: distinct[id(a)] for v, a in given.items()}
    grey = _grey(_volume(volume))
    phases = np.unique(np.concatenate([g.ravel() for g in greys.values()]))
    longest = min(min(min(g.shape) for g in greys.values()), min(grey.shape)) // 2
    r_max = min(32, longest) if max_distance is None else check.integer(
        "max_distance", max_distance, low=1, high=max(1, longest))
    mine = _phase_shape_curves(grey, phases, r_max)
    refs: dict[int, list[np.ndarray]] = {}
    curves_of = {key: _phase_shape_curves(g, phases, r_max) for key, g in distinct.items()}
    for view, a in given.items():
        curves = curves_of[id(a)]
        for image_axis, volume_axis in enumerate(VIEW_AXES[view]):
            for axis in range(3) if reference == "isotropic" else (volume_axis,):
                refs.setdefault(axis, []).append(curves[image_axis])
    errors = [float(np.sqrt(((mine[axis] - np.mean(ref, axis=0)) ** 2).sum()))
              for axis, ref in sorted(refs.items())]
    return float(np.mean(errors))


# --------------------------------------------------------------------------- the report


def _exemplar_map(exemplars: Any, views: Any) -> dict[str, np.ndarray]:
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


def _check_sides(shape: tuple[int, ...], name: str) -> None:
    if min(shape) < MIN_SIDE:
        dims = "x".join(str(n) for n in shape)
        check.fail(f"{name} of size {dims} is too small for the metrics; every side must be at "
                   f"least {MIN_SIDE}")


def _prepare(volume: Any, exemplars: Any, views: Any) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    v = _volume(volume)
    _check_sides(v.shape[:3], "volume")
    cache: dict[int, np.ndarray] = {}
    out = {}
    for view, raw in _exemplar_map(exemplars, views).items():
        if id(raw) not in cache:
            name = f"exemplar of the {view} view"
            e = _exemplar(raw, name)
            _check_sides(e.shape[:2], name)
            if e.shape[-1] != v.shape[-1]:
                check.fail(f"{name} has {e.shape[-1]} channel(s) but the volume has "
                           f"{v.shape[-1]}; give every exemplar the volume's channels")
            cache[id(raw)] = e
        out[view] = cache[id(raw)]
    return v, out


# --------------------------------------------------------------------------- the registry


class ViewPair(NamedTuple):
    """One view's exemplar and the volume's slices orthogonal to it, as :func:`evaluate` passes
    them to every function of :data:`METRIC_FUNCTIONS`."""

    exemplar: np.ndarray  # (H, W, C) float64
    slices: np.ndarray  # (S, A, B, C) float64
    grey_exemplar: np.ndarray  # (H, W)
    grey_slices: np.ndarray  # (S, A, B)
    joint_bins: int  # bins per channel of the joint colour histogram


def _histogram_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    e, slices = pair.exemplar, pair.slices
    ranges = _channel_ranges(e)
    (glo, ghi), = _channel_ranges(pair.grey_exemplar[..., None])
    grey_kl = kl_divergence(_histogram(pair.grey_exemplar, s.bins, glo, ghi),
                            _histogram(pair.grey_slices, s.bins, glo, ghi), eps=s.eps)
    channel_kl = [kl_divergence(_histogram(e[..., c], s.bins, lo, hi),
                                _histogram(slices[..., c], s.bins, lo, hi), eps=s.eps)
                  for c, (lo, hi) in enumerate(ranges)]
    if e.shape[-1] == 1:
        hist_kl = grey_kl
    else:
        hist_kl = kl_divergence(_joint_histogram(e, ranges, pair.joint_bins),
                                _joint_histogram(slices, ranges, pair.joint_bins), eps=s.eps)
    return hist_kl, {"histogram_kl_grey": grey_kl, "histogram_kl_channels": channel_kl}


def _autocorrelation_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    lag = effective_max_lag(s.max_lag, pair.exemplar.shape, pair.slices.shape[1:])
    difference = autocorrelation(pair.grey_exemplar, lag) - autocorrelation(pair.grey_slices, lag)
    return float(np.sqrt((difference**2).sum())), {"max_lag": lag}


def _orientation_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    kw = _orientation_kwargs(s)
    return kl_divergence(orientation_histogram(pair.grey_exemplar, **kw),
                         orientation_histogram(pair.grey_slices, **kw), eps=s.eps), {}


def _sliced_wasserstein_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    sw, patch = _sliced_wasserstein(pair.exemplar, pair.slices, s)
    return sw, {"patch": patch}


#: name -> ``metric(pair, settings) -> (value, details)``: what :func:`evaluate` computes per
#: view, in the order of :data:`METRICS` (a new metric is one function plus one line here).
METRIC_FUNCTIONS: dict[str, Callable[[ViewPair, MetricSettings], tuple[float, dict]]] = {
    "histogram_kl": _histogram_metric,
    "autocorrelation_l2": _autocorrelation_metric,
    "orientation_kl": _orientation_metric,
    "sliced_wasserstein": _sliced_wasserstein_metric,
}
assert tuple(METRIC_FUNCTIONS) == METRICS


def evaluate(volume: Any, exemplars: Any, *, views: Any = None,
             settings: MetricSettings | None = None) -> dict[str, Any]:
    """Compare each view's exemplar with all the volume's slices orthogonal to that view.

    Parameters
    ----------
    volume : (N1, N2, N3) or (N1, N2, N3, C) array
    exemplars : mapping view -> (H, W) or (H, W, C) array, or one array used for every view
        Each exemplar needs the volume's C channels; sides of at least :data:`MIN_SIDE`.
    views : str or sequence of str, optional
        Views to report, e.g. ``"front,top"``; default the mapping's keys (in the order front,
        right, top) or all three views for a single array.
    settings : MetricSettings, optional
        Default :data:`DEFAULT_SETTINGS`.

    Returns
    -------
    dict
        ``per_view``: view -> ``{name: float}`` for every name of :data:`METRICS`;
        ``mean``: the same names averaged over the views; ``settings``: every setting plus
        what was derived from the inputs (channels, grey definition, joint bins used);
        ``details``: view -> per-channel histogram KL, grey histogram KL, the lag and patch
        side actually used. For C = 1 ``histogram_kl`` is the grey-level KL (``bins`` bins);
        for C > 1 it is the joint colour KL (``joint_bins`` per channel).

    Raises
    ------
    ParameterError
        NaN/Inf values, wrong shapes, too small sides, channel mismatch, unknown or repeated
        view names, a view without an exemplar.
    """
    s = DEFAULT_SETTINGS if settings is None else settings
    if not isinstance(s, MetricSettings):
        check.fail(f"settings must be a MetricSettings; got {type(settings).__name__}")
    v, per_view_exemplars = _prepare(volume, exemplars, views)
    channels = v.shape[-1]
    joint = _joint_bins(channels, s.joint_bins)
    per_view: dict[str, dict[str, float]] = {}
    details: dict[str, dict[str, Any]] = {}
    for view, e in per_view_exemplars.items():
        slices = view_slices(v, view)
        pair = ViewPair(e, slices, _grey(e), _grey(slices), joint)
        per_view[view], details[view] = {}, {}
        for name, metric in METRIC_FUNCTIONS.items():
            per_view[view][name], extra = metric(pair, s)
            details[view].update(extra)
        details[view].update({"exemplar_shape": list(e.shape), "slices": int(slices.shape[0])})
    mean = {name: float(np.mean([per_view[view][name] for view in per_view])) for name in METRICS}
    derived = {
        "channels": int(channels),
        "joint_bins_used": int(joint) if channels > 1 else None,
        "grey": "mean of the channels",
        "histogram": ("grey-level KL" if channels == 1 else "joint colour KL")
                     + "; bins evenly spaced over the exemplar's range, volume values "
                       "clipped into it",
        "autocorrelation": "per-image mean removed, covariances averaged over slices, "
                           "lags -L..L with L = min(max_lag, side // 2)",
        "orientation": "structure tensor: Gaussian(gradient_sigma) + 3x3 Sobel, "
                       "Gaussian(integration_sigma), mode reflect; angles in [0, pi)",
        "sliced_wasserstein": "mean over projections of exact W1 of projected patches"
                              + (" (each patch's channel means removed)"
                                 if s.centre_patches else ""),
        "max_lag_per_view": {view: d["max_lag"] for view, d in details.items()},
        "patch_per_view": {view: d["patch"] for view, d in details.items()},
    }
    return {"per_view": per_view, "mean": mean,
            "settings": {**dataclasses.asdict(s), **derived}, "details": details}


def view_histograms(volume: Any, exemplar: Any, view: str, *,
                    settings: MetricSettings = DEFAULT_SETTINGS) -> dict[str, Any]:
    """The histograms behind :func:`evaluate` for one view, for plotting.

    Returns
    -------
    dict
        ``values``: ``edges`` (C, bins + 1), ``exemplar`` and ``volume`` (C, bins)
        probabilities per channel (for C = 1 the grey histogram of ``histogram_kl``);
        ``orientation``: ``edges`` (orientation_bins + 1,), ``exemplar`` and ``volume``
        probabilities.
    """
    view = check.choice("view", view, VIEWS)
    v, exemplars = _prepare(volume, {view: exemplar}, None)
    e = exemplars[view]
    slices = view_slices(v, view)
    edges, he, hv = [], [], []
    for c, (lo, hi) in enumerate(_channel_ranges(e)):
        edges.append(np.linspace(lo, hi, settings.bins + 1))
        a = _histogram(e[..., c], settings.bins, lo, hi)
        b = _histogram(slices[..., c], settings.bins, lo, hi)
        he.append(a / a.sum())
        hv.append(b / b.sum())
    kw = _orientation_kwargs(settings)
    return {
        "values": {"edges": np.array(edges), "exemplar": np.array(he), "volume": np.array(hv)},
        "orientation": {"edges": np.linspace(0.0, np.pi, settings.orientation_bins + 1),
                        "exemplar": orientation_histogram(_grey(e), **kw),
                        "volume": orientation_histogram(_grey(slices), **kw)},
    }


def largest_value_share(volume: np.ndarray) -> float:
    """Share of voxels holding the most common value (1.0 = a constant volume)."""
    flat = volume.reshape(-1, volume.shape[-1])
    _, counts = np.unique(flat, axis=0, return_counts=True)
    return float(counts.max() / len(flat))
