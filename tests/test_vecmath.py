"""The vectorised float32 ``exp`` of the Parzen label stage (npmrf3d._kernels.vecmath), the
integer-view minimum beside it and the label sums over the kept patches, against numpy."""

from __future__ import annotations

import math

import numpy as np
import pytest

from npmrf3d._kernels.parzen import all_label_weights, kept_label_weights, smallest_distance
from npmrf3d._kernels.vecmath import WEIGHT_LOG_MIN, relative_weight, relative_weights
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


def test_relative_weight_is_relative_weights_bit_for_bit(rng):
    """The one-distance form gives the bits of the vectorised pass, at every log weight down to
    the floor (and 0 below it)."""
    dist = np.concatenate([rng.random(4000) * 0.1, rng.random(500) * 1e-3, [0.0]]).astype(np.float32)
    for inv, lowest in ((1241.6, -40.0), (9.0e4, -np.inf), (3.0, -1.0)):
        d_min = float(dist.min())
        want = weights(dist, d_min, inv, lowest)
        top, scale = np.float32(d_min), np.float32(inv)
        floor = np.float32(max(lowest, WEIGHT_LOG_MIN))
        got = np.array([relative_weight(d, top, scale, floor) for d in dist], dtype=np.float32)
        np.testing.assert_array_equal(got.view(np.int32), want.view(np.int32))


def _label_sums(kernel, dist, starts, inv, prune, adapt=0.0):
    k = len(starts) - 1
    w = np.zeros(k)
    nonzero = np.empty(k, dtype=np.int64)
    n_nz = kernel(dist, len(dist), starts, inv, adapt, 1e-4, prune, w, nonzero,
                  np.empty((2, len(dist)), dtype=np.float32))
    return w, nonzero[:n_nz]


@pytest.mark.parametrize("n", [5, 32, 200, 3364])
@pytest.mark.parametrize("spread", [1e-4, 0.02, 1.0])
def test_kept_label_weights_are_all_label_weights_bit_for_bit(rng, n, spread):
    """The sums over the kept patches only are the sums over every patch, bit for bit, whether
    few patches are kept (a sharp bandwidth: the chunk scan) or many (the hand-over); and both
    are the numpy sums of the kept weights."""
    dist = (0.3 + rng.random(n) * spread).astype(np.float32)
    dist[rng.integers(n)] = 0.3  # ties with the best
    if spread == 1.0:  # a few close matches among far ones: most chunks hold no kept patch
        dist[dist < 0.35] += 1.0
        dist[rng.integers(n, size=4)] = 0.3 + rng.random(4).astype(np.float32) * 0.03
        dist[-1] = 0.301  # in the last, shorter chunk
    cuts = np.sort(rng.integers(0, n + 1, size=max(1, n // 7)))
    starts = np.concatenate([[0], cuts, [n]]).astype(np.int64)  # labels of 0 to many patches
    for inv, prune, adapt in ((1241.6, 40.0, 0.0), (50.0, 40.0, 0.0), (1241.6, 3.0, 0.0),
                              (0.0, 40.0, 0.0), (1.0, 40.0, 0.05)):
        kept = _label_sums(kept_label_weights, dist, starts, inv, prune, adapt)
        every = _label_sums(all_label_weights, dist, starts, inv, prune, adapt)
        np.testing.assert_array_equal(kept[1], every[1])
        np.testing.assert_array_equal(kept[0].view(np.int64), every[0].view(np.int64))
        scale = 1.0 / max(adapt * float(dist.min()), 1e-4) if adapt else inv
        want = naive.naive_label_weights(dist, starts, scale, prune)
        np.testing.assert_allclose(kept[0], want, rtol=4 * ULP32)
        assert list(kept[1]) == list(np.flatnonzero(want))
