"""The k-coherence engine's histograms: the solver's position and value histograms
(:func:`position_histogram`, :class:`ValueHistogram`) and what a ``blockwise`` run's finer
levels keep of the coarsest level's (:class:`FrozenHistograms`, :func:`held_values`).

Used by :mod:`npmrf3d.model.kcoherence_engine`; bins of values by the compiled
:func:`npmrf3d._kernels.kcoherence.value_bins`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._kernels import kcoherence as _search

__all__ = ["FrozenHistograms", "ValueHistogram", "held_values", "position_histogram", "value_counts",
           "value_scale"]


def value_scale(span, bins: int) -> np.ndarray:
    """Bins per unit of value of each channel, ``bins / span`` (0 for a channel of one value)."""
    span = np.asarray(span, dtype=np.float64)
    return np.where(span > 0, bins / np.where(span > 0, span, 1.0), 0.0)


def value_counts(values: np.ndarray, lo: np.ndarray, scale: np.ndarray, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """The bin of every value of ``values`` (n, C) (:func:`npmrf3d._kernels.kcoherence.value_bin`),
    ``(n, C)`` int64, and each channel's counts, ``(C, bins)`` float64."""
    b = np.empty(values.shape, dtype=np.int64)
    _search.value_bins(np.ascontiguousarray(values, dtype=np.float32), np.asarray(lo, dtype=np.float64), scale, bins, b)
    return b, np.stack([np.bincount(b[:, c], minlength=bins) for c in range(values.shape[1])]).astype(np.float64)


class ValueHistogram(NamedTuple):
    """Per-channel value histograms of a level for the solver's histogram matching.

    Attributes
    ----------
    lo, scale : (C,) float64
        Bin of value ``x`` of channel ``c``: ``floor((x - lo[c]) * scale[c])`` clamped to
        ``0..bins - 1`` (:func:`npmrf3d._kernels.kcoherence.value_bin`).
    ex_bins : (G, C) int64
        Bins of every packed exemplar texel.
    hist : (C, bins) float64
        The volume's histogram, in units of ``unit`` voxels (an even bin's share); the solver
        updates it.
    target : (C, bins) float64
        The exemplars' histogram (views pooled, each view's exemplar weighted equally), same units.
    unit : float
        Voxels per even bin, ``N / bins``.
    """

    lo: np.ndarray
    scale: np.ndarray
    ex_bins: np.ndarray
    hist: np.ndarray
    target: np.ndarray
    unit: float

    @classmethod
    def build(cls, exemplars, ex_flat: np.ndarray, volume: np.ndarray, *, bins: int,
              lo: np.ndarray, span: np.ndarray) -> "ValueHistogram":
        """Histograms of ``volume`` (N1, N2, N3, C) and of ``exemplars`` (one (H, W, C) array per
        view) over ``bins`` bins spanning ``lo .. lo + span`` per channel; ``ex_flat`` the packed
        texels (:func:`npmrf3d.model.kcoherence_engine.pack_exemplars`)."""
        channels = volume.shape[3]
        lo = np.asarray(lo, dtype=np.float64)
        scale = value_scale(span, bins)
        ex_bins, _ = value_counts(ex_flat, lo, scale, bins)
        n = volume.shape[0] * volume.shape[1] * volume.shape[2]
        _, hist = value_counts(volume.reshape(n, channels), lo, scale, bins)
        target = np.zeros((channels, bins), dtype=np.float64)
        for ex in exemplars:
            _, h = value_counts(ex.reshape(-1, channels), lo, scale, bins)
            target += h / h.sum(axis=1, keepdims=True)
        unit = n / bins
        return cls(lo, scale, ex_bins, hist / unit, target * bins / len(exemplars), float(unit))


def position_histogram(src_v: np.ndarray, pixels: int) -> np.ndarray:
    """How many voxels copy each exemplar pixel: ``(pixels,)`` float64 counts of ``src_v``."""
    return np.bincount(np.asarray(src_v).ravel(), minlength=pixels).astype(np.float64)


def held_values(positions: np.ndarray, position_offsets, texel_bins: np.ndarray, texel_offsets, pixels,
                bins: int) -> np.ndarray:
    """The value histogram ``(C, bins)`` (in voxels) of a volume whose every voxel holds the
    texel its source names, from each view's position counts (``positions`` packed per view at
    ``position_offsets``, ``pixels`` each; their texels' bins ``texel_bins`` at
    ``texel_offsets``), the views averaged.

    >>> held_values(np.array([2.0, 0.0, 1.0]), [0], np.array([[0], [1], [1]]), [0], [3], 2)
    array([[2., 1.]])
    """
    channels = texel_bins.shape[1]
    out = np.zeros((channels, bins), dtype=np.float64)
    for start, offset, n in zip(position_offsets, texel_offsets, pixels):
        counts = positions[start:start + n]
        for ch in range(channels):
            out[ch] += np.bincount(texel_bins[offset:offset + n, ch], weights=counts, minlength=bins)
    return out / len(pixels)


class FrozenHistograms(NamedTuple):
    """The histograms a ``blockwise`` run's finer levels keep from its coarsest level, which
    runs whole: per view the position counts of the coarsest level's sources.

    A finer level's position counts are the coarsest ones up-sampled as the sources are (each
    coarse pixel's count goes, doubled, to the four pixels ``2 * p + offset``:
    :meth:`positions_at`), which is what the level's starting sources hold, and its value
    histogram that of the texels they name (:func:`held_values`): the histograms of that
    level's exemplar, not of the coarsest level's smoother one. The solver's votes and its
    histogram prior read them without updates, so that every voxel depends on its
    neighbourhood alone.
    """

    positions: tuple[np.ndarray, ...]
    shapes: tuple[tuple[int, int], ...]

    @classmethod
    def of(cls, state, models) -> "FrozenHistograms":
        """The position counts of the coarsest level's finished whole ``state`` (a
        :class:`npmrf3d.model.kcoherence_engine.CoherentState`; its level ``models``)."""
        positions = tuple(position_histogram(state.sources[vi], m.pixels) for vi, m in enumerate(models))
        return cls(positions, tuple((int(m.exemplar.shape[0]), int(m.exemplar.shape[1])) for m in models))

    def positions_at(self, view: int, fine_shapes) -> np.ndarray:
        """View ``view``'s counts up-sampled once per exemplar shape of ``fine_shapes`` (the
        view's exemplar at each finer level in turn, down to the one wanted).

        >>> frozen = FrozenHistograms((np.array([1.0, 0.0, 0.0, 3.0]),), ((2, 2),))
        >>> frozen.positions_at(0, [(4, 4)]).reshape(4, 4)
        array([[2., 2., 0., 0.],
               [2., 2., 0., 0.],
               [0., 0., 6., 6.],
               [0., 0., 6., 6.]])
        """
        counts, (h, w) = self.positions[view], self.shapes[view]
        rows, cols = np.divmod(np.arange(h * w), w)
        for fh, fw in fine_shapes:
            fine = np.zeros(fh * fw, dtype=np.float64)
            for a in (0, 1):
                for b in (0, 1):
                    np.add.at(fine, np.minimum(2 * rows + a, fh - 1) * fw + np.minimum(2 * cols + b, fw - 1),
                              2.0 * counts)
            counts, h, w = fine, fh, fw
            rows, cols = np.divmod(np.arange(h * w), w)
        return counts
