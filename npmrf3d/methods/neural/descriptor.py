"""Texture descriptors for the training loss: Gram matrices of feature maps (Gutierrez et al.
2020, eq. 2-3).

The paper compares Gram matrices of VGG-19 layers (relu1_1 ... relu5_1) of each slice and the
exemplar. Pretrained weights cannot be downloaded here, so the default descriptor needs none:

``random``
    Gram matrices of a **fixed random filter bank on an image pyramid** (after Ustyuzhaninov,
    Brendel, Gatys & Bethge 2017, who showed that Gram matrices of a single layer of random
    filters already drive texture synthesis). At each of ``scales`` pyramid levels (2x2 average
    pooling between levels, so a ``filter_size`` filter sees ``filter_size * 2**s`` pixels) the
    image, centred on the exemplar's mean colour, is filtered by ``filters`` zero-mean,
    unit-norm Gaussian filters, rectified (ReLU) and summarised by its Gram matrix; a colour
    term (the Gram matrix of the centred pixels and a constant) adds the mean and covariance of
    the colours. Chosen over a patch sliced-Wasserstein loss or Portilla–Simoncelli statistics
    because it keeps the paper's loss exactly (eq. 3: Gram matrices, Frobenius distance), is
    differentiable by construction and cheap on a CPU (one small convolution per scale), and
    its multi-scale pyramid reaches structures as large as the slices.

``vgg19``
    The paper's descriptor, from a local weights file (a torchvision-style ``state_dict`` of
    ``vgg19().features``); its layer widths are read from the file, so a narrow stand-in with
    the same layer layout loads the same way (the tests use one). Max pooling is replaced by
    average pooling as in Gatys et al.; inputs are normalised with ImageNet's statistics.

Each layer's term is ``||G(x) - G(u)||_F / ||G(u)||_F``: the paper's Frobenius distance, divided
by the exemplar's own Gram norm (instead of ``1/M^2``) so that layers of very different scale
weigh alike, and **not squared**: squared, the loss grows with the fourth power of the
generator's output scale, and on this CPU set-up (Adam, step 0.05, one slice per view) it went
from 3.4 to 30,000 within four steps; unsquared it decreases steadily (measured, 40 steps).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ...errors import ParameterError
from .checkpoint import file_head, torch_load_failure

__all__ = ["RandomFilterDescriptor", "VGG19Descriptor", "gram", "gram_loss", "histogram_loss", "histogram_target",
           "make_descriptor"]


def gram(features: torch.Tensor) -> torch.Tensor:
    """(B, M, H, W) feature maps -> (B, M, M) Gram matrices averaged over the H * W positions."""
    b, m = features.shape[:2]
    flat = features.reshape(b, m, -1)
    return flat @ flat.transpose(1, 2) / flat.shape[2]


class RandomFilterDescriptor(nn.Module):
    """Feature maps of a fixed random filter bank on an image pyramid (no trained weights)."""

    def __init__(self, channels: int, *, filters: int = 48, scales: int = 5, filter_size: int = 5,
                 seed: int = 0, mean=None):
        super().__init__()
        g = torch.Generator().manual_seed(int(seed) + 7919)
        w = torch.randn((scales, filters, channels, filter_size, filter_size), generator=g)
        w = w - w.mean(dim=(2, 3, 4), keepdim=True)
        w = w / w.flatten(2).norm(dim=2).clamp_min(1e-8)[..., None, None, None]
        self.register_buffer("weight", w)
        self.register_buffer("mean", torch.zeros(1, channels, 1, 1) if mean is None
                             else torch.as_tensor(mean, dtype=torch.float32).reshape(1, channels, 1, 1))
        self.scales = scales

    def forward(self, image: torch.Tensor) -> list[torch.Tensor]:
        """(B, C, H, W) -> feature maps: the centred colours with a constant, then one ReLU
        response per pyramid scale that still holds a whole filter."""
        x = image - self.mean
        ones = torch.ones_like(x[:, :1])
        out = [torch.cat([x, ones], dim=1)]
        size = self.weight.shape[-1]
        for s in range(self.scales):
            if min(x.shape[-2:]) < size:
                break
            out.append(F.relu(F.conv2d(x, self.weight[s])))
            x = F.avg_pool2d(x, 2)
        return out


#: Positions of the convolutions in ``torchvision.models.vgg19().features`` up to conv5_1,
#: and which of them feed the loss (relu1_1, relu2_1, relu3_1, relu4_1, relu5_1).
VGG19_CONVS = (0, 2, 5, 7, 10, 12, 14, 16, 19, 21, 23, 25, 28)
VGG19_POOL_AFTER = (2, 7, 16, 25)
VGG19_LOSS_LAYERS = (0, 5, 10, 19, 28)
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def _vgg_state(path: str) -> dict:
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # any unreadable file is a user-facing error
        raise ParameterError(f"vgg19_weights '{path}' cannot be read as a torch state_dict: "
                             f"{torch_load_failure(exc, file_head(path))}") from exc
    if not isinstance(state, dict):
        raise ParameterError(f"vgg19_weights '{path}' must hold a state_dict (a dict of tensors); "
                             f"got {type(state).__name__}")
    return {k.removeprefix("features."): v for k, v in state.items() if isinstance(v, torch.Tensor)}


class VGG19Descriptor(nn.Module):
    """VGG-19's convolutions up to conv5_1 from a local ``state_dict`` (widths read from it)."""

    def __init__(self, path: str, channels: int):
        super().__init__()
        state = _vgg_state(path)
        self.convs = nn.ModuleDict()
        previous = 3
        for i in VGG19_CONVS:
            wk, bk = f"{i}.weight", f"{i}.bias"
            if wk not in state or bk not in state:
                raise ParameterError(f"vgg19_weights '{path}' is not a VGG-19 features state_dict: "
                                     f"it has no '{wk}' and '{bk}' (torchvision's layout expected)")
            w = state[wk]
            if w.ndim != 4 or w.shape[1] != previous or w.shape[2:] != (3, 3):
                raise ParameterError(f"vgg19_weights '{path}': layer {i} must be a 3x3 convolution "
                                     f"with {previous} input channels; got weight shape {tuple(w.shape)}")
            conv = nn.Conv2d(previous, w.shape[0], 3, padding=1)
            conv.weight.data.copy_(w.float())
            conv.bias.data.copy_(state[bk].float())
            conv.requires_grad_(False)
            self.convs[str(i)] = conv
            previous = w.shape[0]
        self.channels = channels
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).reshape(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(IMAGENET_STD).reshape(1, 3, 1, 1))

    def forward(self, image: torch.Tensor) -> list[torch.Tensor]:
        x = image if self.channels == 3 else image[:, :1].expand(-1, 3, -1, -1)
        x = (x - self.mean) / self.std
        out = []
        for i in VGG19_CONVS:
            x = F.relu(self.convs[str(i)](x))
            if i in VGG19_LOSS_LAYERS:
                out.append(x)
            if i in VGG19_POOL_AFTER:
                x = F.avg_pool2d(x, 2)
        return out


