"""The structure judge per view, as ratios to a floor (docs/metrics.md, "Layout, view by view").

:func:`npmrf3d.analysis.structure.structure_scores` compares each sampled slice of a view with
the exemplar on its own (``continuity`` and ``pyramid``, each a ratio to the structureless
control). Here the judge runs once per view, against that view's exemplar, and each ratio is
divided by the **floor's**, what another crop of the same texture scores: 1 = as good as a real
crop, lower is better. :func:`half_floor` is the floor a lone exemplar has (its right half
against its left half, as :func:`npmrf3d.analysis.metrics.references.floor` does for the pooled
metrics); the quality benchmark passes the floor of other crops of its photographs instead.

Needs scikit-image (``pip install 'npmrf3d[structure]'``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import structure
from .inputs import as_exemplar

__all__ = ["MIN_FLOOR", "SLICES", "VIEW_AXES", "half_floor", "view_scores"]

#: Slices sampled per view (and control images per view).
SLICES = 8
#: The axis perpendicular to each view's slices (the inverse of ``structure.AXIS_VIEWS``).
VIEW_AXES = {view: axis for axis, view in structure.AXIS_VIEWS.items()}
#: The judge's smallest image side.
MIN_JUDGED = 8
#: The smallest floor a ratio is taken to: an exemplar whose halves are alike to the judge (a
#: periodic pattern) has a floor of 0, and every ratio to it would be infinite.
MIN_FLOOR = 0.01


def half_floor(exemplar: Any, *, rng=0) -> dict[str, float]:
    """The judge's ratios to the control (per estimator) of the exemplar's right half, judged
    against its left half: what another crop of the same texture scores. The half is judged
    :data:`SLICES` times over (the same distance each time), so its control holds as many
    images as a view's. The exemplar must be at least 8 pixels high and 16 wide (two halves
    the judge can read).

    >>> e = np.zeros((16, 32)); e[::4] = 1.0                    # stripes: both halves alike
    >>> sorted(half_floor(e)) == sorted(structure.ESTIMATORS)
    True
    """
    e = as_exemplar(exemplar)
    half = e.shape[1] // 2
    if half < MIN_JUDGED or e.shape[0] < MIN_JUDGED:
        raise ValueError(f"an exemplar of {e.shape[0]} x {e.shape[1]} pixels has no halves of at "
                         f"least {MIN_JUDGED} x {MIN_JUDGED}")
    right = np.stack([e[:, half:2 * half]] * SLICES)   # as many control images as a view's
    return structure.image_scores(right, e[:, :half], rng=rng).ratio["images"]


def view_scores(volume: Any, exemplars: dict[str, Any], floors: dict[str, dict[str, float]], *,
                slices: int = SLICES, rng=0) -> dict[str, Any]:
    """The judge per view of ``volume``, as ratios to the control and to the floor.

    Parameters
    ----------
    volume : (N1, N2, N3[, C]) array
    exemplars : view -> (H, W[, C]) array
        Each view's slices are judged against its exemplar.
    floors : view -> estimator -> the floor's ratio to the control (:func:`half_floor`)
    slices : int
        Slices sampled per view.
    rng : int
        Seeds the slices and the control of every view (the same numbers every time).

    Returns
    -------
    dict
        ``per_view``: view -> ``ratio`` (to the control) and ``to_floor`` (that ratio divided
        by the floor's, at least :data:`MIN_FLOOR`), per estimator, and ``scales``; ``mean`` and ``worst``: per estimator, the mean and the
        largest ``to_floor`` over the views; ``worst_view``: per estimator, that view;
        ``floor``: ``floors`` as given; ``settings``: slices, seed and the top-hats' width (the
        pyramid's octaves are each view's ``scales``).
    """
    per_view, width = {}, None
    for view, exemplar in exemplars.items():
        scores = structure.structure_scores(volume, exemplar, axes=(VIEW_AXES[view],),
                                            slices=slices, rng=rng)
        ratio = scores.ratio[VIEW_AXES[view]]
        per_view[view] = {"ratio": ratio,
                          "to_floor": {k: ratio[k] / max(floors[view][k], MIN_FLOOR)
                                       for k in structure.ESTIMATORS},
                          "scales": scores.settings["scales"]}
        width = scores.settings["width"]
    names = structure.ESTIMATORS
    worst_view = {k: max(per_view, key=lambda v: per_view[v]["to_floor"][k]) for k in names}
    return {
        "per_view": per_view,
        "mean": {k: float(np.mean([s["to_floor"][k] for s in per_view.values()])) for k in names},
        "worst": {k: per_view[worst_view[k]]["to_floor"][k] for k in names},
        "worst_view": worst_view,
        "floor": {view: dict(floors[view]) for view in exemplars},
        "settings": {"slices": int(slices), "seed": rng, "width": width},
    }
