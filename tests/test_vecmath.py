"""The vectorised float32 ``exp`` of the Parzen label stage (npmrf3d._kernels.vecmath) and the
integer-view minimum beside it, against numpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from npmrf3d._kernels.parzen import smallest_distance
from npmrf3d._kernels.vecmath import WEIGHT_LOG_MIN, relative_weights
from tests import naive

pytestmark = pytest.mark.kernels

ULP32 = float(np.finfo(np.float32).eps)


def weights(dist, d_min, inv, lowest):
    out = np.empty(len(dist), dtype=np.float32)
    relative_weights(dist, len(dist), d_min, inv, lowest, out, np.empty(len(dist), dtype=np.float32))
    return out


@pytest.mark.parametrize("inv", [0.3, 1.0, 1241.6, 9.0e4])
def test_relative_weights_match_numpy_exp_to_a_few_float32_ulps(rng, inv):
    dist = np.concatenate([rng.random(3000) * 0.2, rng.random(64) * 1e-4, [0.0, 0.0]]).astype(np.float32)
    d_min = float(dist.min())
    got = weights(dist, d_min, inv, -np.inf)
    want = naive.naive_relative_weights(dist, d_min, inv, -np.inf)
    live = want > 0
    assert live.sum() >= 60  # the test sees weights over the whole float32 range
    rel = np.abs(got[live] - want[live]) / want[live]
    assert rel.max() <= 2 * ULP32, rel.max()
    assert (got[~live] == 0).all()
    assert (got[dist == d_min] == 1.0).all()  # the best patch weighs exactly 1


def test_relative_weights_prune_and_range_floor(rng):
    dist = (rng.random(500) * 0.1).astype(np.float32)
    inv = 2000.0
    lw = (np.float32(0.0) - dist) * np.float32(inv)
    pruned = weights(dist, 0.0, inv, -40.0)
    assert (pruned[lw < -40] == 0).all() and (pruned[lw >= -40] > 0).all()
    full = weights(dist, 0.0, inv, -np.inf)  # no pruning: the float32 range ends at -87
    assert (full[lw < WEIGHT_LOG_MIN] == 0).all() and (full[lw >= WEIGHT_LOG_MIN] > 0).all()
    np.testing.assert_array_equal(full[lw >= -40], pruned[lw >= -40])


def test_relative_weights_at_the_reduction_boundaries():
    """Log weights at multiples of ln 2 (and halfway between) exercise the exponent bits."""
    lw = np.array([-k * math.log(2) for k in range(0, 126)] +
                  [-(k + 0.5) * math.log(2) for k in range(0, 125)])
    inv = 1.0
    dist = (-lw).astype(np.float32)
    got = weights(dist, 0.0, inv, -np.inf).astype(np.float64)
    want = naive.naive_relative_weights(dist, 0.0, inv, -np.inf)
    live = want > 0
    np.testing.assert_allclose(got[live], want[live], rtol=2 * ULP32)


def test_smallest_distance_is_the_minimum(rng):
    cell = np.empty(1, dtype=np.float32)
    for n in (1, 2, 7, 3364):
        dist = (rng.random(n) * rng.choice([1e-6, 1.0, 1e6])).astype(np.float32)
        assert smallest_distance(dist, n, cell) == float(dist.min())
    dist = np.array([3.0, 0.0, 2.0, -0.0], dtype=np.float32)
    assert smallest_distance(dist, 4, cell) == 0.0
    assert smallest_distance(np.array([5.0, 1e-40, 2.0], dtype=np.float32), 3, cell) == np.float32(1e-40)
