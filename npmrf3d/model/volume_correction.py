"""The correction passes of the volume-lh method: every voxel's exemplar coordinate replaced by
the best candidate of its neighbours' similarity sets, by the nearest neighbourhood in appearance
space with the position and phase histograms (:func:`correction_pass`) or by the Parzen LCPDF of
the ``npmrf-3d`` method (:func:`parzen_pass`); the compiled loops are
:mod:`npmrf3d._kernels.volume_lh`.
"""

from __future__ import annotations

import numpy as np

from .. import _validation as check
from .._kernels import volume_lh as _k
from .phases import PhaseControl, phase_error

__all__ = ["NEIGHBOURHOODS", "cell_usage", "correction_pass", "parzen_pass", "set_positions", "usage_scale",
           "window_offsets"]

#: The synthesis neighbourhoods: the paper's 8 diagonal neighbours, or those and the 6 faces.
NEIGHBOURHOODS = {"diagonal": _k.DIAGONALS, "faces": np.concatenate([_k.DIAGONALS, _k.FACES])}


def correction_pass(coords: np.ndarray, frames: np.ndarray, feat: np.ndarray, kset: np.ndarray,
                    h: int, lo, hi, offsets: np.ndarray = _k.DIAGONALS,
                    usage: float = 0.0, balance: float = 0.0,
                    phases: tuple[np.ndarray, np.ndarray] | None = None,
                    control: PhaseControl | None = None) -> tuple[np.ndarray, float]:
    """One correction pass: the 8 parity sub-passes in a fixed order; returns the coordinates and
    the mean matching score.

    A sub-pass reads ``coords`` and writes its parity class into ``out``, which is then copied
    back into ``coords`` (an eighth of the voxels), so every sub-pass reads its input unchanged.
    ``usage`` is the strength of the position histogram (:func:`cell_usage`), recounted before
    every sub-pass; 0 is the paper's rule. ``balance`` is the strength of the phase histogram
    (:func:`npmrf3d.model.phases.class_balance`, of ``phases = (phase_footprint(...),
    share)``), also recounted before every sub-pass; ``control``
    (:class:`npmrf3d.model.phases.PhaseControl`, ``PhaseControl.start(phases)`` at the start
    of a run) holds its prices and gain, is **updated in place** every sub-pass and is carried
    from pass to pass and level to level."""
    coords = np.array(coords, dtype=np.int64, order="C")  # a copy: the caller's array stays
    out = np.empty_like(coords)
    feat = np.ascontiguousarray(feat)
    positions = set_positions(kset, feat.shape[:3])
    cost = np.zeros(coords.shape[:3])
    scale = usage_scale(feat, offsets) if usage or balance else 0.0
    weight = float(usage) * scale
    counts, even = np.zeros((1, 1, 1)), 1.0  # read only when weight > 0
    bias = np.zeros((1, 1, 1))  # none
    if balance and (phases is None or control is None):
        check.fail("balance > 0 needs the exemplar's phases and their control state "
                   "(phases=(phase_footprint(...), share), control=PhaseControl.start(len(share)))")
    for parity in np.ndindex(2, 2, 2):
        if weight:
            counts, even = cell_usage(coords, feat.shape[:3], h, lo, hi)
        if balance:
            control.step(phase_error(coords, *phases))
            bias = control.cost(phases[0], float(balance) * scale)
        _k.correct(coords, out, frames, feat, positions, h, lo, hi, offsets,
                   np.array(parity, dtype=np.int64), cost, counts, even, weight, bias)
        cls = tuple(slice(p, None, 2) for p in parity)
        coords[cls] = out[cls]
    return coords, float(cost.mean())


def usage_scale(feat: np.ndarray, offsets: np.ndarray) -> float:
    """The distance scale of the position-histogram penalty: half the expected matching distance
    of two random exemplar voxels, ``len(offsets) * sum_e var(feat[..., e])``."""
    return float(len(offsets) * feat.reshape(-1, feat.shape[-1]).var(axis=0).sum())


def cell_usage(coords: np.ndarray, shape, h: int, lo, hi) -> tuple[np.ndarray, float]:
    """The position histogram of a level: how many voxels' coordinates fall in each ``h``-cell
    ``u // h`` of the exemplar (float64, ``ceil(shape / h)``), and ``even``, the count of every
    cell that meets the valid box if all were used equally.

    This project's addition after Chen & Wang 2010's position histogram (the vector-field deformation method has none, and
    relies on a stationary exemplar): the correction adds ``usage * s * max(0, c / even - 1)`` to
    a candidate's distance (``s``: :func:`usage_scale`), so that no part of the exemplar is
    copied far more often than the rest. Without it a non-stationary exemplar (a scan with a
    homogeneous region) collapses onto that region: uniform neighbourhoods match each other best
    (``docs/volume.md``). Cells of the level's spacing make ``even`` the same at every level,
    the ratio of output voxels to exemplar voxels."""
    cells = tuple(-(-int(n) // h) for n in shape)
    flat = np.ravel_multi_index(tuple((coords.reshape(-1, 3) // h).T), cells)
    counts = np.bincount(flat, minlength=int(np.prod(cells))).astype(np.float64).reshape(cells)
    valid = int(np.prod([int(hi[a]) // h - int(lo[a]) // h + 1 for a in range(3)]))
    return counts, coords[..., 0].size / valid


def set_positions(kset: np.ndarray, shape) -> np.ndarray:
    """The similarity sets ``(D * H * W, k)`` of flat indices as positions ``(D * H * W, k, 3)``
    int64, the form :func:`npmrf3d._kernels.volume_lh.correct` reads."""
    return np.ascontiguousarray(np.stack(np.unravel_index(kset, tuple(shape)), axis=-1), dtype=np.int64)


def window_offsets(window: int) -> np.ndarray:
    """The ``window^3 - 1`` offsets of a cube without its centre, lexicographic."""
    r = window // 2
    return np.array([o for o in np.ndindex(window, window, window) if o != (r, r, r)], dtype=np.int64) - r


def parzen_pass(coords, frames, feat, values, kset, h: int, lo, hi, offsets, window: int,
                adaptive: float, centre_h2: float) -> tuple[np.ndarray, float]:
    """:func:`correction_pass` with the Parzen decision (:func:`_kernels.volume.correct_parzen`)."""
    coords = np.ascontiguousarray(coords, dtype=np.int64)
    cost = np.zeros(coords.shape[:3])
    woff = window_offsets(window)
    for parity in np.ndindex(2, 2, 2):
        out = coords.copy()
        _k.correct_parzen(coords, out, frames, feat, values, kset, h, lo, hi, offsets, woff,
                          np.array(parity, dtype=np.int64), adaptive, centre_h2, cost)
        coords = out
    return coords, float(cost.mean())
