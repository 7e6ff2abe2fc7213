"""The autocorrelation metric: L2 distance between the normalised grey autocorrelation of the
exemplar and that of the view's slices, lags ``-L..L`` (``docs/metrics.md``)."""

from __future__ import annotations

import numpy as np

from ... import _validation as check
from .inputs import ViewPair, exemplar_and_slices, grey_level
from .settings import DEFAULT_SETTINGS, MetricSettings


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
    e, slices = exemplar_and_slices(exemplar, volume, view)
    lag = effective_max_lag(check.integer("max_lag", max_lag, low=1), e.shape, slices.shape[1:])
    return _distance(grey_level(e), grey_level(slices), lag)


def autocorrelation_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    """``autocorrelation_l2`` of :func:`~npmrf3d.analysis.metrics.evaluate`, with the lag used."""
    lag = effective_max_lag(s.max_lag, pair.exemplar.shape, pair.slices.shape[1:])
    return _distance(pair.grey_exemplar, pair.grey_slices, lag), {"max_lag": lag}


def _distance(grey_exemplar: np.ndarray, grey_slices: np.ndarray, lag: int) -> float:
    """L2 distance of the autocorrelations, lags ``-lag..lag``."""
    difference = autocorrelation(grey_exemplar, lag) - autocorrelation(grey_slices, lag)
    return float(np.sqrt((difference**2).sum()))
