"""copy_repetition against a brute-force loop over every shift (tests/naive.py)."""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d.analysis.repetition import copy_repetition
from npmrf3d.errors import ParameterError
from tests.naive import naive_copy_repetition


@pytest.mark.parametrize("shape, values, min_shift, tolerance",
                         [((5, 6, 7), 2, 2, 0), ((5, 5, 7), 6, 2, 1), ((6, 6, 6), 3, 1, 0), ((6, 5, 5), 9, 2, 2)])
def test_copy_repetition_matches_every_shift_counted(shape, values, min_shift, tolerance):
    rng = np.random.default_rng(sum(shape))
    coords = rng.integers(0, values, size=shape + (3,))
    exact = naive_copy_repetition(coords, min_shift, tolerance)
    every = copy_repetition(coords, min_shift=min_shift, tolerance=tolerance, candidates=None)
    assert every["share"] == pytest.approx(exact)
    t = np.array(every["shift"])
    moved = np.roll(coords, shift=tuple(-t), axis=(0, 1, 2))
    assert (np.abs(moved - coords).max(axis=-1) <= tolerance).mean() == pytest.approx(every["share"])
    assert copy_repetition(coords, min_shift=min_shift, tolerance=tolerance)["share"] <= exact + 1e-12


def test_the_searched_shifts_find_a_jittered_copy_and_count_a_collapse_once():
    """The default (peaks of the exact-copy histogram) finds the exact maximum of a copied
    volume: blocks of an exemplar at a far shift, moved by the jitter, beside a flat region
    that copies one voxel (which a box sum over shifts would count up to 125 times)."""
    rng = np.random.default_rng(5)
    coords = rng.integers(0, 40, size=(20, 20, 20, 3))
    coords[10:18, :8, :8] = coords[0:8, :8, :8] + rng.integers(-1, 2, size=(8, 8, 8, 3))  # a copy at t = 10
    coords[:, 12:, 12:] = 7  # a collapse: one exemplar voxel copied 20 x 8 x 8 times
    exact = naive_copy_repetition(coords, 4, 2)
    got = copy_repetition(coords, min_shift=4)
    assert got["share"] == pytest.approx(exact)
    # at t = (10, 0, 0): the collapse (0.16) and the copy both ways (2 x 0.064), each voxel once
    assert 0.288 <= exact < 0.3 and got["shift"] in ([10, 0, 0], [-10, 0, 0])


def test_a_tiled_volume_repeats_and_a_shuffled_one_does_not():
    period = 20
    tiled = np.stack(np.meshgrid(*[np.arange(48) % period] * 3, indexing="ij"), axis=-1)
    got = copy_repetition(tiled)
    assert got["share"] == pytest.approx((48 - period) / 48)  # voxels whose p + 20 does not wrap
    assert sorted(np.abs(got["shift"])) == [0, 0, period]
    shuffled = tiled.reshape(-1, 3)[np.random.default_rng(0).permutation(48 ** 3)].reshape(tiled.shape)
    assert copy_repetition(shuffled)["share"] < 0.05  # chance: 14 copies each, over 125 of 110592 shifts
    # a second copy moved by one voxel in the exemplar still counts, with the tolerance
    # (a coherent block copied at t = 20 along axis 0, each quarter moved by its own voxel)
    block = np.stack(np.meshgrid(np.arange(period), np.arange(48), np.arange(48), indexing="ij"), axis=-1)
    quarter = (np.arange(48)[:, None] >= 24) * 2 + (np.arange(48)[None, :] >= 24)
    moved = np.concatenate([block, block + np.eye(3, dtype=int)[[0, 1, 2, 0]][quarter], block[:48 - 2 * period]])
    assert copy_repetition(moved, tolerance=0)["share"] < 0.25 < 0.5 < copy_repetition(moved)["share"]


def test_copy_repetition_refuses_values():
    with pytest.raises(ParameterError, match="integer array"):
        copy_repetition(np.zeros((8, 8, 8, 3)))


def test_volume_lh_records_the_repetition_of_its_tiled_start():
    """With neither jitter nor correction the tiled start is the exemplar laid side by side
    (period: the valid box, 12 voxels of a 16^3 exemplar, seen at 24 >= MIN_SHIFT); uniform
    random coordinates are not, nor tiles that each take their own offset ('blocks')."""
    from npmrf3d.methods.volume_lh import volume_synthesize
    exemplar = np.random.default_rng(3).random((16, 16, 16, 1)).astype(np.float32)
    common = dict(size=48, levels=2, passes=0, jitter=0.0, usage=0.0, balance=0.0, rng=0)
    tiled = volume_synthesize(exemplar, start="tiled", **common).stats["repetition"]
    random = volume_synthesize(exemplar, start="random", **common).stats["repetition"]
    blocks = volume_synthesize(exemplar, start="blocks", **common).stats["repetition"]
    assert tiled["share"] > 0.3 and random["share"] < 0.1
    assert blocks["share"] < tiled["share"] / 4  # every tile at its own offset
    assert max(abs(x) for x in tiled["shift"]) == 24
