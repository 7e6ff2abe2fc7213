"""Input-versus-output measures (docs/metrics.md), per constrained view.

The exemplar of a view is compared with *all* the volume's slices orthogonal to that view
(pooled), slices oriented like the exemplar (:func:`view_slices`). One module per family:

* :mod:`.histograms`: ``KL(exemplar || volume)`` of grey-level, per-channel and joint colour
  histograms (:func:`kl_divergence`, :func:`histogram_kl`, :func:`joint_histogram_kl`);
* :mod:`.autocorrelations`: the L2 distance of the normalised grey autocorrelations
  (:func:`autocorrelation`, :func:`autocorrelation_error`);
* :mod:`.orientation`: the structure tensor's orientation histogram and its KL
  (:func:`structure_tensor`, :func:`orientation_field`, :func:`orientation_kl`);
* :mod:`.patches`: the sliced Wasserstein distance of patches, at one scale or several
  (:func:`sliced_wasserstein`, :func:`multiscale_sliced_wasserstein`);
* :mod:`.two_point`: two-point correlation and the two-point shape error
  (:func:`two_point_correlation`, :func:`two_point_shape_error`);
* :mod:`.registry`: :data:`METRIC_FUNCTIONS`, the registry :func:`evaluate` loops over, and
  :func:`view_histograms`; :mod:`.inputs` (validation, :func:`view_slices`) and
  :mod:`.settings` (:class:`MetricSettings`) serve them all.

One entry point, :func:`evaluate`, returns the four numbers of :data:`METRICS` per view and
their mean over the views; every setting (bins, epsilon, lags, scales, patch size, seed) is in
:class:`MetricSettings` and is returned with the numbers. ``docs/metrics.md`` gives the
definitions; ``tests/test_metrics.py`` checks each against an independent implementation.
Lower is better for every metric; 0 means "indistinguishable by this measure".

Units: images are compared in the units the synthesiser uses, so integer inputs are scaled as
:func:`npmrf3d.model.exemplar.load_exemplar` does (``uint8 / 255``, ``uint16 / 65535``, ``bool`` to
0/1); float inputs are taken as they are. Grey level = mean of the channels.

Examples
--------
>>> import numpy as np
>>> from npmrf3d import metrics
>>> exemplar = np.random.default_rng(0).random((16, 16))
>>> stacked = np.stack([exemplar] * 8)           # every right slice volume[i] is the exemplar
>>> result = metrics.evaluate(stacked, {"right": exemplar})
>>> sorted(result["per_view"]) == ["right"] and sorted(result["mean"]) == sorted(metrics.METRICS)
True
>>> [round(result["mean"][name], 6) for name in metrics.METRICS[:3]]
[0.0, 0.0, 0.0]
"""

from __future__ import annotations

from .autocorrelations import autocorrelation, autocorrelation_error, effective_max_lag
from .histograms import channel_histogram_kl, histogram_kl, joint_histogram_kl, kl_divergence
from .inputs import view_slices
from .orientation import orientation_field, orientation_histogram, orientation_kl, structure_tensor
from .patches import multiscale_sliced_wasserstein, patch_sample, sliced_wasserstein, wasserstein_1d
from .registry import METRIC_FUNCTIONS, METRICS, evaluate, largest_value_share, view_histograms
from .settings import DEFAULT_SETTINGS, MIN_SIDE, MetricSettings
from .two_point import SHAPE_REFERENCES, two_point_correlation, two_point_shape_error

__all__ = [
    "DEFAULT_SETTINGS",
    "METRICS",
    "METRIC_FUNCTIONS",
    "MIN_SIDE",
    "MetricSettings",
    "SHAPE_REFERENCES",
    "autocorrelation",
    "autocorrelation_error",
    "channel_histogram_kl",
    "effective_max_lag",
    "evaluate",
    "histogram_kl",
    "joint_histogram_kl",
    "kl_divergence",
    "largest_value_share",
    "orientation_field",
    "orientation_histogram",
    "orientation_kl",
    "patch_sample",
    "multiscale_sliced_wasserstein",
    "sliced_wasserstein",
    "structure_tensor",
    "two_point_correlation",
    "two_point_shape_error",
    "view_histograms",
    "view_slices",
    "wasserstein_1d",
]
