"""Helpers of the torch tests (imported as ``tests_neural.helpers``)."""

from __future__ import annotations

import torch

from npmrf3d.methods.neural.config import make_neural_config
from npmrf3d.methods.neural.engine import NeuralModel
from npmrf3d.methods.neural.generator import SolidGenerator


def random_generator(**kwargs) -> SolidGenerator:
    """An untrained generator in evaluation mode whose normalisation statistics are not the
    identity (so the tiling tests exercise them)."""
    torch.manual_seed(0)
    g = SolidGenerator(**kwargs)
    with torch.no_grad():
        for m in g.modules():
            if isinstance(m, torch.nn.BatchNorm3d):
                m.running_mean.uniform_(-0.5, 0.5)
                m.running_var.uniform_(0.5, 2.0)
    return g.eval()


def random_model(tile: int, **arch) -> NeuralModel:
    """:func:`random_generator` with 3 output channels, wrapped as a model with ``tile``."""
    config = make_neural_config(tile=tile, **arch)
    return NeuralModel(random_generator(out_channels=3, **config.architecture), config)
