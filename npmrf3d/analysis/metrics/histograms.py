"""Histogram metrics: ``KL(exemplar || volume)`` of grey-level, per-channel and joint colour
histograms, each channel binned over the exemplar's range (``docs/metrics.md``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ... import _validation as check
from .inputs import ViewPair, as_exemplar, as_values, exemplar_and_volume, grey_level
from .settings import DEFAULT_SETTINGS, MAX_JOINT_CELLS, MetricSettings


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
    e, v = as_exemplar(exemplar), as_values(volume)
    if e.shape[-1] == 1 and v.shape[-1] != 1:  # a grey stack given without a channel axis
        v = v[..., None]
    if v.shape[-1] != e.shape[-1]:
        check.fail(f"the exemplar has {e.shape[-1]} channel(s) but the volume has {v.shape[-1]}; "
                   f"compare arrays with the same channels")
    return _grey_kl(grey_level(e), grey_level(v), bins, eps)


def channel_histogram_kl(exemplar: np.ndarray, volume: np.ndarray, *,
                         bins: int = DEFAULT_SETTINGS.bins,
                         eps: float = DEFAULT_SETTINGS.eps) -> list[float]:
    """Per-channel ``KL(exemplar || volume)``, each channel binned over its exemplar range."""
    e, v = exemplar_and_volume(exemplar, volume)
    return [kl_divergence(a, b, eps=eps) for _, _, a, b in channel_histograms(e, v, bins)]


def channel_histograms(exemplar: np.ndarray, other: np.ndarray,
                       bins: int) -> list[tuple[float, float, np.ndarray, np.ndarray]]:
    """``(lo, hi, exemplar counts, other counts)`` of each channel of ``(..., C)`` arrays: ``bins``
    bins evenly spaced over the exemplar's range of the channel, ``other``'s values outside it
    counted in the end bins."""
    return [(lo, hi, _histogram(exemplar[..., c], bins, lo, hi), _histogram(other[..., c], bins, lo, hi))
            for c, (lo, hi) in enumerate(_channel_ranges(exemplar))]


def _grey_kl(grey_exemplar: np.ndarray, grey_other: np.ndarray, bins: int, eps: float) -> float:
    """``KL`` of the grey-level histograms, binned over the exemplar's grey range."""
    (_, _, a, b), = channel_histograms(grey_exemplar[..., None], grey_other[..., None], bins)
    return kl_divergence(a, b, eps=eps)


def joint_bins(channels: int, bins: int) -> int:
    """Bins per channel of the joint histogram of ``channels`` channels: ``bins``, or fewer when
    ``bins ** channels`` would exceed :data:`MAX_JOINT_CELLS`."""
    if bins**channels <= MAX_JOINT_CELLS:
        return bins
    return max(2, int(math.floor(MAX_JOINT_CELLS ** (1.0 / channels) + 1e-9)))


def _joint_histogram(values: np.ndarray, ranges: list[tuple[float, float]], bins: int) -> np.ndarray:
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
    e, v = exemplar_and_volume(exemplar, volume)
    return _joint_kl(e, v, joint_bins(e.shape[-1], bins), eps)


def _joint_kl(exemplar: np.ndarray, other: np.ndarray, bins: int, eps: float) -> float:
    """``KL`` of the joint histograms, ``bins`` per channel over the exemplar's ranges."""
    ranges = _channel_ranges(exemplar)
    return kl_divergence(_joint_histogram(exemplar, ranges, bins), _joint_histogram(other, ranges, bins),
                         eps=eps)


def histogram_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    """``histogram_kl`` of :func:`~npmrf3d.analysis.metrics.evaluate`: the grey KL for one channel,
    the joint colour KL for more; the grey and per-channel KLs as details."""
    grey_kl = _grey_kl(pair.grey_exemplar, pair.grey_slices, s.bins, s.eps)
    channel_kl = [kl_divergence(a, b, eps=s.eps)
                  for _, _, a, b in channel_histograms(pair.exemplar, pair.slices, s.bins)]
    if pair.exemplar.shape[-1] == 1:
        hist_kl = grey_kl
    else:
        hist_kl = _joint_kl(pair.exemplar, pair.slices, pair.joint_bins, s.eps)
    return hist_kl, {"histogram_kl_grey": grey_kl, "histogram_kl_channels": channel_kl}
