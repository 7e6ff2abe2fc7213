"""The neural method's frozen configuration and its validation (its memory estimate is
:func:`npmrf3d.resources.neural_estimate`).

No torch here: the registry (:mod:`npmrf3d.methods`), ``npmrf3d info`` and the command line's
``--help`` read this module without the ``[neural]`` extra installed.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass

from ... import _validation as check
from ...config import DEFAULT_SIZE
from ...model.neighbourhood import VIEWS

__all__ = ["DESCRIPTORS", "ORIGIN_LIMIT", "ZARR_BLOCK", "ZARR_WORKERS", "NeuralConfig", "make_neural_config"]

#: Side of the blocks (and Zarr chunks) that ``write_zarr`` writes, and its local Dask workers.
ZARR_BLOCK = 128
#: Largest distance of a generated block's first voxel from the lattice origin, per axis: the
#: noise hashes 64-bit lattice coordinates, so farther blocks cannot be made.
ORIGIN_LIMIT = 2 ** 40
ZARR_WORKERS = 2
#: The texture descriptors training can compare slices with (see :mod:`npmrf3d.methods.neural.descriptor`).
DESCRIPTORS = ("random", "vgg19")


#: Largest training slice side taken from the exemplar when ``slice_size`` is None.
AUTO_SLICE_MAX = 128


@dataclass(frozen=True)
class NeuralConfig:
    """A validated training (and generation) run of the on-demand generator (Gutierrez et al. 2020).

    Attributes
    ----------
    size : (3,) tuple of int
        Volume made by the registry method and by ``npmrf3d neural generate`` (voxels per axis).
    views : tuple of str
        Constrained views; each view's slices are compared with its exemplar.
    iterations : int
        Optimiser steps (one step: ``batch`` slices per view). Why 1,000 by default: on
        ``gravel64`` 1,200 steps took the orientation KL from 0.18 (100 steps) to 0.042 and on
        ``lawn`` 1,000 from 0.22 to 0.12, every other metric better too. On 2 CPU cores (AMD
        EPYC) 1,000 steps take 12-14 min for a 64x64 exemplar and about 45 min for a 128x128 one
        (2.7 s a step); 600 steps keep the latter inside 30 minutes (README, "Quality, longer
        training").
    slice_size : int or None
        Side of the training slices; None: the exemplar's side, at most 128.
    batch : int
        Slices per view and step.
    learning_rate : float
        Adam's step size.
    scales, noise_channels, channel_step : int
        The generator: ``K + 1`` noise scales, ``M_i`` noise channels, ``M_s`` channel step
        (the paper: 6, 3, 4 — about 85,000 parameters).
    tile : int
        Side of the canonical tiles generation computes (a multiple of ``2**(scales - 1)``): a
        block is cut from the tiles that cover it, so its values do not depend on how a volume is
        split into blocks (bit for bit).
    descriptor : {"random", "vgg19"}
        ``random``: Gram matrices of a fixed random filter bank on an image pyramid (no weights
        needed); ``vgg19``: Gram matrices of VGG-19 layers read from ``vgg19_weights``.
    vgg19_weights : str or None
        A local VGG-19 ``state_dict`` file (torchvision's layout); needed for ``vgg19``.
    filters, descriptor_scales, filter_size : int
        The random descriptor: filters per scale, pyramid scales, filter side.
    histogram_weight : float
        Weight of the value-histogram term of the loss (:func:`npmrf3d.methods.neural.descriptor.
        histogram_loss`: sorted slice values against the exemplar's quantiles, per channel) beside
        the Gram terms; 0 leaves it out (the paper's loss).
    calibrate : bool
        After training, fit a monotone map per channel (per principal component of the
        exemplars' colours, for colour) that takes the quantiles of a
        calibration block of the generator's output to the exemplars' quantiles, and apply it
        to every generated value (:func:`npmrf3d.methods.neural.engine.fit_calibration`). The map is
        pointwise, so blocks still tile exactly; it corrects the value histogram the Gram
        descriptor leaves off (this project's addition; False: the paper's raw output).
    checkpoint_every : int
        Steps between two checkpoints (when a checkpoint file is given).
    seed : int or None
        Seeds the weights, the filter bank, the slice positions and the model's noise.
    """

    size: tuple[int, int, int] = (DEFAULT_SIZE,) * 3
    views: tuple[str, ...] = VIEWS
    iterations: int = 1000
    slice_size: int | None = None
    batch: int = 1
    learning_rate: float = 0.05
    scales: int = 6
    noise_channels: int = 3
    channel_step: int = 4
    tile: int = 64
    descriptor: str = "random"
    vgg19_weights: str | None = None
    filters: int = 48
    descriptor_scales: int = 5
    filter_size: int = 5
    histogram_weight: float = 1.0
    calibrate: bool = True
    checkpoint_every: int = 25
    seed: int | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def architecture(self) -> dict:
        """The generator's constructor arguments (without the output channels and the seed)."""
        return {"scales": self.scales, "noise_channels": self.noise_channels,
                "channel_step": self.channel_step}

    def slice_side(self, exemplar_shape=None) -> int:
        """The training slice side: ``slice_size``, or the side of an exemplar of
        ``exemplar_shape`` (unknown: :data:`AUTO_SLICE_MAX`), at most :data:`AUTO_SLICE_MAX`."""
        if self.slice_size is not None:
            return self.slice_size
        if exemplar_shape is None:
            return AUTO_SLICE_MAX
        return max(8, min(AUTO_SLICE_MAX, int(exemplar_shape[0]), int(exemplar_shape[1])))


def make_neural_config(*, size=NeuralConfig.size, views=NeuralConfig.views,
                       iterations: int = NeuralConfig.iterations, slice_size=NeuralConfig.slice_size,
                       batch: int = NeuralConfig.batch, learning_rate: float = NeuralConfig.learning_rate,
                       scales: int = NeuralConfig.scales, noise_channels: int = NeuralConfig.noise_channels,
                       channel_step: int = NeuralConfig.channel_step, tile: int = NeuralConfig.tile,
                       descriptor: str = NeuralConfig.descriptor, vgg19_weights=NeuralConfig.vgg19_weights,
                       filters: int = NeuralConfig.filters,
                       descriptor_scales: int = NeuralConfig.descriptor_scales,
                       filter_size: int = NeuralConfig.filter_size,
                       histogram_weight: float = NeuralConfig.histogram_weight,
                       calibrate: bool = NeuralConfig.calibrate,
                       checkpoint_every: int = NeuralConfig.checkpoint_every,
                       seed=NeuralConfig.seed) -> NeuralConfig:
    """Validate plain keyword arguments into a :class:`NeuralConfig` (``ParameterError``).

    >>> make_neural_config(iterations=10, size=16).size
    (16, 16, 16)
    """
    scales = check.integer("scales", scales, low=1, high=10)
    tile = check.integer("tile", tile, low=1)
    period = 2 ** (scales - 1)
    if tile % period:
        check.fail(f"tile must be a multiple of 2**(scales-1) = {period}; got {tile}")
    descriptor = check.choice("descriptor", descriptor, DESCRIPTORS)
    if descriptor == "vgg19":
        if vgg19_weights is None:
            check.fail("vgg19_weights must name a local VGG-19 weights file when descriptor is vgg19; got None")
        if not os.path.isfile(vgg19_weights):
            check.fail(f"vgg19_weights must be an existing file; got {str(vgg19_weights)!r}")
        vgg19_weights = os.fspath(vgg19_weights)
    elif vgg19_weights is not None:
        check.fail(f"vgg19_weights is only used with descriptor vgg19; got descriptor {descriptor!r}")
    if seed is not None:
        seed = check.integer("seed", seed, low=0, high=2**62)
    if slice_size is not None:
        slice_size = check.integer("slice_size", slice_size, low=8, high=1024)
    return NeuralConfig(
        size=check.triple("size", size, low=1), views=check.views(views, VIEWS),
        iterations=check.integer("iterations", iterations, low=1, high=10**7),
        slice_size=slice_size, batch=check.integer("batch", batch, low=1, high=64),
        learning_rate=check.real("learning_rate", learning_rate, low=0.0, high=10.0, low_open=True),
        scales=scales, noise_channels=check.integer("noise_channels", noise_channels, low=1, high=64),
        channel_step=check.integer("channel_step", channel_step, low=1, high=64), tile=tile,
        descriptor=descriptor, vgg19_weights=vgg19_weights,
        filters=check.integer("filters", filters, low=1, high=1024),
        descriptor_scales=check.integer("descriptor_scales", descriptor_scales, low=1, high=8),
        filter_size=check.integer("filter_size", filter_size, low=1, high=15),
        histogram_weight=check.real("histogram_weight", histogram_weight, low=0.0, high=1000.0),
        calibrate=check.boolean("calibrate", calibrate),
        checkpoint_every=check.integer("checkpoint_every", checkpoint_every, low=1),
        seed=seed)
