"""The settings of the metrics: :class:`MetricSettings` (every number that defines them, returned
with the numbers by :func:`npmrf3d.analysis.metrics.evaluate`) and the size limits of the inputs."""

from __future__ import annotations

import dataclasses

import numpy as np

from ... import _validation as check

#: Smallest side (pixels or voxels) of an exemplar or a volume that :func:`evaluate` accepts.
MIN_SIDE = 4
#: Largest number of cells of a joint colour histogram; more channels get fewer bins each.
MAX_JOINT_CELLS = 2**16


@dataclasses.dataclass(frozen=True)
class MetricSettings:
    """Every number that defines the metrics (``docs/metrics.md``).

    Attributes
    ----------
    bins : int
        Bins of the grey-level histogram and of each per-channel histogram, evenly spaced over
        the exemplar's range of that channel (volume values outside it count in the end bins).
    joint_bins : int
        Bins per channel of the joint colour histogram (C > 1); reduced to
        ``floor(MAX_JOINT_CELLS ** (1 / C))`` when ``joint_bins ** C`` would exceed
        ``MAX_JOINT_CELLS`` (C > 5).
    eps : float
        Added to every bin *probability* of both histograms before renormalising, so empty
        bins stay finite: ``p = (h / sum(h) + eps) / (1 + bins * eps)``.
    max_lag : int
        Largest autocorrelation lag along each axis (lags ``-L..L``); reduced per view to
        ``min(max_lag, side // 2)`` over the exemplar's and the slices' sides.
    gradient_sigma : float
        Gaussian pre-smoothing (pixels) before the 3x3 Sobel gradient of the structure tensor
        (0 = none).
    integration_sigma : float
        Gaussian integration scale (pixels) of the structure tensor's entries.
    orientation_bins : int
        Bins of the orientation histogram over ``[0, pi)``.
    coherence_weighting : bool
        Weight each pixel's orientation by its coherence ``(l1 - l2) / (l1 + l2)`` (0 in flat
        regions, 1 along a perfect edge); False = every pixel counts once.
    patch : int
        Side of the square patches compared by the sliced Wasserstein distance; reduced to the
        smallest side of the exemplar and the slices when larger.
    centre_patches : bool
        Subtract each patch's own mean (per channel) before projecting, so the distance measures
        local structure rather than the grey-level histogram (which ``histogram_kl`` covers).
        With raw patches, random projections of many pixels average independent values out and
        the distance becomes mostly a histogram distance (``docs/metrics.md``).
    projections : int
        Number of random unit directions of the sliced Wasserstein distance.
    max_patches : int
        At most this many patches per side of the comparison (a seeded random subset).
    seed : int
        Seed of the projections and of the patch subsets (fixed, so results are repeatable).
    """

    bins: int = 32
    joint_bins: int = 8
    eps: float = 1e-10
    max_lag: int = 32
    gradient_sigma: float = 1.0
    integration_sigma: float = 2.0
    orientation_bins: int = 18
    coherence_weighting: bool = True
    patch: int = 5
    centre_patches: bool = True
    projections: int = 64
    max_patches: int = 20_000
    seed: int = 0

    def __post_init__(self) -> None:
        check.integer("bins", self.bins, low=2)
        check.integer("joint_bins", self.joint_bins, low=2)
        check.real("eps", self.eps, low=0.0, high=1.0)
        check.integer("max_lag", self.max_lag, low=1)
        check.real("gradient_sigma", self.gradient_sigma, low=0.0)
        check.real("integration_sigma", self.integration_sigma, low=0.0, low_open=True)
        check.integer("orientation_bins", self.orientation_bins, low=2)
        for name in ("coherence_weighting", "centre_patches"):
            value = getattr(self, name)
            if not isinstance(value, (bool, np.bool_)):
                check.fail(f"{name} must be True or False; got {value!r}")
        check.integer("patch", self.patch, low=1)
        check.integer("projections", self.projections, low=1)
        check.integer("max_patches", self.max_patches, low=2)
        check.integer("seed", self.seed, low=0)


DEFAULT_SETTINGS = MetricSettings()
