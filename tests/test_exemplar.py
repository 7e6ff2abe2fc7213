"""Exemplar loading, label sets, patches and decimation phases (docs/model.md, sections 1, 2 and 7)."""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d import data
from npmrf3d.model.exemplar import decimation_phases, extract_patches, load_exemplar, make_labels
from tests import naive

#: Seed of the shared ``rng`` fixture (tests/conftest.py).
RNG_SEED = 2024


# --------------------------------------------------------------------------- load_exemplar


def test_uint8_scaled_to_unit_interval():
    a = np.array([[0, 51], [255, 128]], dtype=np.uint8)
    out = load_exemplar(a)
    assert out.dtype == np.float32 and out.shape == (2, 2, 1)
    np.testing.assert_allclose(out[..., 0], a / 255.0, rtol=1e-7)
    assert out.max() == 1.0 and out.min() == 0.0


def test_uint16_scaled_to_unit_interval():
    a = np.array([[0, 1000], [65535, 32768]], dtype=np.uint16)
    out = load_exemplar(a)
    assert out.dtype == np.float32 and out.shape == (2, 2, 1)
    np.testing.assert_allclose(out[..., 0], a / 65535.0, rtol=1e-7)
    assert out.max() == 1.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int32])
def test_other_numbers_keep_their_units(dtype):
    a = np.array([[-3.0, 0.5], [1000.0, 2.0]]).astype(dtype)
    out = load_exemplar(a)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out[..., 0], a.astype(np.float32))


def test_bool_is_zero_one():
    a = np.array([[True, False], [False, True]])
    out = load_exemplar(a)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out[..., 0], [[1.0, 0.0], [0.0, 1.0]])


def test_shapes(rng):
    assert load_exemplar(np.zeros((8, 9), dtype=np.uint8)).shape == (8, 9, 1)
    colour = rng.integers(0, 256, size=(5, 6, 3), dtype=np.uint8)
    out = load_exemplar(colour)
    assert out.shape == (5, 6, 3) and out.flags.c_contiguous
    np.testing.assert_allclose(out, colour / 255.0, rtol=1e-7)
    assert load_exemplar(np.zeros((4, 4, 7))).shape == (4, 4, 7)  # any channel count


def test_input_is_not_modified(rng):
    a = rng.random((6, 6))
    before = a.copy()
    out = load_exemplar(a)
    out[...] = 7.0
    np.testing.assert_array_equal(a, before)


def test_files_round_trip(tmp_path, rng):
    import imageio.v3 as iio

    grey = rng.integers(0, 256, size=(12, 10), dtype=np.uint8)
    iio.imwrite(tmp_path / "g.png", grey)
    out = load_exemplar(tmp_path / "g.png")
    assert out.shape == (12, 10, 1)
    np.testing.assert_allclose(out[..., 0], grey / 255.0, rtol=1e-7)
    arr = rng.random((7, 8, 2))
    np.save(tmp_path / "a.npy", arr)
    np.testing.assert_allclose(load_exemplar(str(tmp_path / "a.npy")), arr.astype(np.float32))


def test_default_exemplar_is_bundled():
    out = load_exemplar()
    assert out.ndim == 3 and out.dtype == np.float32
    assert 0.0 <= out.min() and out.max() <= 1.0
    assert hasattr(data, "DEFAULT_EXEMPLAR")


# --------------------------------------------------------------------------- make_labels


def test_distinct_values_are_the_labels(rng):
    ex = (rng.integers(0, 5, size=(9, 11, 1)) / 4).astype(np.float32)
    labels, (image,) = make_labels([ex], rng=rng)
    assert labels.dtype == np.float32 and labels.shape[1] == 1
    np.testing.assert_array_equal(labels[:, 0], np.unique(ex))
    assert image.dtype == np.int32 and image.shape == (9, 11)
    np.testing.assert_array_equal(labels[image], ex)


def test_labels_shared_by_several_exemplars(rng):
    a = (rng.integers(0, 4, size=(6, 7, 3)) / 3).astype(np.float32)
    b = (rng.integers(2, 6, size=(8, 5, 3)) / 5).astype(np.float32)
    labels, (ia, ib) = make_labels([a, b], rng=rng)
    pooled = np.concatenate([a.reshape(-1, 3), b.reshape(-1, 3)])
    np.testing.assert_array_equal(labels, np.unique(pooled, axis=0))
    np.testing.assert_array_equal(labels[ia], a)
    np.testing.assert_array_equal(labels[ib], b)
    # lexicographic order
    assert [tuple(x) for x in labels] == sorted(tuple(x) for x in labels)


