"""The optimisation phase of NP_K (Kopf et al. 2007; docs/kopf.md): every voxel set to the
re-weighted average of the exemplar texels its neighbourhoods' matches assign to it, with
histogram matching, voxel constraints and optional mean-shift (:func:`optimisation_phase`; the
compiled loops are :mod:`npmrf3d._kernels.kopf`), and the per-channel histograms it matches.
"""

from __future__ import annotations

import types
from collections.abc import Sequence

import numpy as np

from .._kernels import kopf as _k
from .exemplar import pack_rows
from .kopf_search import NeighbourhoodIndex

__all__ = ["MEAN_SHIFT_ITERATIONS", "SWEEP_CHUNK", "PackedExemplars", "channel_bins", "channel_histograms",
           "optimisation_phase", "pack_exemplars"]

#: Mean-shift steps per voxel (when a bandwidth is set).
MEAN_SHIFT_ITERATIONS = 8
#: Voxels gathered per optimisation batch.
SWEEP_CHUNK = 1 << 15


def channel_bins(values: np.ndarray, lo: np.ndarray, scale: np.ndarray, bins: int) -> np.ndarray:
    """Histogram bin of each channel value: ``clip(int((x - lo) * scale), 0, bins - 1)``
    (the same formula as the compiled sweep).

    Parameters
    ----------
    values : (..., C) ndarray
    lo, scale : (C,) float64 ndarrays

    Returns
    -------
    (..., C) int32 ndarray
    """
    b = np.trunc((values.astype(np.float64) - lo) * scale)
    return np.clip(b, 0, bins - 1).astype(np.int32)


def channel_histograms(values: np.ndarray, lo, scale, bins: int) -> np.ndarray:
    """Per-channel bin counts of ``values`` (..., C) as a (C, bins) int64 array."""
    b = channel_bins(values, lo, scale, bins).reshape(-1, values.shape[-1])
    return np.stack([np.bincount(b[:, c], minlength=bins) for c in range(b.shape[1])]).astype(np.int64)


class PackedExemplars(types.SimpleNamespace):
    """The views' exemplars of one level packed for the kernels."""


def pack_exemplars(indices: Sequence[NeighbourhoodIndex], lo, scale, bins) -> PackedExemplars:
    ex_flat, offsets = pack_rows([idx.exemplar for idx in indices])
    return PackedExemplars(
        flat=ex_flat,
        bins=np.ascontiguousarray(channel_bins(ex_flat, lo, scale, bins)),
        offsets=offsets,
        pwidth=np.array([idx.pwidth for idx in indices], dtype=np.int64),
        ewidth=np.array([idx.exemplar.shape[1] for idx in indices], dtype=np.int64),
    )


def optimisation_phase(volume: np.ndarray, assign: np.ndarray, omega: np.ndarray,
                       view_axes: np.ndarray, packed: PackedExemplars, *, window: int, grid: int,
                       order: np.ndarray, hist: np.ndarray, hist_target: np.ndarray,
                       histogram_weight: float, lo: np.ndarray, scale: np.ndarray, bins: int,
                       bandwidth: float = 0.0, constraint=None, tau=None) -> float:
    """Set every voxel (in ``order``) to the re-weighted average of its exemplar texels.

    ``volume`` and ``hist`` (per-channel bin counts of ``volume``) are updated in place;
    ``hist_target`` holds the exemplar histograms as fractions. A contributing texel ``e`` has its
    weight divided by ``1 + histogram_weight * sum_c max(0, hist[c, b] - N * hist_target[c, b])``
    (``b = b_c(e)``, ``N`` voxels: both histograms as counts over the volume). Returns the mean
    absolute change per value.
    """
    n_views = assign.shape[0]
    cap = n_views * (-(-window // grid)) ** 2
    rows = np.empty((min(SWEEP_CHUNK, order.size), cap), dtype=np.int64)
    weights = np.empty(rows.shape, dtype=np.float64)
    counts = np.empty(rows.shape[0], dtype=np.int64)
    n_voxels = volume.shape[0] * volume.shape[1] * volume.shape[2]
    use_constraint = constraint is not None
    if not use_constraint:
        constraint = np.zeros((1, 1, 1, volume.shape[3]), dtype=np.float32)
        tau = np.zeros((1, 1, 1), dtype=np.float32)
    change = 0.0
    for start in range(0, order.size, SWEEP_CHUNK):
        chunk = order[start:start + SWEEP_CHUNK]
        m = chunk.size
        _k.gather_texels(chunk, assign, omega, view_axes, packed.ewidth, window, grid, rows[:m],
                         weights[:m], counts[:m])
        change += _k.optimise_sweep(volume, chunk, rows[:m], weights[:m], counts[:m], packed.flat,
                                    packed.bins, hist, hist_target, float(histogram_weight) * n_voxels, lo,
                                    scale, bins, constraint, tau, use_constraint, float(bandwidth),
                                    MEAN_SHIFT_ITERATIONS)
    return change / max(1, order.size * volume.shape[3])
