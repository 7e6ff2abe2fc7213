"""Coordinate-seeded noise: a pure function of (coordinate, scale, channel, seed)."""

from __future__ import annotations

import torch

from npmrf3d.methods.neural.noise import mix64, noise_block


def test_overlapping_blocks_hold_the_same_values():
    a = noise_block((-8, 3, 100), (16, 12, 10), scale=2, channels=3, seed=5)
    b = noise_block((-3, 7, 104), (5, 6, 4), scale=2, channels=3, seed=5)
    assert torch.equal(a[:, :, 5:10, 4:10, 4:8], b)


def test_seed_scale_and_channel_change_the_values():
    base = noise_block((0, 0, 0), (8, 8, 8), scale=0, channels=2, seed=1)
    assert not torch.equal(base[:, 0], base[:, 1])
    assert not torch.equal(base, noise_block((0, 0, 0), (8, 8, 8), scale=0, channels=2, seed=2))
    assert not torch.equal(base, noise_block((0, 0, 0), (8, 8, 8), scale=1, channels=2, seed=1))


def test_uniform_and_uncorrelated():
    v = noise_block((0, 0, 0), (40, 40, 40), scale=0, channels=1, seed=3)[0, 0]
    assert 0.0 <= float(v.min()) and float(v.max()) < 1.0
    assert abs(float(v.mean()) - 0.5) < 0.01
    assert abs(float(v.var()) - 1 / 12) < 0.002
    centred = v - v.mean()
    for axis in range(3):
        lagged = torch.roll(centred, 1, dims=axis)
        corr = float((centred * lagged).mean() / centred.var())
        assert abs(corr) < 0.02, (axis, corr)
    # the axes are not interchangeable (no symmetry of the hash in x, y, z)
    assert not torch.equal(v, v.transpose(0, 1))


def test_mix64_matches_splitmix64_reference():
    # SplitMix64's finaliser on 1 (unsigned arithmetic in Python), as a signed int64
    x, m = 1, (1 << 64) - 1
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & m
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & m
    x ^= x >> 31
    expected = x - (1 << 64) if x >= 1 << 63 else x
    assert int(mix64(torch.tensor([1], dtype=torch.int64))[0]) == expected
