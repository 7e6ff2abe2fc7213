"""The registry of the metrics (:data:`METRIC_FUNCTIONS`, in the order of :data:`METRICS`) and
:func:`evaluate`, which computes them per view; :func:`view_histograms` for plotting."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from ... import _validation as check
from ...model.neighbourhood import VIEWS
from .autocorrelations import autocorrelation_metric
from .histograms import channel_histograms, histogram_metric, joint_bins
from .inputs import ViewPair, as_exemplar, as_volume, exemplars_by_view, grey_level, view_slices
from .orientation import orientation_histograms, orientation_metric
from .patches import sliced_wasserstein_metric
from .settings import DEFAULT_SETTINGS, MIN_SIDE, MetricSettings

#: The metric names, in the order of the report's columns.
METRICS: tuple[str, ...] = ("histogram_kl", "autocorrelation_l2", "orientation_kl",
                            "sliced_wasserstein")


def _check_sides(shape: tuple[int, ...], name: str) -> None:
    if min(shape) < MIN_SIDE:
        dims = "x".join(str(n) for n in shape)
        check.fail(f"{name} of size {dims} is too small for the metrics; every side must be at "
                   f"least {MIN_SIDE}")


def _prepare(volume: Any, exemplars: Any, views: Any) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The validated volume ``(N1, N2, N3, C)`` and view -> validated exemplar ``(H, W, C)``
    (an array given for several views is validated once)."""
    v = as_volume(volume)
    _check_sides(v.shape[:3], "volume")
    cache: dict[int, np.ndarray] = {}
    out = {}
    for view, raw in exemplars_by_view(exemplars, views).items():
        if id(raw) not in cache:
            name = f"exemplar of the {view} view"
            e = as_exemplar(raw, name)
            _check_sides(e.shape[:2], name)
            if e.shape[-1] != v.shape[-1]:
                check.fail(f"{name} has {e.shape[-1]} channel(s) but the volume has "
                           f"{v.shape[-1]}; give every exemplar the volume's channels")
            cache[id(raw)] = e
        out[view] = cache[id(raw)]
    return v, out


#: name -> ``metric(pair, settings) -> (value, details)``: what :func:`evaluate` computes per
#: view, in the order of :data:`METRICS` (a new metric is one function plus one line here).
METRIC_FUNCTIONS: dict[str, Callable[[ViewPair, MetricSettings], tuple[float, dict]]] = {
    "histogram_kl": histogram_metric,
    "autocorrelation_l2": autocorrelation_metric,
    "orientation_kl": orientation_metric,
    "sliced_wasserstein": sliced_wasserstein_metric,
}
assert tuple(METRIC_FUNCTIONS) == METRICS


