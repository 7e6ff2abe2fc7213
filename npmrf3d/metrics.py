"""Input-versus-output measures (SPEC.md section 7), per constrained view.

The exemplar of a view is compared with *all* the volume's slices orthogonal to that view
(pooled). Slices are oriented as in :mod:`npmrf3d.neighborhood` so the exemplar's rows and
columns line up with the slice's.
"""

from __future__ import annotations

import numpy as np

from .neighborhood import VIEW_AXES

__all__ = [
    "autocorrelation",
    "autocorrelation_error",
    "histogram_kl",
    "largest_value_share",
    "view_slices",
]


def view_slices(volume: np.ndarray, view: str) -> np.ndarray:
    """All slices of ``volume`` (N1, N2, N3, C) in one view, as (S, rows, cols, C)."""
    row_axis, col_axis = VIEW_AXES[view]
    fixed = ({0, 1, 2} - {row_axis, col_axis}).pop()
    return np.moveaxis(volume, (fixed, row_axis, col_axis), (0, 1, 2))


def _grey(images: np.ndarray) -> np.ndarray:
    return images.astype(np.float64).mean(axis=-1)


def autocorrelation(images: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation coefficients of grey images, averaged over images.

    Parameters
    ----------
    images : (S, H, W) or (H, W) ndarray
    max_lag : int
        Lags ``-max_lag..max_lag`` along both axes (``max_lag < min(H, W)``).

    Returns
    -------
    (2 max_lag + 1, 2 max_lag + 1) float64 ndarray, 1 at lag (0, 0). Non-periodic estimate:
    zero-padded FFT, each lag divided by its number of overlapping pixel pairs.
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
    return ac / centre if centre > 0 else np.zeros_like(ac)


def autocorrelation_error(exemplar: np.ndarray, volume: np.ndarray, view: str, max_lag: int) -> float:
    """L2 distance between the autocorrelation of the exemplar and of the view's slices."""
    a = autocorrelation(_grey(exemplar), max_lag)
    b = autocorrelation(_grey(view_slices(volume, view)), max_lag)
    return float(np.sqrt(((a - b) ** 2).sum()))


def histogram_kl(exemplar: np.ndarray, volume: np.ndarray, *, bins: int = 32, eps: float = 1e-10) -> float:
    """``KL(exemplar || volume)`` of grey-level histograms (``bins`` bins over the exemplar's
    range; ``eps`` added to every bin of both before normalising)."""
    e, v = _grey(exemplar).ravel(), _grey(volume).ravel()
    lo, hi = float(e.min()), float(e.max())
    if hi <= lo:
        hi = lo + 1.0
    p = np.histogram(np.clip(e, lo, hi), bins=bins, range=(lo, hi))[0] + eps
    q = np.histogram(np.clip(v, lo, hi), bins=bins, range=(lo, hi))[0] + eps
    p, q = p / p.sum(), q / q.sum()
    return float((p * np.log(p / q)).sum())


def largest_value_share(volume: np.ndarray) -> float:
    """Share of voxels holding the most common value (1.0 = a constant volume)."""
    flat = volume.reshape(-1, volume.shape[-1])
    _, counts = np.unique(flat, axis=0, return_counts=True)
    return float(counts.max() / len(flat))
