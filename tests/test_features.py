"""The line-distance channel of the coherent sampler (npmrf3d.model.features)."""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d.errors import ParameterError
from npmrf3d.methods.npmrf_coherent import coherent_synthesize, make_coherent_config
from npmrf3d.model.features import CLIP, line_distance, with_feature


def _mortar(size: int = 32, step: int = 8) -> np.ndarray:
    """Grey blocks between one-pixel dark mortar lines, (size, size, 1) float32."""
    rng = np.random.default_rng(0)
    e = 0.6 + 0.1 * rng.random((size, size))
    e[::step] = 0.1
    e[:, 3::step] = 0.1
    return e[..., None].astype(np.float32)


def test_line_distance_is_the_distance_to_the_nearest_dark_line():
    e = _mortar()[..., 0]
    lines = np.argwhere(e < 0.2)
    rows, cols = np.indices(e.shape)
    brute = np.sqrt(((rows[..., None] - lines[:, 0]) ** 2 + (cols[..., None] - lines[:, 1]) ** 2).min(axis=-1))
    assert np.allclose(line_distance(e), np.minimum(brute, CLIP))


def test_an_image_without_lines_is_far_from_them_everywhere():
    assert np.all(line_distance(np.full((12, 12), 0.5)) == CLIP)
    assert np.all(with_feature(np.full((12, 12, 3), 0.5, dtype=np.float32), 1.0)[..., 3] == 0.0)


@pytest.mark.parametrize("weight", [0.5, 2.0])
def test_the_channel_is_scaled_to_the_weight_and_the_colours_kept(weight):
    e = np.repeat(_mortar(), 3, axis=-1) * np.array([1.0, 0.8, 0.5], dtype=np.float32)
    out = with_feature(e, weight)
    assert out.shape == (32, 32, 4) and out.dtype == np.float32
    assert np.array_equal(out[..., :3], e)
    assert abs(out[..., 3].mean()) < 1e-5
    assert out[..., 3].std() == pytest.approx(weight * e.std(), rel=1e-5)
    assert out[..., 3][e[..., 0] < 0.2].max() < out[..., 3].mean()   # on a line: the lowest values


def test_the_volume_keeps_the_exemplars_channels_and_colours():
    e = _mortar()
    with_channel = coherent_synthesize(e, size=16, window=5, levels=2, grid=2, iterations=(2, 1), rng=1,
                                       feature_weight=2.0).volume
    without = coherent_synthesize(e, size=16, window=5, levels=2, grid=2, iterations=(2, 1), rng=1,
                                  feature_weight=0.0).volume
    assert with_channel.shape == without.shape == (16, 16, 16, 1)
    assert np.isin(with_channel, e).all()                   # every voxel an exemplar colour
    assert not np.array_equal(with_channel, without)        # the channel took part


def test_a_negative_weight_is_refused_by_name():
    with pytest.raises(ParameterError, match="feature_weight"):
        make_coherent_config(size=32, window=5, levels=2, feature_weight=-1.0)
