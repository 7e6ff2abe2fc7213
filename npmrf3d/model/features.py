"""A feature-distance channel for matching structured exemplars (Lefebvre & Hoppe 2006).

Lefebvre & Hoppe ("Appearance-space texture synthesis", 2006) match neighbourhoods in an
*appearance space*: the exemplar's colours plus channels that make structure visible to a
small window, among them the distance of every pixel to the nearest feature line. A 7 x 7
window that sits inside a paving stone then still knows how far the mortar is, and a voxel's
candidates that continue a line score better than ones that end it.

:func:`line_distance` is that channel for thin dark lines (mortar, cracks, veins): the black
top-hat of the exemplar's grey image (a grey closing by a disk of diameter 7 minus the image)
above Otsu's split of its values (:func:`npmrf3d.model.otsu.otsu_threshold`), and every pixel's
Euclidean distance to it, at most :data:`CLIP` pixels. :func:`with_feature` appends it to an
exemplar, standardised and scaled to ``weight`` times the exemplar's spread, so that matching and
deciding read it as one more channel; the volume's colours are the first channels.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from .otsu import otsu_threshold

__all__ = ["CLIP", "LINE_WIDTH", "line_distance", "with_feature"]

#: Widest line found, in pixels (the closing's disk has diameter ``LINE_WIDTH + 1``).
LINE_WIDTH = 6
#: Distances beyond this many pixels are all "far from a line".
CLIP = 8.0


def line_distance(grey: np.ndarray, width: int = LINE_WIDTH, clip: float = CLIP) -> np.ndarray:
    """Distance in pixels (at most ``clip``) of every pixel of ``grey`` ``(H, W)`` to the nearest
    thin dark line, float64 ``(H, W)``; all ``clip`` when the image holds no line.

    >>> g = np.ones((9, 9)); g[4] = 0.0                    # one dark row
    >>> line_distance(g)[:, 0].tolist()
    [4.0, 3.0, 2.0, 1.0, 0.0, 1.0, 2.0, 3.0, 4.0]
    """
    g = np.asarray(grey, dtype=np.float64)
    r = width // 2
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    disk = np.hypot(y, x) <= width / 2.0
    response = ndimage.grey_closing(g, footprint=disk, mode="reflect") - g
    if np.ptp(response) <= 1e-12 * max(1.0, float(np.abs(g).max())):
        return np.full(g.shape, float(clip))
    lines = response > otsu_threshold(response)
    if not lines.any():
        return np.full(g.shape, float(clip))
    return np.minimum(ndimage.distance_transform_edt(~lines), clip)


def with_feature(exemplar: np.ndarray, weight: float) -> np.ndarray:
    """``exemplar`` ``(H, W, C)`` with one more channel, :func:`line_distance` of its grey image
    (the mean of the channels) standardised to mean 0 and spread ``weight`` times the
    exemplar's (all channels pooled); a constant channel (0) when the exemplar has no line.

    >>> e = np.zeros((16, 16, 3), dtype=np.float32); e[::5] = 1.0
    >>> f = with_feature(e, 1.0)
    >>> f.shape, bool(np.allclose(f[..., :3], e)), round(float(f[..., 3].std() / e.std()), 3)
    ((16, 16, 4), True, 1.0)
    """
    e = np.asarray(exemplar, dtype=np.float32)
    channel = line_distance(e.mean(axis=-1))
    spread = channel.std()
    channel = (channel - channel.mean()) / spread * weight * float(e.std()) if spread > 1e-12 \
        else np.zeros_like(channel)
    return np.ascontiguousarray(np.concatenate([e, channel[..., None].astype(np.float32)], axis=-1))
