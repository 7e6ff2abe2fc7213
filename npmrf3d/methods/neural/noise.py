"""Coordinate-seeded noise: a pure function of (voxel coordinate, scale, channel, seed).

The generator's input at scale ``k`` is uniform noise on the integer lattice of that scale
(Gutierrez et al. 2020, section 4.3: a PRNG seeded by coordinates, channel and scale, so that
any block of the unbounded volume can be made on its own). Here the PRNG is a counter-based hash
rather than the paper's xorshift: SplitMix64's finaliser (Steele, Lea & Flood 2014) applied to
each axis coordinate with a key made of (seed, scale, channel, axis), the three axis hashes
combined by XOR and mixed once more. Everything is int64 arithmetic in torch (products wrap
modulo 2**64, right shifts are made logical by masking), so the values do not depend on the
device, the block or the thread count, and the top 24 bits map exactly to float32 in [0, 1).
"""

from __future__ import annotations

import torch

__all__ = ["mix64", "noise_block", "uniform_from_hash"]

_M1 = 0xBF58476D1CE4E5B9 - (1 << 64)  # SplitMix64 multipliers as signed int64
_M2 = 0x94D049BB133111EB - (1 << 64)
_GOLDEN = 0x9E3779B97F4A7C15 - (1 << 64)


def _shr(x: torch.Tensor, s: int) -> torch.Tensor:
    """Logical right shift of int64 values (torch's ``>>`` is arithmetic)."""
    return (x >> s) & ((1 << (64 - s)) - 1)


def mix64(x: torch.Tensor) -> torch.Tensor:
    """SplitMix64's finaliser on int64 values (bijective on 64-bit words)."""
    x = (x ^ _shr(x, 30)) * _M1
    x = (x ^ _shr(x, 27)) * _M2
    return x ^ _shr(x, 31)


def _mix_int(x: int) -> int:
    """:func:`mix64` on one Python integer (for the per-axis keys), as signed int64."""
    mask = (1 << 64) - 1
    x &= mask
    x = ((x ^ (x >> 30)) * (_M1 & mask)) & mask
    x = ((x ^ (x >> 27)) * (_M2 & mask)) & mask
    x ^= x >> 31
    return x - (1 << 64) if x >= 1 << 63 else x


def uniform_from_hash(h: torch.Tensor, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """The top 24 bits of a hash as a value in [0, 1) (exact in float32)."""
    return _shr(h, 40).to(dtype) * (2.0 ** -24)


def noise_block(start: tuple[int, int, int], shape: tuple[int, int, int], *, scale: int,
                channels: int, seed: int, device=None, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """Uniform noise of one scale on the lattice block ``start + [0, shape)``.

    Parameters
    ----------
    start : three ints
        Lattice coordinate of the block's first voxel (any integers, negative included).
    shape : three ints
        Block size per axis.
    scale, channels, seed : int
        Scale index (0 = finest), number of channels, the noise seed.

    Returns
    -------
    (1, channels, *shape) tensor
        ``value[0, c, i, j, k]`` depends only on ``(start + (i, j, k), scale, c, seed)``.

    >>> a = noise_block((0, 0, 0), (4, 4, 4), scale=0, channels=2, seed=1)
    >>> b = noise_block((2, 1, 3), (2, 3, 1), scale=0, channels=2, seed=1)
    >>> bool((a[:, :, 2:4, 1:4, 3:4] == b).all())
    True
    """
    out = torch.empty((1, channels, *shape), dtype=dtype, device=device)
    for c in range(channels):
        hashes = []
        for axis in range(3):
            key = _mix_int(((seed * 8 + scale) * 4096 + c) * 4 + axis) & ((1 << 63) - 1)
            coords = torch.arange(start[axis], start[axis] + shape[axis], dtype=torch.int64,
                                  device=device)
            hashes.append(mix64(coords * _GOLDEN + key))
        h = (hashes[0].view(-1, 1, 1) ^ (hashes[1].view(1, -1, 1) * 3)
             ^ (hashes[2].view(1, 1, -1) * 5))
        out[0, c] = uniform_from_hash(mix64(h), dtype)
    return out
