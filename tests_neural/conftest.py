"""Fixtures of the torch tests (``python -m pytest tests_neural``; needs ``.[neural]``).

One torch thread (the machine is shared; results do not depend on it), tiny exemplars and a
tiny generator (3 scales, 2 channels per step, 16-voxel tiles) so that training steps take
milliseconds.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

torch.set_num_threads(1)

#: Options of a tiny training run (any test may override some).
TINY = dict(scales=3, channel_step=2, noise_channels=2, tile=16, filters=6, descriptor_scales=2,
            filter_size=3, slice_size=16, iterations=3, size=16)


@pytest.fixture
def tiny_options() -> dict:
    return dict(TINY)


@pytest.fixture
def exemplar() -> np.ndarray:
    """A 24x24 grey exemplar: blurred noise (a stochastic texture), float32 in [0, 1]."""
    rng = np.random.default_rng(0)
    a = rng.random((26, 26))
    a = (a[:-2, :-2] + a[1:-1, 1:-1] + a[2:, 2:]) / 3
    return a.astype(np.float32)


@pytest.fixture
def exemplar_rgb() -> np.ndarray:
    rng = np.random.default_rng(1)
    return rng.random((20, 20, 3)).astype(np.float32)