def evaluate(volume: Any, exemplars: Any, *, views: Any = None,
             settings: MetricSettings | None = None) -> dict[str, Any]:
    """Compare each view's exemplar with all the volume's slices orthogonal to that view.

    Parameters
    ----------
    volume : (N1, N2, N3) or (N1, N2, N3, C) array
    exemplars : mapping view -> (H, W) or (H, W, C) array, or one array used for every view
        Each exemplar needs the volume's C channels; sides of at least :data:`MIN_SIDE`.
    views : str or sequence of str, optional
        Views to report, e.g. ``"front,top"``; default the mapping's keys (in the order front,
        right, top) or all three views for a single array.
    settings : MetricSettings, optional
        Default :data:`DEFAULT_SETTINGS`.

    Returns
    -------
    dict
        ``per_view``: view -> ``{name: float}`` for every name of :data:`METRICS`;
        ``mean``: the same names averaged over the views; ``settings``: every setting plus
        what was derived from the inputs (channels, grey definition, joint bins used);
        ``details``: view -> per-channel histogram KL, grey histogram KL, the lag and patch
        side actually used. For C = 1 ``histogram_kl`` is the grey-level KL (``bins`` bins);
        for C > 1 it is the joint colour KL (``joint_bins`` per channel).

    Raises
    ------
    ParameterError
        NaN/Inf values, wrong shapes, too small sides, channel mismatch, unknown or repeated
        view names, a view without an exemplar.
    """
    s = DEFAULT_SETTINGS if settings is None else settings
    if not isinstance(s, MetricSettings):
        check.fail(f"settings must be a MetricSettings; got {type(settings).__name__}")
    v, per_view_exemplars = _prepare(volume, exemplars, views)
    channels = v.shape[-1]
    joint = joint_bins(channels, s.joint_bins)
    per_view: dict[str, dict[str, float]] = {}
    details: dict[str, dict[str, Any]] = {}
    for view, e in per_view_exemplars.items():
        slices = view_slices(v, view)
        pair = ViewPair(e, slices, grey_level(e), grey_level(slices), joint)
        per_view[view], details[view] = {}, {}
        for name, metric in METRIC_FUNCTIONS.items():
            per_view[view][name], extra = metric(pair, s)
            details[view].update(extra)
        details[view].update({"exemplar_shape": list(e.shape), "slices": int(slices.shape[0])})
    mean = {name: float(np.mean([per_view[view][name] for view in per_view])) for name in METRICS}
    derived = {
        "channels": int(channels),
        "joint_bins_used": int(joint) if channels > 1 else None,
        "grey": "mean of the channels",
        "histogram": ("grey-level KL" if channels == 1 else "joint colour KL")
                     + "; bins evenly spaced over the exemplar's range, volume values "
                       "clipped into it",
        "autocorrelation": "per-image mean removed, covariances averaged over slices, "
                           "lags -L..L with L = min(max_lag, side // 2)",
        "orientation": "structure tensor: Gaussian(gradient_sigma) + 3x3 Sobel, "
                       "Gaussian(integration_sigma), mode reflect; angles in [0, pi)",
        "sliced_wasserstein": "mean over projections of exact W1 of projected patches"
                              + (" (each patch's channel means removed)"
                                 if s.centre_patches else ""),
        "max_lag_per_view": {view: d["max_lag"] for view, d in details.items()},
        "patch_per_view": {view: d["patch"] for view, d in details.items()},
    }
    return {"per_view": per_view, "mean": mean,
            "settings": {**dataclasses.asdict(s), **derived}, "details": details}


def view_histograms(volume: Any, exemplar: Any, view: str, *,
                    settings: MetricSettings = DEFAULT_SETTINGS) -> dict[str, Any]:
    """The histograms behind :func:`evaluate` for one view, for plotting.

    Returns
    -------
    dict
        ``values``: ``edges`` (C, bins + 1), ``exemplar`` and ``volume`` (C, bins)
        probabilities per channel (for C = 1 the grey histogram of ``histogram_kl``);
        ``orientation``: ``edges`` (orientation_bins + 1,), ``exemplar`` and ``volume``
        probabilities.
    """
    view = check.choice("view", view, VIEWS)
    v, exemplars = _prepare(volume, {view: exemplar}, None)
    e = exemplars[view]
    slices = view_slices(v, view)
    per_channel = channel_histograms(e, slices, settings.bins)
    orientation = orientation_histograms(grey_level(e), grey_level(slices), settings)
    return {
        "values": {"edges": np.array([np.linspace(lo, hi, settings.bins + 1) for lo, hi, _, _ in per_channel]),
                   "exemplar": np.array([a / a.sum() for _, _, a, _ in per_channel]),
                   "volume": np.array([b / b.sum() for _, _, _, b in per_channel])},
        "orientation": {"edges": np.linspace(0.0, np.pi, settings.orientation_bins + 1),
                        "exemplar": orientation[0], "volume": orientation[1]},
    }


def largest_value_share(volume: np.ndarray) -> float:
    """Share of voxels holding the most common value (1.0 = a constant volume)."""
    flat = volume.reshape(-1, volume.shape[-1])
    _, counts = np.unique(flat, axis=0, return_counts=True)
    return float(counts.max() / len(flat))
