"""The on-demand solid texture generator of Gutierrez et al. 2020 (section 4).

A multi-scale fully convolutional network: noise at ``scales`` lattice resolutions (scale 0 the
finest, each coarser one half the resolution), each processed by a *convolution block* (3x3x3,
3x3x3, 1x1x1 convolutions without padding, each followed by batch normalisation and a leaky
ReLU), joined coarse to fine by nearest-neighbour up-sampling, batch normalisation and channel
concatenation, then a second block; a final 1x1x1 convolution maps to the exemplar's channels.

On demand (section 4.2-4.3): the block of the unbounded volume at integer ``origin`` with
``shape`` is computed from the noise on exactly the lattice range each scale needs
(:func:`plan`); the ranges follow from the architecture — every block trims 2 voxels per side,
an up-sampled coarse voxel ``p`` covers fine voxels ``2p, 2p + 1`` — so no margin is guessed and
the up-sampled branch is cropped by the offset that keeps absolute coordinates aligned (the
paper's shift compensation). Every output voxel therefore depends only on the noise at fixed
absolute lattice coordinates: blocks tile exactly (tested bit for bit in ``tests_neural``).
Batch normalisation uses batch statistics while training and the running statistics (a fixed
per-channel affine map) when generating (:meth:`SolidGenerator.eval`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from .noise import noise_block

__all__ = ["Plan", "SolidGenerator", "plan"]

#: Voxels trimmed per side by one convolution block (two 3x3x3 and one 1x1x1 unpadded convolutions).
BLOCK_TRIM = 2


@dataclass(frozen=True)
class Plan:
    """Lattice ranges of one block: per scale (0 = finest) the noise start and shape, and the
    crop of the up-sampled coarser branch before each concatenation."""

    noise_start: tuple[tuple[int, int, int], ...]
    noise_shape: tuple[tuple[int, int, int], ...]
    crop: tuple[tuple[int, int, int], ...]
    concat_shape: tuple[tuple[int, int, int], ...]


def _axis_plan(origin: int, size: int, scales: int):
    """One axis of :func:`plan`: ranges are half-open [a, b) in the lattice units of a scale."""
    noise, crops, concat = [], [], []
    a, b = origin, origin + size          # what scale 0's last block must output
    for _k in range(scales - 1):
        ca, cb = a - BLOCK_TRIM, b + BLOCK_TRIM          # input of the block after the concatenation
        noise.append((ca - BLOCK_TRIM, cb + BLOCK_TRIM))  # input of the noise branch's block
        concat.append(cb - ca)
        a, b = ca // 2, (cb - 1) // 2 + 1                 # coarser voxels whose copies cover [ca, cb)
        crops.append(ca - 2 * a)                          # offset of ca in the up-sampled branch
    noise.append((a - BLOCK_TRIM, b + BLOCK_TRIM))        # the coarsest scale: one block only
    return noise, crops, concat


def plan(origin, shape, scales: int) -> Plan:
    """The noise ranges and crops that make the block ``origin + [0, shape)`` (per axis)."""
    axes = [_axis_plan(int(o), int(n), scales) for o, n in zip(origin, shape)]
    starts = tuple(tuple(axes[d][0][k][0] for d in range(3)) for k in range(scales))
    shapes = tuple(tuple(axes[d][0][k][1] - axes[d][0][k][0] for d in range(3)) for k in range(scales))
    crops = tuple(tuple(axes[d][1][k] for d in range(3)) for k in range(scales - 1))
    concat = tuple(tuple(axes[d][2][k] for d in range(3)) for k in range(scales - 1))
    return Plan(starts, shapes, crops, concat)


#: Convolutions with fewer input channels run with zero channels added up to this count: CPU
#: libraries take a slow general path below it (measured: a 4 -> 4 channel 3x3x3 convolution of
#: a 70^3 block took 1.16 s, 8 -> 4 channels 0.23 s). The zeros change no value.
MIN_CHANNELS = 8


class Conv3d(nn.Conv3d):
    """An unpadded 3D convolution whose input (and weight) is padded with zero channels up to
    :data:`MIN_CHANNELS` (same parameters and state as :class:`torch.nn.Conv3d`)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.kernel_size == (1, 1, 1) and _is_channels_last(x):
            return _pointwise(x, self.weight, self.bias)
        extra = MIN_CHANNELS - self.in_channels
        if extra <= 0:
            return super().forward(x)
        pad = (0, 0) * 3 + (0, extra)
        return F.conv3d(F.pad(x, pad), F.pad(self.weight, pad), self.bias)


