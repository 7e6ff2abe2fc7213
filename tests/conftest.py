"""Shared fixtures: a seeded ``rng`` and tiny exemplars (no downloads, a few pixels each).

A test module chooses the seed of its ``rng`` with a module-level ``RNG_SEED`` (default 0),
so moving a module's own fixture here kept every test's random draws as they were.
"""

from __future__ import annotations

import importlib.util
import pathlib
import sys

import numpy as np
import pytest

BENCHMARKS = pathlib.Path(__file__).resolve().parents[1] / "benchmarks"


def benchmark_module(name: str):
    """Import ``benchmarks/<name>.py`` (which imports its sibling modules by plain name) and
    register it in ``sys.modules`` (dataclasses look their module up there)."""
    sys.path.insert(0, str(BENCHMARKS))
    try:
        spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCHMARKS))
    return module


def checkerboard(side: int = 24, block: int = 2) -> np.ndarray:
    """A 2D uint8 checkerboard of period ``2 * block``; every axis-aligned slice of the 3D
    checkerboard ``((i//b) + (j//b) + (k//b)) % 2`` is a shifted copy of it."""
    r = np.arange(side) // block
    return (((r[:, None] + r[None, :]) % 2) * 255).astype(np.uint8)


@pytest.fixture
def rng(request) -> np.random.Generator:
    """``np.random.default_rng(RNG_SEED)`` of the requesting module (0 when it sets none)."""
    return np.random.default_rng(getattr(request.module, "RNG_SEED", 0))


@pytest.fixture
def tiny_grey() -> np.ndarray:
    """A 24x24 grey checkerboard exemplar (uint8, two values)."""
    return checkerboard()


@pytest.fixture
def tiny_rgb() -> np.ndarray:
    """A 16x16x3 float32 exemplar with four colours in 4x4 blocks."""
    colours = np.array([[0.9, 0.1, 0.1], [0.1, 0.8, 0.2], [0.1, 0.2, 0.9], [0.9, 0.9, 0.2]],
                       dtype=np.float32)
    r = np.arange(16) // 4
    return colours[(r[:, None] + 2 * r[None, :]) % 4]
