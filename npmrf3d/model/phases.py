"""The phase histogram of the 3D-exemplar method (``volume-lh``): this project's addition after
the histogram matching of Kopf et al. 2007 (the vector-field deformation method, IET Image
Processing 2012, has none), which keeps a scan's phase fractions where the correction alone
lets a thin minority phase erode.

The exemplar's phases (:func:`phase_classes`), the phase mix a coarse coordinate stands for
(:func:`phase_footprint`), the volume's relative error per phase (:func:`phase_error`), and the
cost a candidate pays (:func:`class_balance`), driven by :class:`PhaseControl`: a price per
phase (an integral of the error, :func:`next_prices`) and a gain that halves when the error
flips sign between sub-passes (``docs/volume.md``, "The phase histogram's gain").

The same control drives the 2D methods' value histogram (:func:`bin_phases`,
:func:`bin_phase_error`, :func:`phase_prior_target`): the two sides of each channel's Otsu split
of the exemplars' value histogram, priced through the histogram prior (``phase_weight``,
``docs/segmented.md``, "Phase control (`phase_weight`)").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .kcoherence import pca_project
from .otsu import otsu_split, otsu_threshold

__all__ = ["MAX_PHASES", "PRICE_STEPS", "SOFT_WIDTH", "PhaseControl", "bin_phase_error", "bin_phases",
           "class_balance", "next_prices", "phase_classes", "phase_error", "phase_footprint", "phase_membership",
           "phase_prior_target"]

#: An exemplar with at most this many distinct values is a segmented (labelled) one.
MAX_PHASES = 8


#: A grey exemplar's phases are soft: a voxel's share of the bright side ramps from 0 to 1 over
#: this fraction of the distance between the two sides' mean values, centred on the Otsu
#: threshold, so the voxels at the threshold (a soil's grey matrix) belong to both sides and are
#: not pushed across it (docs/volume.md, "Soft sides of a grey scan's threshold"); 0 = hard sides.
SOFT_WIDTH = 0.25


def _phase_values(exemplar: np.ndarray, lo, hi, phases: int):
    """The value of every exemplar voxel (first principal component of the channels), those of
    the valid box, and the phase edges (between distinct values for a segmented exemplar, else
    Otsu's threshold); the last item says whether it is segmented."""
    ex = np.asarray(exemplar, dtype=np.float64)
    flat = ex.reshape(-1, ex.shape[-1])
    flat = pca_project(flat, 1)[2][:, 0] if flat.shape[1] > 1 else flat[:, 0]
    values = flat.reshape(ex.shape[:3])
    box = values[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1].ravel()
    distinct = np.unique(box)
    if len(distinct) <= phases:
        return values, box, (distinct[1:] + distinct[:-1]) / 2, True
    return values, box, np.array([otsu_threshold(box)]), False


def phase_membership(exemplar: np.ndarray, lo, hi, phases: int = MAX_PHASES,
                     width: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each exemplar voxel's share of every phase, ``(P, D, H, W)`` float32, and each phase's share
    of the valid box (float64, every share > 0): one-hot :func:`phase_classes` for a segmented
    exemplar; for a grey one the bright side's share ``clip((v - t) / w + 1/2, 0, 1)``, ``t``
    Otsu's threshold and ``w`` = ``width`` (default :data:`SOFT_WIDTH`) times the difference of
    the two sides' mean values (the dark side's share its complement)."""
    width = SOFT_WIDTH if width is None else float(width)
    values, box, edges, is_segmented = _phase_values(exemplar, lo, hi, phases)
    ramp = 0.0
    if not is_segmented:
        t = float(edges[0])
        above, below = box[box > t], box[box <= t]
        ramp = width * (float(above.mean()) - float(below.mean())) if above.size and below.size else 0.0
    if ramp <= 0.0:
        classes, share = _hard_phases(values, box, edges)
        return phase_footprint(classes, len(share), 1), share
    bright = np.clip((values - t) / ramp + 0.5, 0.0, 1.0)
    member = np.stack([1.0 - bright, bright]).astype(np.float32)
    inner = member[:, lo[0]:hi[0] + 1, lo[1]:hi[1] + 1, lo[2]:hi[2] + 1].reshape(2, -1)
    return member, np.maximum(inner.astype(np.float64).mean(axis=1), 1.0 / box.size)


def _hard_phases(values: np.ndarray, box: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The phase of every voxel between ``edges`` (int64) and each phase's share of ``box``."""
    classes = np.searchsorted(edges, values, side="right").astype(np.int64)
    share = np.bincount(np.searchsorted(edges, box, side="right"), minlength=len(edges) + 1) / box.size
    return classes, np.maximum(share, 1.0 / box.size)


def phase_classes(exemplar: np.ndarray, lo, hi, phases: int = MAX_PHASES) -> tuple[np.ndarray, np.ndarray]:
    """The phase of every exemplar voxel, ``(D, H, W)`` int64, and each phase's share of the
    valid box ``[lo, hi]`` (float64, every share > 0).

    The value is the voxel's projection on the first principal component of the channels (the
    value itself for one channel). An exemplar with at most ``phases`` distinct values (a
    segmented scan) has one class per value; any other has two, the sides of the Otsu threshold
    of the valid box's values. (Eight quantile bins of a grey scan were tried and not kept: a
    voxel then changes bin for a tiny change of value, and the histogram turned smooth tissue
    into speckle, ``docs/volume.md``.)"""
    values, box, edges, _ = _phase_values(exemplar, lo, hi, phases)
    return _hard_phases(values, box, edges)


def phase_footprint(classes: np.ndarray, phases: int, h: int) -> np.ndarray:
    """The phase mix a level-``h`` coordinate stands for, ``(phases, D, H, W)`` float32: the share
    of each phase among the exemplar voxels its descendants at the finest level copy.

    ``classes``: every exemplar voxel's phase ``(D, H, W)`` int, or its share of each phase
    ``(phases, D, H, W)`` float (:func:`phase_membership`). Up-sampling puts the children of ``u``
    at ``u + floor(h' (delta - 1/2) + 1/2)`` (``h'`` the children's spacing), so without jitter
    or deformation the finest-level descendants of a level-``h`` coordinate cover ``u + [1 -
    h/2, h/2]`` on every axis: a box of ``h`` voxels (faces clamped, as the coordinates are). At
    the finest level (``h = 1``) it is the voxel's own phase (one-hot for ``classes``)."""
    classes = np.asarray(classes)
    if classes.ndim == 4:
        mix = np.ascontiguousarray(classes, dtype=np.float32)
    else:
        mix = (classes[None] == np.arange(phases)[:, None, None, None]).astype(np.float32)
    if h == 1:
        return mix
    for axis in (1, 2, 3):  # the box [u + 1 - h/2, u + h/2]: scipy's window of an even size, origin -1
        mix = ndimage.uniform_filter1d(mix, size=h, axis=axis, mode="nearest", origin=-1)
    return mix


#: The phase histogram's integral time, in sub-passes: every sub-pass a phase's price moves by
#: its relative error over this many (``next_prices``).
PRICE_STEPS = 4


def phase_error(coords: np.ndarray, footprint: np.ndarray, share: np.ndarray) -> np.ndarray:
    """Each phase's relative excess in the volume, ``v_c / share_c - 1`` (float64 per phase),
    ``v_c = mean f_c(S[p])`` over the volume's voxels (``footprint``: :func:`phase_footprint`)."""
    picked = footprint[:, coords[..., 0], coords[..., 1], coords[..., 2]]
    return picked.reshape(len(share), -1).mean(axis=1) / share - 1.0


def next_prices(prices: np.ndarray, error: np.ndarray) -> np.ndarray:
    """The phase histogram's integral term after one more sub-pass: ``prices + error /
    PRICE_STEPS``, shifted so that the cheapest phase costs 0 (only the differences between
    phases change a decision)."""
    moved = np.asarray(prices, dtype=np.float64) + np.asarray(error, dtype=np.float64) / PRICE_STEPS
    return moved - moved.min()


def class_balance(footprint: np.ndarray, error: np.ndarray, prices: np.ndarray, weight: float) -> np.ndarray:
    """The phase-histogram cost of every exemplar voxel, ``(D, H, W)`` float64: ``weight *
    sum_c f_c(u) (max(0, e_c) + lambda_c)``, ``f_c(u)`` the share of phase ``c`` that voxel ``u``
    stands for at this level (:func:`phase_footprint`; one-hot at the finest level), ``e_c`` the
    volume's relative excess of the phase (:func:`phase_error`) and ``lambda_c`` its price, the
    running sum of the errors (:func:`next_prices`).

    This project's addition, after the histogram matching of Kopf et al. 2007 (the vector-field
    deformation method has none): with it the phase fractions of a segmented scan stay those of the
    exemplar, where the correction alone lets a thin minority phase (a rock's pores) erode level by
    level (``docs/volume.md``). The excess alone (a proportional rule) left a steady deficit of the
    minority phase; the price, an integral of the error carried across passes and levels, removes
    it. Counting a coarse coordinate by the phases of its descendants, not by its own voxel, keeps
    the share through the up-sampling."""
    per_phase = np.maximum(0.0, error) + prices
    return np.ascontiguousarray(weight * np.tensordot(per_phase, footprint, axes=1))


#: The gain's rule (:class:`PhaseControl`): an error flip counts when both errors' largest
#: phase error is above this (relative; smaller flips are noise around the target) ...
FLIP_TOLERANCE = 0.01
#: ... and halves the gain; a sub-pass without a flip multiplies it by this, up to 1.
GAIN_RECOVERY = 1.1


@dataclass
class PhaseControl:
    """The phase histogram's running state, carried from sub-pass to sub-pass, level to level
    and into the checkpoint: each phase's price (:func:`next_prices`), the last sub-pass's error
    and the gain that scales both the cost and the price's step.

    Why a gain (docs/volume.md, "The phase histogram's gain"): on a noisy grey exemplar (a woven
    composite's micro-CT) nearly every voxel is indifferent between the two sides of the Otsu
    threshold, so one sub-pass answers an excess of a phase by swapping most of its eighth of the
    voxels to the other; the error then flipped sign every sub-pass with a growing amplitude (0.03
    up to 0.38), and the parity sub-passes printed it into the volume as a period-2 grid of flat
    grey. Halving the gain at each flip (both errors above :data:`FLIP_TOLERANCE`) and letting it
    grow back by :data:`GAIN_RECOVERY` otherwise damps that oscillation and leaves a steady approach
    (the segmented rocks it was tuned on) at gain 1."""

    prices: np.ndarray
    last_error: np.ndarray
    gain: float = 1.0

    @classmethod
    def start(cls, phases: int) -> "PhaseControl":
        """The state at the start of a run: no prices, no error yet, gain 1."""
        return cls(np.zeros(phases), np.zeros(phases), 1.0)

    def step(self, error: np.ndarray) -> None:
        """One more sub-pass with the volume's relative ``error`` per phase: update the gain,
        then the prices by the gain times the error (:func:`next_prices`)."""
        error = np.asarray(error, dtype=np.float64)
        flipped = (float(np.dot(error, self.last_error)) < 0.0
                   and min(np.abs(error).max(), np.abs(self.last_error).max()) > FLIP_TOLERANCE)
        self.gain = self.gain * 0.5 if flipped else min(1.0, self.gain * GAIN_RECOVERY)
        self.prices = next_prices(self.prices, self.gain * error)
        self.last_error = error.copy()

    def cost(self, footprint: np.ndarray, weight: float) -> np.ndarray:
        """The cost of every exemplar voxel after the last :meth:`step` (:func:`class_balance` of
        its error at ``weight`` times the gain)."""
        return class_balance(footprint, self.last_error, self.prices, weight * self.gain)

    def phase_costs(self, weight: float) -> np.ndarray:
        """Each phase's cost after the last :meth:`step`, ``weight * gain * (max(0, e_c) +
        lambda_c)`` (what :func:`class_balance` charges a voxel of that one phase)."""
        return weight * self.gain * (np.maximum(0.0, self.last_error) + self.prices)

    def to_array(self) -> np.ndarray:
        """``[prices, last error, gain]`` as one float64 vector, for the checkpoint."""
        return np.concatenate([self.prices, self.last_error, [self.gain]])

    @classmethod
    def from_array(cls, saved: np.ndarray, phases: int) -> "PhaseControl":
        """The state :meth:`to_array` saved; a state of ``phases`` numbers holds the prices alone
        (no error yet, gain 1)."""
        saved = np.asarray(saved, dtype=np.float64)
        if saved.size == phases:
            return cls(saved.copy(), np.zeros(phases), 1.0)
        if saved.size != 2 * phases + 1:
            raise ValueError(f"a phase-histogram state of {saved.size} numbers does not fit {phases} phases")
        return cls(saved[:phases].copy(), saved[phases:2 * phases].copy(), float(saved[-1]))


# --------------------------------------------------------------------------- 2D value histograms


def bin_phases(target: np.ndarray) -> np.ndarray:
    """The phase of every value bin, ``(C, B)`` int64 (0 below, 1 above each channel's Otsu
    split of the exemplars' histogram ``target`` ``(C, B)``; :func:`npmrf3d.model.otsu.otsu_split`),
    all 0 for a channel whose values fill one bin (nothing to split)."""
    target = np.asarray(target, dtype=np.float64)
    phases = np.zeros(target.shape, dtype=np.int64)
    for c, counts in enumerate(target):
        if np.count_nonzero(counts) > 1:
            phases[c, otsu_split(counts) + 1:] = 1
    return phases


def bin_phase_error(hist: np.ndarray, target: np.ndarray, phases: np.ndarray) -> np.ndarray:
    """Each channel's relative excess per phase, ``(C, 2)`` float64: ``v_c / t_c - 1`` for the
    volume's share ``v`` of the bins of a phase in ``hist`` and the exemplars' ``t`` in
    ``target`` (0 for a phase the exemplars lack)."""
    error = np.zeros((len(hist), 2))
    for c in range(len(hist)):
        v = np.bincount(phases[c], weights=hist[c], minlength=2) / max(float(np.sum(hist[c])), 1e-300)
        t = np.bincount(phases[c], weights=target[c], minlength=2) / max(float(np.sum(target[c])), 1e-300)
        error[c] = np.where(t > 0, v / np.where(t > 0, t, 1.0) - 1.0, 0.0)
    return error


def phase_prior_target(target: np.ndarray, phases: np.ndarray, costs: np.ndarray, prior: float) -> np.ndarray:
    """The target histogram through which the histogram prior charges each phase its cost:
    ``T_c(b) exp(-costs[c, phase_c(b)] / prior)``, so the prior ``prior * log(T' / H)`` of a texel
    is the plain prior minus its phase's cost (:meth:`PhaseControl.phase_costs`, ``(C, 2)``)."""
    if prior <= 0.0:
        return np.asarray(target, dtype=np.float64)
    cost = np.take_along_axis(np.asarray(costs, dtype=np.float64), phases, axis=1)
    return np.ascontiguousarray(np.asarray(target, dtype=np.float64) * np.exp(-cost / prior))
