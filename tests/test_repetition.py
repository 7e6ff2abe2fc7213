"""copy_repetition against a brute-force loop over every shift (tests/naive.py)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.naive import naive_copy_repetition
from npmrf3d.errors import ParameterError
from npmrf3d.repetition import copy_repetition


@pytest.mark.parametrize("shape, values, min_shift, tolerance",
                         [((6, 7, 8), 2, 2, 0), ((5, 5, 9), 3, 3, 1), ((8, 8, 8), 2, 1, 0), ((7, 6, 6), 3, 2, 2)])
def test_copy_repetition_matches_every_shift_counted(shape, values, min_shift, tolerance):
    rng = np.random.default_rng(sum(shape))
    coords = rng.integers(0, values, size=shape + (3,))
    got = copy_repetition(coords, min_shift=min_shift, tolerance=tolerance)
    assert got["share"] == pytest.approx(naive_copy_repetition(coords, min_shift, tolerance))
    if tolerance == 0:
        t = np.array(got["shift"])
        moved = np.roll(coords, shift=tuple(-t), axis=(0, 1, 2))
        assert np.all(moved == coords, axis=-1).mean() == pytest.approx(got["share"])


def test_a_tiled_volume_repeats_and_a_shuffled_one_does_not():
    period = 20
    tiled = np.stack(np.meshgrid(*[np.arange(48) % period] * 3, indexing="ij"), axis=-1)
    got = copy_repetition(tiled)
    assert got["share"] == pytest.approx((48 - period) / 48)  # voxels whose p + 20 does not wrap
    assert sorted(np.abs(got["shift"])) == [0, 0, period]
    shuffled = tiled.reshape(-1, 3)[np.random.default_rng(0).permutation(48 ** 3)].reshape(tiled.shape)
    assert copy_repetition(shuffled)["share"] < 0.05  # chance: 14 copies each, over 125 of 110592 shifts
    # a second copy moved by one voxel in the exemplar still counts, with the tolerance
    moved = tiled.copy()
    moved[period:] = np.clip(moved[period:] + 1, 0, period - 1)
    assert copy_repetition(moved, tolerance=0)["share"] < copy_repetition(moved)["share"]


def test_copy_repetition_refuses_values():
    with pytest.raises(ParameterError, match="integer array"):
        copy_repetition(np.zeros((8, 8, 8, 3)))


def test_volume_lh_records_the_repetition_of_its_tiled_start():
    """With neither jitter nor correction the tiled start is the exemplar laid side by side
    (period: the valid box, 12 voxels of a 16^3 exemplar, seen at 24 >= MIN_SHIFT); uniform
    random coordinates are not, nor tiles that each take their own offset ('blocks')."""
    from npmrf3d.volume_synthesis import volume_synthesize
    exemplar = np.random.default_rng(3).random((16, 16, 16, 1)).astype(np.float32)
    common = dict(size=48, levels=2, passes=0, jitter=0.0, usage=0.0, balance=0.0, rng=0)
    tiled = volume_synthesize(exemplar, start="tiled", **common).stats["repetition"]
    random = volume_synthesize(exemplar, start="random", **common).stats["repetition"]
    blocks = volume_synthesize(exemplar, start="blocks", **common).stats["repetition"]
    assert tiled["share"] > 0.3 and random["share"] < 0.1
    assert blocks["share"] < tiled["share"] / 4  # every tile at its own offset
    assert max(abs(x) for x in tiled["shift"]) == 24