def _is_channels_last(x: torch.Tensor) -> bool:
    """Whether ``x`` is stored channels-last (and not also contiguous, as one channel would be)."""
    return x.dim() == 5 and x.shape[1] > 1 and x.stride(1) == 1 and not x.is_contiguous()


def _pointwise(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
    """A 1x1x1 convolution of a channels-last tensor as one matrix product over its voxels
    (CPU libraries run this case 5x slower as a convolution: measured 54 ms against 10 ms for
    24 -> 24 channels on 64^3). The result is channels-last too."""
    b, c, n0, n1, n2 = x.shape
    rows = x.permute(0, 2, 3, 4, 1).reshape(-1, c)
    w = weight.reshape(weight.shape[0], c).t()
    y = rows @ w if bias is None else torch.addmm(bias, rows, w)
    return y.view(b, n0, n1, n2, -1).permute(0, 4, 1, 2, 3)


def _affine(norm: nn.BatchNorm3d) -> tuple[torch.Tensor, torch.Tensor]:
    """The evaluation-mode map ``x -> scale * x + shift`` of a batch normalisation (float64)."""
    scale = norm.weight.double() / torch.sqrt(norm.running_var.double() + norm.eps)
    return scale, norm.bias.double() - norm.running_mean.double() * scale


def _fold_after(conv: nn.Conv3d, scale: torch.Tensor, shift: torch.Tensor) -> None:
    """``conv`` followed by the per-output-channel affine map, as one convolution (in place)."""
    w = conv.weight.double() * scale.view(-1, 1, 1, 1, 1)
    conv.weight.copy_(w.to(conv.weight.dtype))
    conv.bias.copy_((conv.bias.double() * scale + shift).to(conv.bias.dtype))


def _fold_before(conv: nn.Conv3d, scale: torch.Tensor, shift: torch.Tensor) -> None:
    """The per-input-channel affine map followed by the unpadded ``conv``, as one convolution
    (in place): ``W' = W * scale_i``, ``b' = b + sum_{i, taps} W * shift_i``."""
    w = conv.weight.double()
    conv.bias.copy_((conv.bias.double() + (w * shift.view(1, -1, 1, 1, 1)).sum(dim=(1, 2, 3, 4)))
                    .to(conv.bias.dtype))
    conv.weight.copy_((w * scale.view(1, -1, 1, 1, 1)).to(conv.weight.dtype))


def _conv_block(c_in: int, c_out: int, slope: float) -> nn.Sequential:
    layers = []
    for i, k in enumerate((3, 3, 1)):
        layers += [Conv3d(c_in if i == 0 else c_out, c_out, k), nn.BatchNorm3d(c_out),
                   nn.LeakyReLU(slope, inplace=True)]
    return nn.Sequential(*layers)


class SolidGenerator(nn.Module):
    """G(Z | theta) of Gutierrez et al. 2020 (figure 2), evaluated on demand.

    Parameters
    ----------
    scales : int
        Noise scales ``K + 1`` (the paper: 6).
    noise_channels : int
        Channels of each scale's noise ``M_i`` (the paper: 3).
    channel_step : int
        Channels after each noise block and the step across scales ``M_s`` (the paper: 4);
        the finest scale has ``scales * channel_step`` channels.
    out_channels : int
        Channels of the texture (1 grey, 3 colour).
    slope : float
        Negative slope of the leaky ReLUs.
    seed : int
        The noise seed: the unbounded volume the model describes.
    """

    def __init__(self, *, scales: int = 6, noise_channels: int = 3, channel_step: int = 4,
                 out_channels: int = 3, slope: float = 0.1, seed: int = 0):
        super().__init__()
        self.scales, self.noise_channels, self.channel_step = scales, noise_channels, channel_step
        self.out_channels, self.seed = out_channels, seed
        m = channel_step
        self.noise_blocks = nn.ModuleList(_conv_block(noise_channels, m, slope) for _ in range(scales))
        # after_blocks[k] joins scale k's noise branch with the up-sampled coarser branch
        self.after_blocks = nn.ModuleList(
            _conv_block(m * (scales - k), m * (scales - k), slope) for k in range(scales - 1))
        self.norm_coarse = nn.ModuleList(nn.BatchNorm3d(m * (scales - k - 1)) for k in range(scales - 1))
        self.norm_noise = nn.ModuleList(nn.BatchNorm3d(m) for _ in range(scales - 1))
        self.final = Conv3d(m * scales, out_channels, 1)

    @property
    def device(self) -> torch.device:
        return self.final.weight.device

    @property
    def is_channels_last(self) -> bool:
        """Whether the parameters (and so the activations of :meth:`forward`) are channels-last."""
        return self.after_blocks[0][0].weight.stride(1) == 1 if self.scales > 1 else False

    def for_inference(self) -> "SolidGenerator":
        """A copy for generation: every batch normalisation (a fixed per-channel affine map in
        evaluation mode) folded into the convolution next to it, and the parameters
        channels-last (:meth:`channels_last`). The same function up to float32 rounding, with
        two passes over each activation fewer; ``self`` is left as it is."""
        g = copy.deepcopy(self).eval()
        with torch.no_grad():
            for block in (*g.noise_blocks, *g.after_blocks):
                for i in range(0, len(block), 3):   # (conv, norm, relu) triples
                    scale, shift = _affine(block[i + 1])
                    _fold_after(block[i], scale, shift)
                    block[i + 1] = nn.Identity()
            for k in range(self.scales - 1):       # the norms before each concatenation
                (sc, tc), (sn, tn) = _affine(g.norm_coarse[k]), _affine(g.norm_noise[k])
                _fold_before(g.after_blocks[k][0], torch.cat([sc, sn]), torch.cat([tc, tn]))
                g.norm_coarse[k], g.norm_noise[k] = nn.Identity(), nn.Identity()
        return g.channels_last(True)

    def channels_last(self, enabled: bool = True) -> "SolidGenerator":
        """Store the parameters channels-last (``enabled``) or contiguous, in place.

        Generation on a CPU is about 1.5x faster channels-last (measured on a 64^3 tile: 0.65 s
        against 0.43 s on one core); the values differ from the contiguous layout's in the last
        bits only, and a given layout gives the same values for every block.
        """
        return self.to(memory_format=torch.channels_last_3d if enabled else torch.contiguous_format)

    def forward(self, origin, shape, seed: int | None = None) -> torch.Tensor:
        """The block ``origin + [0, shape)`` of the volume: a ``(1, C, *shape)`` tensor."""
        p = plan(origin, shape, self.scales)
        seed = self.seed if seed is None else seed
        dtype = self.final.weight.dtype

        def noise(k):
            return noise_block(p.noise_start[k], p.noise_shape[k], scale=k,
                               channels=self.noise_channels, seed=seed, device=self.device, dtype=dtype)

        # the generator's parameters in channels-last order (see :meth:`channels_last`) mean its
        # activations are stored that way too: the CPU library's fast path for 3D convolutions
        fmt = torch.channels_last_3d if self.is_channels_last else torch.contiguous_format
        top = self.scales - 1
        x = self.noise_blocks[top](noise(top).contiguous(memory_format=fmt))
        for k in range(top - 1, -1, -1):
            b, c, n0, n1, n2 = x.shape  # nearest-neighbour up-sampling by 2, one copy
            up = x[:, :, :, None, :, None, :, None].expand(b, c, n0, 2, n1, 2, n2, 2)
            up = up.reshape(b, c, 2 * n0, 2 * n1, 2 * n2)
            (c0, c1, c2), (n0, n1, n2) = p.crop[k], p.concat_shape[k]
            up = up[:, :, c0:c0 + n0, c1:c1 + n1, c2:c2 + n2].contiguous(memory_format=fmt)
            y = self.noise_blocks[k](noise(k).contiguous(memory_format=fmt))
            x = self.after_blocks[k](torch.cat([self.norm_coarse[k](up), self.norm_noise[k](y)], dim=1))
        return self.final(x)
