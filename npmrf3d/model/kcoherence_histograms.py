"""The k-coherence engine's histograms: the solver's position and value histograms
(:func:`position_histogram`, :class:`ValueHistogram`) and what a ``blockwise`` run's finer
levels read in their place (:class:`PilotHistograms`).

Used by :mod:`npmrf3d.model.kcoherence_engine`; bins of values by the compiled
:func:`npmrf3d._kernels.kcoherence.value_bins`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._kernels import kcoherence as _search

__all__ = ["PilotHistograms", "ValueHistogram", "pack_pilot", "pilot_length", "position_histogram", "unpack_pilot",
           "value_counts", "value_scale"]


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


class PilotHistograms(NamedTuple):
    """What one finer level of a ``blockwise`` run reads in place of its own histograms: the
    live histograms of a *pilot* region of that level, recorded before each batch of each pass.

    A block cannot keep the default's histograms (every batch of a pass reads the counts of the
    whole level so far). The pilot -- the dependency cone of one fixed block, made once after the
    levels that run whole, with its own histograms updated between batches as the default does -- shows
    how those histograms move through a level; every block then reads the pilot's counts at the
    same batch, scaled to the level's whole grid, so its decisions feel the pull the whole
    volume's would, and depend on nothing outside their cone.

    Attributes
    ----------
    positions : (iterations, batches, P) float64
        Per pass and batch the position counts (views packed), per voxel of the pilot region.
    values : (iterations, batches, C, bins) float64
        The value histograms, in units of an even bin's share.
    targets : (iterations, C, bins) float64
        Per pass the value prior's target (the phase control's, when it is on).
    """

    positions: np.ndarray
    values: np.ndarray
    targets: np.ndarray

    @staticmethod
    def shapes(iterations: int, batches: int, pixels: int, channels: int, bins: int) -> tuple[tuple[int, ...], ...]:
        """The shapes of the three arrays of a record."""
        return (iterations, batches, pixels), (iterations, batches, channels, bins), (iterations, channels, bins)

    @classmethod
    def empty(cls, *layout) -> "PilotHistograms":
        """A record to fill, zeros: ``layout`` as :meth:`shapes` takes it."""
        return cls(*(np.zeros(shape) for shape in cls.shapes(*layout)))


def pack_pilot(records, layout) -> np.ndarray:
    """The pilot's records of every level in ``layout`` (``(level, iterations, batches, pixels,
    channels, bins)`` each) as one float64 array (a checkpoint member); empty without records."""
    if not records:
        return np.zeros(0, dtype=np.float64)
    return np.concatenate([a.ravel() for level, *_ in layout for a in records[level]])


def unpack_pilot(flat: np.ndarray, layout) -> dict | None:
    """The records :func:`pack_pilot` packed, by level; None for an empty array."""
    if flat.size == 0:
        return None
    records, at = {}, 0
    for level, *shape_of in layout:
        parts = []
        for shape in PilotHistograms.shapes(*shape_of):
            n = int(np.prod(shape))
            parts.append(np.asarray(flat[at:at + n], dtype=np.float64).reshape(shape))
            at += n
        records[level] = PilotHistograms(*parts)
    return records


def pilot_length(layout) -> int:
    """The length of :func:`pack_pilot`'s array for ``layout``."""
    return sum(int(np.prod(shape)) for _, *shape_of in layout for shape in PilotHistograms.shapes(*shape_of))
