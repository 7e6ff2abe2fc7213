"""The coordinate pyramid of the volume-lh method: the coarsest level's start, the up-sampling
of a level's exemplar coordinates to the next finer one and the jitter
(:mod:`npmrf3d.methods.volume_lh`; ``docs/volume.md``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["STARTS", "initial_coordinates", "jittered", "upsample"]

#: How the coarsest level starts: the exemplar tiled (the paper's coordinate pyramid, from one
#: voxel) with a random offset and jitter, uniformly random coordinates, or the tiling with an
#: offset of its own for every tile.
STARTS = ("tiled", "random", "blocks")


def upsample(coords: np.ndarray, frames: np.ndarray, h: int, lo, hi) -> np.ndarray:
    """Children's coordinates ``S[parent] + floor(h R^T (delta - 1/2) + 1/2)``, clamped to the
    valid box (``frames``: the children's, or one frame for all)."""
    n1, n2, n3 = coords.shape[:3]
    child = np.repeat(np.repeat(np.repeat(coords, 2, axis=0), 2, axis=1), 2, axis=2).astype(np.int64)
    delta = np.stack(np.meshgrid(*[(np.arange(2 * n) % 2) - 0.5 for n in (n1, n2, n3)], indexing="ij"), axis=-1)
    rt = np.swapaxes(frames.astype(np.float64), -1, -2)
    offset = np.floor(h * np.einsum("...rc,...c->...r", rt, delta) + 0.5).astype(np.int64)
    return np.clip(child + offset, lo, hi)


def initial_coordinates(shape, h: int, lo, hi, start: str, jitter: float,
                        rng: np.random.Generator) -> np.ndarray:
    """The coarsest level's coordinates ``(*shape, 3)`` int64 in the valid box ``[lo, hi]``.

    ``tiled``: the exemplar laid out at the level's spacing, ``lo + (h p + o) mod (hi - lo + 1)``
    with one random offset ``o``, then jittered (:func:`jittered`, amplitude ``jitter``) — what the
    paper's pyramid from a single voxel gives, with wrap-around seams for the correction to mend.
    ``random``: every coordinate uniform in the box (the exemplar's parts mixed voxel by voxel,
    from which the correction drifts to the parts easiest to match: ``docs/volume.md``).
    ``blocks``: the tiling, but every tile (``extent // h`` coarse voxels per axis) takes its own
    random offset, so no block of the exemplar repeats at one shift."""
    lo, hi = np.asarray(lo, dtype=np.int64), np.asarray(hi, dtype=np.int64)
    if start == "random":
        return np.stack([rng.integers(lo[a], hi[a] + 1, size=shape) for a in range(3)], axis=-1)
    extent = hi - lo + 1
    grid = np.stack(np.meshgrid(*[np.arange(n, dtype=np.int64) for n in shape], indexing="ij"), axis=-1)
    if start == "blocks":
        tile = np.maximum(1, extent // h)  # coarse voxels per exemplar tile, per axis
        blocks = tuple(int(-(-n // t)) for n, t in zip(shape, tile))
        offsets = rng.integers(0, extent, size=blocks + (3,))
        offset = offsets[tuple((grid // tile)[..., a] for a in range(3))]
    else:
        offset = rng.integers(0, extent)
    uniforms = rng.uniform(-1.0, 1.0, size=tuple(shape) + (3,)).astype(np.float32)
    return jittered(lo + (grid * h + offset) % extent, h, jitter, uniforms, lo, hi)


def jittered(coords: np.ndarray, h: int, amount: float, uniforms: np.ndarray, lo, hi) -> np.ndarray:
    """``S + floor(h * amount * U + 1/2)`` clamped to the valid box (``U`` pre-drawn in [-1, 1])."""
    return np.clip(coords + np.floor(h * amount * uniforms + 0.5).astype(np.int64), lo, hi)
