"""Multi-scale grids: level sizes, random initialisation and 1/8 or 8/8 up-sampling (SPEC.md section 5).

Level ``l`` is the level-0 grid decimated by ``2**l``; synthesis runs from ``l = levels - 1``
down to 0. The voxel of level ``l - 1`` at ``2 * (i, j, k)`` is the *inherited* child of voxel
``(i, j, k)`` of level ``l``: it always receives the parent's value and temperature 0. With
``1/8`` up-sampling the other 7 children are re-initialised by random draws from the exemplar
(temperature 1); with ``8/8`` they copy the parent's value (temperature 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UPSAMPLING = ("1/8", "8/8")
INHERIT = ("resynth", "fixed")


@dataclass
class LevelState:
    """The mutable state of one level: values, label indices, temperatures, inherited mask."""

    volume: np.ndarray  # (N1, N2, N3, C) float32
    labels_volume: np.ndarray  # (N1, N2, N3) int32
    temps: np.ndarray  # (N1, N2, N3) float32
    inherited: np.ndarray  # (N1, N2, N3) bool


def level_shape(size: tuple[int, int, int], level: int) -> tuple[int, int, int]:
    """Grid shape of ``level`` (size divided by ``2**level``)."""
    return tuple(n // 2 ** level for n in size)


def random_state(shape, labels: np.ndarray, label_freq: np.ndarray, rng: np.random.Generator) -> LevelState:
    """Every voxel a label drawn from the exemplar's label frequencies, temperature 1."""
    drawn = rng.choice(len(labels), size=shape, p=label_freq).astype(np.int32)
    return LevelState(
        volume=np.ascontiguousarray(labels[drawn], dtype=np.float32),
        labels_volume=drawn,
        temps=np.ones(shape, dtype=np.float32),
        inherited=np.zeros(shape, dtype=bool),
    )


def upsample(parent: LevelState, mode: str, labels: np.ndarray, label_freq: np.ndarray,
             rng: np.random.Generator) -> LevelState:
    """Up-sample a relaxed level to the next finer one (``mode`` in :data:`UPSAMPLING`)."""
    shape = tuple(2 * n for n in parent.labels_volume.shape)
    if mode == "8/8":
        lab = parent.labels_volume
        for axis in range(3):
            lab = np.repeat(lab, 2, axis=axis)
        vol = parent.volume
        for axis in range(3):
            vol = np.repeat(vol, 2, axis=axis)
        child = LevelState(np.ascontiguousarray(vol), np.ascontiguousarray(lab),
                           np.ones(shape, dtype=np.float32), np.zeros(shape, dtype=bool))
    else:
        child = random_state(shape, labels, label_freq, rng)
    child.volume[::2, ::2, ::2] = parent.volume
    child.labels_volume[::2, ::2, ::2] = parent.labels_volume
    child.temps[::2, ::2, ::2] = 0.0
    child.inherited[::2, ::2, ::2] = True
    return child
