"""The patch metric: the sliced 1-Wasserstein distance between the exemplar's and the slices'
patches, at one scale or averaged over block-mean scales (``docs/metrics.md``)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ... import _validation as check
from .inputs import ViewPair, exemplar_and_slices
from .settings import DEFAULT_SETTINGS, MIN_SIDE, MetricSettings


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
    e, slices = exemplar_and_slices(exemplar, volume, view)
    value, _ = _sliced_wasserstein(e, slices, settings)
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
    is the mean over the scales, in exemplar value units (docs/metrics.md,
    ``multiscale_sliced_wasserstein``). A scale whose reduced exemplar or slices would be
    smaller than :data:`MIN_SIDE` is skipped (at least scale 1 is kept).

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
    e, slices = exemplar_and_slices(exemplar, volume, view)
    check.integer("patch", patch, low=1)
    scales = tuple(check.integer("scale", s, low=1) for s in scales) or (1,)
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


def sliced_wasserstein_metric(pair: ViewPair, s: MetricSettings) -> tuple[float, dict]:
    """``sliced_wasserstein`` of :func:`~npmrf3d.analysis.metrics.evaluate`, with the patch side used."""
    sw, patch = _sliced_wasserstein(pair.exemplar, pair.slices, s)
    return sw, {"patch": patch}
