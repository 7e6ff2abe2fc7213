"""The orientation metric: the structure tensor's dominant gradient orientation per pixel, its
coherence-weighted histogram, and ``KL(exemplar || slices)`` of those histograms
(``docs/metrics.md``)."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage

from .histograms import kl_divergence
from .inputs import ViewPair, exemplar_and_slices, grey_level
from .settings import DEFAULT_SETTINGS, MetricSettings


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
    e, slices = exemplar_and_slices(exemplar, volume, view)
    return kl_divergence(*orientation_histograms(grey_level(e), grey_level(slices), settings), eps=settings.eps)


def orientation_histograms(grey_exemplar: np.ndarray, grey_slices: np.ndarray,
                           s: MetricSettings) -> tuple[np.ndarray, np.ndarray]:
    """The orientation histograms of the exemplar and of the pooled slices, with the settings ``s``."""
    kw: dict[str, Any] = dict(bins=s.orientation_bins, gradient_sigma=s.gradient_sigma,
                              integration_sigma=s.integration_sigma,
                              coherence_weighting=s.coherence_weighting)
    return orientation_histogram(grey_exemplar, **kw), orientation_histogram(grey_slices, **kw)


def orientation_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    """``orientation_kl`` of :func:`~npmrf3d.analysis.metrics.evaluate` (no details)."""
    return kl_divergence(*orientation_histograms(pair.grey_exemplar, pair.grey_slices, s), eps=s.eps), {}