@pytest.mark.parametrize("channels", [1, 3])
def test_grey_levels(rng, channels):
    ex = rng.random((16, 16, channels)).astype(np.float32)
    labels, (image,) = make_labels([ex], grey_levels=4, rng=rng)
    for c in range(channels):
        assert len(np.unique(labels[:, c])) <= 4
    # evenly spaced levels between the pooled min and max; each pixel goes to the nearest level
    lo, hi = float(ex.min()), float(ex.max())
    levels = lo + np.arange(4) * (hi - lo) / 3
    values = labels[image]
    assert (np.abs(values[..., None] - levels).min(axis=-1) < 1e-6).all()
    assert (np.abs(values - ex) <= (hi - lo) / 6 + 1e-6).all()


def test_palette_on_colour_image(rng):
    colours = rng.random((10, 3)).astype(np.float32)
    ex = colours[rng.integers(0, 10, size=(20, 20))]
    labels, (image,) = make_labels([ex], palette=3, rng=rng)
    assert labels.shape[0] <= 3 and labels.shape[1] == 3
    pixels = ex.reshape(-1, 3).astype(np.float64)
    d2 = ((pixels[:, None, :] - labels[None, :, :].astype(np.float64)) ** 2).sum(axis=2)
    own = d2[np.arange(len(pixels)), image.ravel()]
    assert (own <= d2.min(axis=1) + 1e-6).all()


def test_palette_is_not_applied_when_few_colours(rng):
    ex = np.array([[0.0, 1.0], [0.5, 0.0]], dtype=np.float32)[:, :, None].repeat(3, axis=2)
    labels, (image,) = make_labels([ex], palette=5, rng=rng)
    assert len(labels) == 3
    np.testing.assert_array_equal(labels[image], ex)


def test_palette_is_seeded():
    ex = np.random.default_rng(0).random((12, 12, 3)).astype(np.float32)
    a, _ = make_labels([ex], palette=4, rng=np.random.default_rng(5))
    b, _ = make_labels([ex], palette=4, rng=np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------- patches


@pytest.mark.parametrize("window", [3, 5])
@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("toroidal", [False, True])
def test_extract_patches_matches_naive(rng, window, channels, toroidal):
    ex = (rng.integers(0, 4, size=(9, 11, channels)) / 3).astype(np.float32)
    labels, (image,) = make_labels([ex], rng=rng)
    patches, centres = extract_patches(image, labels, window, toroidal=toroidal)
    ref, ref_centres = naive.naive_extract_patches(image, labels, window, toroidal=toroidal)
    n = 9 * 11 if toroidal else (9 - window + 1) * (11 - window + 1)
    assert patches.shape == (n, (window**2 - 1) * channels) and patches.dtype == np.float32
    assert centres.shape == (n,) and centres.dtype == np.int32
    np.testing.assert_array_equal(patches.reshape(ref.shape), ref)
    np.testing.assert_array_equal(centres, ref_centres)


def test_extract_patches_layout():
    """patches[p, m*C + c] is channel c of the m-th neighbour in window_offsets order."""
    image = np.arange(25, dtype=np.int32).reshape(5, 5)
    labels = np.stack([np.arange(25), -np.arange(25)], axis=1).astype(np.float32)
    patches, centres = extract_patches(image, labels, 3)
    assert centres.tolist() == [6, 7, 8, 11, 12, 13, 16, 17, 18]
    # centre 6 = (1, 1): neighbours (0,0) (0,1) (0,2) (1,0) (1,2) (2,0) (2,1) (2,2)
    expect = [0, 1, 2, 5, 7, 10, 11, 12]
    assert patches[0, 0::2].tolist() == expect
    assert patches[0, 1::2].tolist() == [-x for x in expect]


# --------------------------------------------------------------------------- decimation


@pytest.mark.parametrize("level", [0, 1, 2, 3])
@pytest.mark.parametrize("shape", [(16, 16), (13, 10), (5, 3)])
def test_decimation_phases_cover_every_pixel_once(level, shape):
    image = np.arange(shape[0] * shape[1]).reshape(shape)
    phases = decimation_phases(image, level)
    assert len(phases) == 4**level
    seen = np.concatenate([p.ravel() for p in phases])
    np.testing.assert_array_equal(np.sort(seen), np.arange(image.size))
    f = 2**level
    for idx, p in enumerate(phases):
        a, b = divmod(idx, f)
        np.testing.assert_array_equal(p, image[a::f, b::f])
