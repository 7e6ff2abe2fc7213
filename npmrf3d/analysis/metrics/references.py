"""What a volume's metrics are read against (docs/metrics.md, "Reading the numbers"):

* the **structureless control**: voxels drawn independently from the exemplar's pixels (its
  histogram, no spatial structure), in the volume's shape. Each metric as a ratio to the
  control's (:func:`ratios`) is what docs/quality.md tabulates: 1 = no better than no
  structure, lower is better. The histogram KL is left out of the ratios: the control has the
  exemplar's histogram, so its KL is sampling noise.
* the **floor**: another crop of the same texture measured the same way, about what a perfect
  volume scores (:func:`floor`): the exemplar's right half as slices against its left half,
  with its own control. The benchmark's floor uses the other quadrants of a larger photograph;
  a single exemplar has only its halves.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .registry import METRICS, evaluate
from .settings import DEFAULT_SETTINGS, MIN_SIDE, MetricSettings

__all__ = ["RATIO_METRICS", "against_controls", "floor", "ratios", "structureless"]

#: The metrics reported as ratios to the control (all but the histogram KL, see above).
RATIO_METRICS: tuple[str, ...] = tuple(name for name in METRICS if name != "histogram_kl")


def structureless(exemplar: np.ndarray, shape, rng) -> np.ndarray:
    """The structureless control of ``shape`` (three sides): voxels drawn independently from
    the pixels of ``exemplar`` (H, W, C), float32 (N1, N2, N3, C).

    >>> structureless(np.ones((4, 4, 1), np.float32), (2, 3, 2), 0).shape
    (2, 3, 2, 1)
    """
    generator = np.random.default_rng(rng)
    flat = np.asarray(exemplar, dtype=np.float32).reshape(-1, exemplar.shape[-1])
    picks = generator.integers(0, len(flat), size=int(np.prod(shape)))
    return flat[picks].reshape(*(int(n) for n in shape), flat.shape[1])


def ratios(values: dict[str, float], control: dict[str, float]) -> dict[str, float]:
    """Each metric of :data:`RATIO_METRICS` divided by the control's (1.0 = no structure)."""
    return {name: float(values[name] / max(control[name], 1e-12)) for name in RATIO_METRICS}


def _grouped(exemplars: dict[str, np.ndarray]) -> list[dict[str, np.ndarray]]:
    """The views grouped by the exemplar they share (one control per distinct exemplar)."""
    groups: dict[int, dict[str, np.ndarray]] = {}
    for view, e in exemplars.items():
        groups.setdefault(id(e), {})[view] = e
    return list(groups.values())


def against_controls(result: dict[str, Any], shape, exemplars: dict[str, np.ndarray], *,
                     settings: MetricSettings = DEFAULT_SETTINGS) -> dict[str, Any]:
    """The control of a volume of ``shape`` whose :func:`~.registry.evaluate` is ``result``
    (against ``exemplars``, view -> (H, W, C)), and the volume's ratios to it.

    Returns
    -------
    dict
        ``control``: ``per_view`` and ``mean`` raw metrics of the control (seeded by
        ``settings.seed``: the same numbers every time); ``ratio``: ``per_view`` and ``mean``
        ratios of the volume's metrics to the control's (the mean is the ratio of the means,
        as in docs/quality.md).
    """
    control: dict[str, dict[str, float]] = {}
    for group in _grouped(exemplars):
        e = next(iter(group.values()))
        volume = structureless(e, shape[:3], settings.seed)
        control.update(evaluate(volume, group, views=list(group), settings=settings)["per_view"])
    control = {view: control[view] for view in result["per_view"]}
    mean = {name: float(np.mean([values[name] for values in control.values()])) for name in METRICS}
    return {
        "control": {"per_view": control, "mean": mean},
        "ratio": {"per_view": {view: ratios(values, control[view])
                               for view, values in result["per_view"].items()},
                  "mean": ratios(result["mean"], mean)},
    }


def floor(exemplar: np.ndarray, *, settings: MetricSettings = DEFAULT_SETTINGS) -> dict[str, Any] | None:
    """The exemplar's right half as slices against its left half: the metrics another crop of
    the same texture scores, raw and as ratios to its own control (the left half's pixels drawn
    independently in the same shape). None when a half would be narrower than
    :data:`~.settings.MIN_SIDE`.

    The right half is stacked :data:`~.settings.MIN_SIDE` times as the front slices of a volume
    (the metrics' smallest side; the same slice repeated leaves every pooled statistic as it is).
    """
    e = np.asarray(exemplar, dtype=np.float32)
    if e.ndim == 2:
        e = e[..., None]
    half = e.shape[1] // 2
    if half < MIN_SIDE or e.shape[0] < MIN_SIDE:
        return None
    left, right = e[:, :half], e[:, half:2 * half]
    volume = np.stack([right] * MIN_SIDE, axis=2)
    raw = evaluate(volume, {"front": left}, views=["front"], settings=settings)["mean"]
    control = evaluate(structureless(left, volume.shape[:3], settings.seed), {"front": left},
                       views=["front"], settings=settings)["mean"]
    return {"raw": raw, "control": control, "ratio": ratios(raw, control),
            "half_shape": [int(e.shape[0]), int(half)]}