def make_descriptor(config, channels: int, mean) -> nn.Module:
    """The descriptor a :class:`npmrf3d.methods.neural.config.NeuralConfig` asks for."""
    if config.descriptor == "vgg19":
        return VGG19Descriptor(config.vgg19_weights, channels)
    return RandomFilterDescriptor(channels, filters=config.filters, scales=config.descriptor_scales,
                                  filter_size=config.filter_size, seed=config.seed or 0, mean=mean)


def gram_loss(descriptor: nn.Module, image: torch.Tensor, targets: list[torch.Tensor]) -> torch.Tensor:
    """Sum over layers of ``||G(image) - G_target||_F / ||G_target||_F`` (mean over the batch)."""
    total = image.new_zeros(())
    for features, target in zip(descriptor(image), targets):
        diff = gram(features) - target
        distance = (diff ** 2).sum(dim=(1, 2)).clamp_min(1e-20).sqrt()
        total = total + distance.mean() / (target ** 2).sum().sqrt().clamp_min(1e-12)
    return total


# --------------------------------------------------------------------------- value histograms


def histogram_target(exemplar: torch.Tensor, pixels: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The exemplar's value distribution as ``pixels`` quantiles per channel, and its spread.

    ``exemplar`` is (C, H, W); returns ``(C, pixels)`` sorted values (linear interpolation of
    the exemplar's sorted values at the mid-points ``(k + 0.5) / pixels``) and the ``(C,)``
    standard deviations (at least 1e-3) that make :func:`histogram_loss` dimensionless.

    >>> t, s = histogram_target(torch.arange(4.0).reshape(1, 2, 2), 2)
    >>> t.tolist()
    [[0.5, 2.5]]
    """
    flat = exemplar.reshape(exemplar.shape[0], -1).double()
    values = flat.sort(dim=1).values
    n = values.shape[1]
    where = ((torch.arange(pixels, dtype=torch.float64) + 0.5) / pixels * n - 0.5).clamp(0, n - 1)
    low = where.floor().long()
    high = (low + 1).clamp(max=n - 1)
    frac = where - low
    target = values[:, low] * (1 - frac) + values[:, high] * frac
    spread = flat.std(dim=1, unbiased=False).clamp_min(1e-3)
    return target.float(), spread.float()


def histogram_loss(image: torch.Tensor, target: torch.Tensor, spread: torch.Tensor) -> torch.Tensor:
    """Sliced-Wasserstein (sorted-value) distance of each channel's values to the exemplar's.

    ``image`` (B, C, H, W) with ``H * W`` equal to ``target``'s second axis: per image and
    channel, the root-mean-square difference between the sorted pixel values and the
    exemplar's quantiles (the 1-D Wasserstein-2 distance of the two value distributions),
    divided by the exemplar's standard deviation, averaged over channels and the batch. The
    Gram terms see only first and second moments of the values; this term pins the whole
    distribution (its range, skew and modes), which the histogram KL measures.
    """
    b, c = image.shape[:2]
    values = image.reshape(b, c, -1).sort(dim=2).values
    rms = ((values - target[None]) ** 2).mean(dim=2).clamp_min(1e-20).sqrt()
    return (rms / spread[None]).mean()
