"""On demand: any block of the unbounded volume, blocks tiling exactly."""

from __future__ import annotations

import pathlib
import subprocess
import sys

import numpy as np
import pytest
import torch

from npmrf3d.methods.neural.engine import generate_block
from npmrf3d.methods.neural.generator import SolidGenerator, plan
from tests_neural.helpers import random_generator
from tests_neural.helpers import random_model as _model


@pytest.mark.parametrize("tile", [32, 64])
def test_a_64_cube_equals_eight_32_cubes_bit_for_bit(tile):
    model = _model(tile)  # the paper's generator: 6 scales, about 85,000 parameters
    assert 80_000 < sum(p.numel() for p in model.generator.parameters()) < 90_000
    whole = generate_block(model, (0, 0, 0), (64, 64, 64))
    assert whole.dtype == np.float32
    assembled = np.empty_like(whole)
    for i in (0, 32):
        for j in (0, 32):
            for k in (0, 32):
                assembled[i:i + 32, j:j + 32, k:k + 32] = generate_block(model, (i, j, k), (32, 32, 32))
    np.testing.assert_array_equal(whole, assembled)


def test_any_block_at_any_origin_is_a_crop_of_a_larger_one():
    model = _model(16, scales=4)
    big = generate_block(model, (-21, 5, 40), (40, 36, 30))
    small = generate_block(model, (-7, 11, 53), (17, 9, 13))
    np.testing.assert_array_equal(small, big[14:31, 6:15, 13:26])


def test_margins_are_right_without_tiles_too():
    """The raw forward pass (no canonical tiles) at two splits agrees up to float rounding:
    the noise ranges and crops of :func:`plan` align every scale; only the convolution
    library's summation order (which depends on the call's shape) differs in the last bits."""
    g = random_generator(out_channels=3)
    with torch.no_grad():
        whole = g((0, 0, 0), (24, 24, 24))
        part = g((5, 13, 7), (9, 11, 17))
    np.testing.assert_allclose(part.numpy(), whole[:, :, 5:14, 13:24, 7:24].numpy(), rtol=0, atol=1e-5)


def test_tile_sizes_agree_up_to_rounding():
    a = generate_block(_model(32), (3, -9, 17), (40, 20, 24))
    b = generate_block(_model(64), (3, -9, 17), (40, 20, 24))
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-5)


def test_one_voxel_needs_the_papers_noise_support():
    """Gutierrez et al. 2020, section 4.2: one voxel needs 9^3 noise values at the finest scale and 11^3 at
    the next; the coarser supports are at most the paper's 13^3 (13, 13, 13, 9)."""
    shapes = plan((0, 0, 0), (1, 1, 1), 6).noise_shape
    assert shapes[0] == (9, 9, 9) and shapes[1] == (11, 11, 11)
    assert all(s[0] <= bound for s, bound in zip(shapes[2:], (13, 13, 13, 9)))
    for origin in range(-40, 40, 3):
        for k, s in enumerate(plan((origin,) * 3, (1, 1, 1), 6).noise_shape[2:], start=2):
            assert s[0] <= (13, 13, 13, 9)[k - 2]


def test_same_block_with_one_and_two_threads(tmp_path):
    code = ("import sys, numpy as np, torch; torch.set_num_threads(int(sys.argv[1])); "
            "sys.path.insert(0, sys.argv[3]); from tests_neural.helpers import random_model; "
            "from npmrf3d.methods.neural.engine import generate_block; "
            "np.save(sys.argv[2], generate_block(random_model(32), (0, 0, 0), (48, 40, 32)))")
    root = str(pathlib.Path(__file__).parents[1])
    for n in (1, 2):
        subprocess.run([sys.executable, "-c", code, str(n), str(tmp_path / f"{n}.npy"), root], check=True)
    np.testing.assert_array_equal(np.load(tmp_path / "1.npy"), np.load(tmp_path / "2.npy"))


def test_unpadded_blocks_trim_what_the_plan_says():
    g = SolidGenerator(scales=3, channel_step=2, noise_channels=2, out_channels=1).eval()
    with torch.no_grad():
        assert g((-3, 0, 7), (5, 1, 2)).shape == (1, 1, 5, 1, 2)


def test_channels_last_layout_gives_the_same_volume_up_to_rounding():
    """Generation runs channels-last (1x1x1 convolutions as matrix products); the values must be
    those of the contiguous layout the model trains in, and the model must come back contiguous."""
    g = random_generator(out_channels=3)
    with torch.no_grad():
        contiguous = g((3, -5, 7), (20, 20, 20), seed=2)
        last = g.channels_last(True)((3, -5, 7), (20, 20, 20), seed=2)
    assert g.is_channels_last
    assert last.shape == contiguous.shape
    np.testing.assert_allclose(last.numpy(), contiguous.numpy(), rtol=0, atol=1e-4)
    model = _model(tile=32)
    generate_block(model, (0, 0, 0), (8, 8, 8))
    assert not model.generator.is_channels_last


def test_the_inference_copy_folds_every_norm_and_computes_the_same_function():
    g = random_generator(out_channels=3)
    with torch.no_grad():  # norms with their own scale and shift, not the identity
        for m in g.modules():
            if isinstance(m, torch.nn.BatchNorm3d):
                m.weight.uniform_(0.5, 1.5)
                m.bias.uniform_(-0.3, 0.3)
        before = {k: v.clone() for k, v in g.state_dict().items()}
        reference = g((-7, 2, 30), (18, 18, 18), seed=5)
        fused = g.for_inference()
        out = fused((-7, 2, 30), (18, 18, 18), seed=5)
    assert not any(isinstance(m, torch.nn.BatchNorm3d) for m in fused.modules())
    assert fused.is_channels_last and not g.is_channels_last
    for k, v in g.state_dict().items():  # the model itself is untouched
        torch.testing.assert_close(v, before[k], rtol=0, atol=0)
    np.testing.assert_allclose(out.numpy(), reference.numpy(), rtol=0, atol=1e-4)
    assert float(reference.std()) > 1e-2  # a non-trivial function, so the match means something
