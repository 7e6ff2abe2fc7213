"""Tests for npmrf3d.analysis.metrics: each metric against an independent implementation, sanity on
stacked exemplars and white noise, colour, input checks.

Independent references: ``scipy.stats.entropy`` (KL), ``scipy.stats.wasserstein_distance``
(1-D W1), scikit-image's ``structure_tensor``/``structure_tensor_eigenvalues`` (orientation),
explicit loops over lags and pixel pairs (autocorrelation, two-point correlation) and over
patch positions (sliced Wasserstein). Arrays are small; the file runs in a few seconds.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from scipy import ndimage, stats

from npmrf3d.analysis import metrics
from npmrf3d.errors import ParameterError
from npmrf3d.model.neighbourhood import VIEW_AXES, VIEWS

S = metrics.DEFAULT_SETTINGS


def smooth_texture(shape, sigma=1.5, seed=0) -> np.ndarray:
    """A smooth random field in [0, 1] (structure at a few pixels)."""
    x = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(shape), sigma,
                                mode="wrap")
    return (x - x.min()) / (x.max() - x.min())


def stack_along(exemplar: np.ndarray, view: str, depth: int) -> np.ndarray:
    """A volume whose every slice in ``view`` is ``exemplar`` ((H, W) or (H, W, C))."""
    row_axis, col_axis = VIEW_AXES[view]
    fixed = ({0, 1, 2} - {row_axis, col_axis}).pop()
    stacked = np.stack([exemplar] * depth)  # (depth, H, W[, C])
    return np.ascontiguousarray(np.moveaxis(stacked, (0, 1, 2), (fixed, row_axis, col_axis)))


# --------------------------------------------------------------------------- KL and histograms


def test_kl_divergence_matches_scipy_entropy():
    rng = np.random.default_rng(1)
    for _ in range(20):
        p, q = rng.random(17), rng.random(17)
        assert metrics.kl_divergence(p, q, eps=0) == pytest.approx(stats.entropy(p, q), rel=1e-12)
        q[rng.integers(0, 17, 3)] = 0  # empty bins: eps keeps the value finite
        eps = 1e-6
        ref = stats.entropy(p / p.sum() + eps, q / q.sum() + eps)
        value = metrics.kl_divergence(p, q, eps=eps)
        assert np.isfinite(value) and value == pytest.approx(ref, rel=1e-12)
        assert value >= 0
        assert metrics.kl_divergence(p, p) == 0.0
        assert abs(metrics.kl_divergence(p, 3 * p)) < 1e-12


def test_kl_divergence_rejects_bad_histograms():
    with pytest.raises(ParameterError, match="same, non-zero number of bins"):
        metrics.kl_divergence([1, 2], [1, 2, 3])
    with pytest.raises(ParameterError, match="non-negative"):
        metrics.kl_divergence([1, -1], [1, 1])
    with pytest.raises(ParameterError, match="positive total"):
        metrics.kl_divergence([0, 0], [1, 1])


def test_grey_histogram_kl_matches_numpy_histogram_and_scipy():
    rng = np.random.default_rng(2)
    exemplar = rng.random((20, 24, 1)) * 0.6 + 0.2
    volume = rng.random((6, 7, 8, 1))  # values outside the exemplar range: clipped into end bins
    lo, hi = exemplar.min(), exemplar.max()
    edges = np.linspace(lo, hi, 33)
    p = np.histogram(exemplar, edges)[0]
    q = np.histogram(np.clip(volume, lo, hi), edges)[0]
    eps = S.eps
    ref = stats.entropy(p / p.sum() + eps, q / q.sum() + eps)
    assert metrics.histogram_kl(exemplar, volume) == pytest.approx(ref, rel=1e-9)
    assert metrics.histogram_kl(exemplar[..., 0], volume[..., 0]) == pytest.approx(ref, rel=1e-9)
    assert metrics.histogram_kl(exemplar, np.stack([exemplar] * 3)) == 0.0


def test_joint_colour_histogram_kl_matches_a_digitised_count():
    rng = np.random.default_rng(3)
    exemplar = rng.random((16, 16, 3)) ** 2
    volume = rng.random((5, 6, 7, 3))
    bins = 4
    index = np.zeros(exemplar[..., 0].shape, int), np.zeros(volume[..., 0].shape, int)
    for c in range(3):
        lo, hi = exemplar[..., c].min(), exemplar[..., c].max()
        for k, array in enumerate((exemplar, volume)):
            cell = np.floor((np.clip(array[..., c], lo, hi) - lo) / (hi - lo) * bins).astype(int)
            index[k][...] = index[k] * bins + np.minimum(cell, bins - 1)
    p = np.bincount(index[0].ravel(), minlength=bins**3)
    q = np.bincount(index[1].ravel(), minlength=bins**3)
    ref = stats.entropy(p / p.sum() + S.eps, q / q.sum() + S.eps)
    assert metrics.joint_histogram_kl(exemplar, volume, bins=bins) == pytest.approx(ref, rel=1e-9)
    per_channel = metrics.channel_histogram_kl(exemplar, volume, bins=8)
    for c, value in enumerate(per_channel):
        assert value == pytest.approx(metrics.histogram_kl(exemplar[..., c:c + 1],
                                                           volume[..., c:c + 1], bins=8))


def test_joint_bins_shrink_for_many_channels():
    volume = np.random.default_rng(0).random((4, 5, 6, 6))
    result = metrics.evaluate(volume, volume[0], views="right")
    assert result["settings"]["joint_bins_used"] == 6  # 6**6 <= 2**16 < 7**6
    assert metrics.evaluate(volume[..., :3], volume[0, ..., :3], views="right")[
        "settings"]["joint_bins_used"] == 8


# --------------------------------------------------------------------------- autocorrelation


def brute_autocorrelation(images: np.ndarray, max_lag: int) -> np.ndarray:
    """Explicit loops over lags and pixel pairs (see metrics.autocorrelation's definition)."""
    images = np.asarray(images, dtype=np.float64)
    _, h, w = images.shape
    centred = [x - x.mean() for x in images]
    size = 2 * max_lag + 1
    cov = np.zeros((size, size))
    for a in range(-max_lag, max_lag + 1):
        for b in range(-max_lag, max_lag + 1):
            total, pairs = 0.0, 0
            for x in centred:
                for r in range(h):
                    for c in range(w):
                        if 0 <= r + a < h and 0 <= c + b < w:
                            total += x[r, c] * x[r + a, c + b]
                            pairs += 1
            cov[a + max_lag, b + max_lag] = total / pairs
    return cov / cov[max_lag, max_lag]


def test_autocorrelation_matches_brute_force_loops():
    rng = np.random.default_rng(4)
    images = rng.random((3, 9, 7)) + np.linspace(0, 1, 7)  # a trend along columns
    np.testing.assert_allclose(metrics.autocorrelation(images, 3), brute_autocorrelation(images, 3),
                               atol=1e-12)
    one = images[0]
    np.testing.assert_allclose(metrics.autocorrelation(one, 4), brute_autocorrelation(one[None], 4),
                               atol=1e-12)
    assert not metrics.autocorrelation(np.ones((6, 6)), 2).any()  # constant: all zeros


def test_autocorrelation_error_matches_brute_force_on_a_view():
    rng = np.random.default_rng(5)
    exemplar = rng.random((8, 10, 1))
    volume = rng.random((6, 8, 10, 1))  # right slices volume[i] are 8 x 10
    ref = np.sqrt(((brute_autocorrelation(exemplar[None, ..., 0], 3)
                    - brute_autocorrelation(volume[..., 0], 3)) ** 2).sum())
    assert metrics.autocorrelation_error(exemplar, volume, "right", 3) == pytest.approx(ref)
    result = metrics.evaluate(volume, exemplar, views="right",
                              settings=metrics.MetricSettings(max_lag=3))
    assert result["per_view"]["right"]["autocorrelation_l2"] == pytest.approx(ref)


def test_small_exemplars_reduce_the_lag_to_half_the_smallest_side():
    exemplar = smooth_texture((20, 40))
    volume = smooth_texture((12, 20, 40), seed=1)
    result = metrics.evaluate(volume, exemplar, views=["right"])
    assert result["details"]["right"]["max_lag"] == 10  # min(32, 20 // 2, 40 // 2)
    assert result["settings"]["max_lag"] == 32
    assert result["settings"]["max_lag_per_view"] == {"right": 10}
    assert metrics.effective_max_lag(32, (128, 128), (64, 70)) == 32
    # front slices of a 12 x 20 x 40 volume are 12 x 20: the lag follows the slices too
    assert metrics.evaluate(volume, {"front": smooth_texture((12, 20))})[
        "details"]["front"]["max_lag"] == 6


# --------------------------------------------------------------------------- orientation


def skimage_orientation(image: np.ndarray):
    """Angle in [0, pi) and coherence from scikit-image's structure tensor and eigenvalues."""
    from skimage.feature import structure_tensor, structure_tensor_eigenvalues

    smoothed = ndimage.gaussian_filter(image, S.gradient_sigma, mode="reflect")
    arr, arc, acc = structure_tensor(smoothed, sigma=S.integration_sigma, mode="reflect",
                                     order="rc")
    l1, l2 = structure_tensor_eigenvalues(np.stack([arr, arc, acc]))
    coherence = np.where(l1 + l2 > 0, (l1 - l2) / np.where(l1 + l2 > 0, l1 + l2, 1), 0)
    # eigenvector of the largest eigenvalue in (column, row) coordinates, per pixel
    tensor = np.stack([np.stack([acc, arc], -1), np.stack([arc, arr], -1)], -2)
    _, vectors = np.linalg.eigh(tensor)
    top = vectors[..., :, 1]
    angle = np.mod(np.arctan2(top[..., 1], top[..., 0]), np.pi)
    return angle, coherence


def test_orientation_field_matches_skimage_structure_tensor():
    image = smooth_texture((40, 36), sigma=2.0, seed=6)
    angle, coherence = metrics.orientation_field(image)
    ref_angle, ref_coherence = skimage_orientation(image)
    np.testing.assert_allclose(coherence, ref_coherence, atol=1e-8)
    strong = ref_coherence > 0.05  # where the direction is defined
    diff = np.abs(angle - ref_angle)[strong]
    assert np.minimum(diff, np.pi - diff).max() < 1e-6


def test_orientation_kl_matches_skimage_histograms_and_scipy_entropy():
    exemplar = smooth_texture((32, 32), sigma=2.0, seed=7)
    volume = np.stack([smooth_texture((32, 32), sigma=(1.0, 3.0), seed=s) for s in range(4)])
    hists = []
    for images in ([exemplar], list(volume)):
        pairs = [skimage_orientation(x) for x in images]
        angles = np.concatenate([a.ravel() for a, _ in pairs])
        weights = np.concatenate([c.ravel() for _, c in pairs])
        h = np.histogram(angles, bins=S.orientation_bins, range=(0, np.pi), weights=weights)[0]
        hists.append(h / h.sum())
    np.testing.assert_allclose(metrics.orientation_histogram(volume), hists[1], atol=1e-6)
    ref = stats.entropy(hists[0] + S.eps, hists[1] + S.eps)
    assert metrics.orientation_kl(exemplar, volume, "right") == pytest.approx(ref, rel=1e-4)
    assert ref > 0.05  # anisotropic slices versus an isotropic exemplar


def test_orientation_convention_and_unweighted_histogram():
    n, m = 40, 12  # the border margin m clears the filters' reach (integration 4 sigma + 2)
    ramp = np.sin(np.arange(n) / 2.0)
    vertical = np.tile(ramp, (n, 1))         # values change along a row: angle 0
    horizontal = vertical.T                  # values change down a column: angle pi/2
    diagonal = np.sin((np.add.outer(np.arange(n), np.arange(n))) / 2.0)  # along r + c: pi/4
    for image, expected in ((vertical, 0.0), (horizontal, np.pi / 2), (diagonal, np.pi / 4)):
        angle, coherence = metrics.orientation_field(image)
        diff = np.abs(angle[m:-m, m:-m] - expected)
        assert np.minimum(diff, np.pi - diff).max() < 1e-6
        assert coherence[m:-m, m:-m].min() > 0.99
    flat = metrics.orientation_histogram(np.ones((10, 10)))
    np.testing.assert_allclose(flat, 1 / S.orientation_bins)  # no gradient: uniform
    unweighted = metrics.orientation_histogram(vertical, coherence_weighting=False)
    assert unweighted.sum() == pytest.approx(1.0) and unweighted[0] > 0.9


# --------------------------------------------------------------------------- sliced Wasserstein


def test_wasserstein_1d_matches_scipy():
    rng = np.random.default_rng(8)
    for n, m in ((5, 5), (7, 3), (40, 61), (1, 9)):
        u, v = rng.standard_normal(n), rng.standard_normal(m) * 2 + 0.5
        assert float(metrics.wasserstein_1d(u, v)) == pytest.approx(
            stats.wasserstein_distance(u, v), rel=1e-12, abs=1e-14)
    u, v = rng.random((30, 4)), rng.random((17, 4))
    np.testing.assert_allclose(metrics.wasserstein_1d(u, v),
                               [stats.wasserstein_distance(u[:, j], v[:, j]) for j in range(4)])


def test_sliced_wasserstein_matches_explicit_patches_and_projections():
    settings = metrics.MetricSettings(patch=3, projections=5, max_patches=10_000, seed=4)
    rng = np.random.default_rng(9)
    exemplar, volume = rng.random((6, 7, 2)), rng.random((3, 6, 5, 2))
    p = settings.patch

    def patches(images):
        return np.array([img[r:r + p, c:c + p].transpose(2, 0, 1).ravel() for img in images
                         for r in range(img.shape[0] - p + 1) for c in range(img.shape[1] - p + 1)])

    def centred(x):  # each channel's mean within the patch removed
        x = x.reshape(len(x), 2, p * p)
        return (x - x.mean(axis=2, keepdims=True)).reshape(len(x), -1)

    directions = np.random.default_rng(settings.seed).standard_normal((p * p * 2, 5))
    directions /= np.linalg.norm(directions, axis=0)
    raw_a, raw_b = patches([exemplar]), patches(list(metrics.view_slices(volume, "top")))
    for centre, (a, b) in ((False, (raw_a, raw_b)), (True, (centred(raw_a), centred(raw_b)))):
        a, b = a @ directions, b @ directions
        ref = np.mean([stats.wasserstein_distance(a[:, j], b[:, j]) for j in range(5)])
        chosen = dataclasses.replace(settings, centre_patches=centre)
        value = metrics.sliced_wasserstein(exemplar, volume, "top", settings=chosen)
        assert value == pytest.approx(ref, rel=1e-10)
    shifted = metrics.sliced_wasserstein(exemplar, np.stack([exemplar + 0.3] * 4), "right",
                                         settings=settings)
    assert shifted < 1e-12  # centred patches ignore a grey-level shift (histogram_kl sees it)


def test_patch_sample_subsets_without_replacement():
    images = np.arange(2 * 6 * 6, dtype=float).reshape(2, 6, 6, 1)
    sample = metrics.patch_sample(images, 2, 7, np.random.default_rng(0))
    assert sample.shape == (7, 4)
    assert len({tuple(row) for row in sample}) == 7
    full = metrics.patch_sample(images, 2, 1000, np.random.default_rng(0))
    assert full.shape == (50, 4)
    assert {tuple(row) for row in sample} <= {tuple(row) for row in full}


# --------------------------------------------------------------------------- two-point correlation


def brute_two_point(indicator: np.ndarray, r_max: int, periodic: bool) -> np.ndarray:
    out = np.zeros((indicator.ndim, r_max + 1))
    for axis, n in enumerate(indicator.shape):
        for r in range(r_max + 1):
            hits = pairs = 0
            for index in itertools.product(*map(range, indicator.shape)):
                other = list(index)
                other[axis] += r
                if other[axis] >= n:
                    if not periodic:
                        continue
                    other[axis] -= n
                pairs += 1
                hits += indicator[index] and indicator[tuple(other)]
            out[axis, r] = hits / pairs
    return out


@pytest.mark.parametrize("periodic", [False, True])
def test_two_point_correlation_matches_a_brute_force_count(periodic):
    rng = np.random.default_rng(10)
    labels = rng.integers(0, 3, (5, 6, 7))
    got = metrics.two_point_correlation(labels, phase=2, max_distance=4, periodic=periodic)
    np.testing.assert_allclose(got, brute_two_point(labels == 2, 4, periodic), atol=1e-12)
    image = rng.random((8, 9))
    got = metrics.two_point_correlation(image, threshold=0.6, periodic=periodic)
    np.testing.assert_allclose(got, brute_two_point(image > 0.6, 4, periodic), atol=1e-12)
    assert got[:, 0] == pytest.approx([(image > 0.6).mean()] * 2)


def test_two_point_correlation_checks_the_distance():
    with pytest.raises(ParameterError, match="max_distance must be between 0 and 4"):
        metrics.two_point_correlation(np.zeros((5, 8)), max_distance=5)


def brute_shape_error(exemplars: dict, volume: np.ndarray, r_max: int, isotropic: bool = False) -> float:
    """:func:`metrics.two_point_shape_error` by brute-force pair counts, written out: phases =
    the exemplars' distinct values, labels by the nearest phase, one normalised curve per phase
    but the first, front = volume axes (0, 1), right = (1, 2), top = (0, 2); ``isotropic``:
    every axis against the mean of all the exemplars' row and column curves."""
    planes = {"front": (0, 1), "right": (1, 2), "top": (0, 2)}
    phases = np.unique(np.concatenate([e.ravel() for e in exemplars.values()]))

    def curves(array):
        label = np.abs(array[..., None] - phases).argmin(axis=-1)
        rows = []
        for p in range(1, len(phases)):
            ind = label == p
            phi = ind.mean()
            s2 = brute_two_point(ind, r_max, False)
            rows.append((s2 - phi ** 2) / (phi - phi ** 2) if 0 < phi < 1 else np.zeros_like(s2))
        return np.stack(rows, axis=1)  # (axes, phases - 1, r)

    mine = curves(volume)
    refs = {a: [] for a in range(3)}
    for view, image in exemplars.items():
        c = curves(image)
        for image_axis, volume_axis in enumerate(planes[view]):
            for a in (0, 1, 2) if isotropic else (volume_axis,):
                refs[a].append(c[image_axis])
    return float(np.mean([np.sqrt(((mine[a] - np.mean(refs[a], axis=0)) ** 2).sum())
                          for a in range(3) if refs[a]]))


def test_two_point_shape_error_matches_brute_force_counts():
    rng = np.random.default_rng(11)
    values = np.array([0.0, 0.5, 1.0])
    front = values[rng.integers(0, 3, (9, 10))]
    right = values[rng.integers(0, 2, (8, 9))]      # the right view holds two of the phases
    volume = values[rng.integers(0, 3, (8, 9, 10))] + rng.normal(0, 0.1, (8, 9, 10))  # nearest phase
    got = metrics.two_point_shape_error({"front": front, "right": right}, volume, max_distance=3)
    assert got == pytest.approx(brute_shape_error({"front": front, "right": right}, volume, 3), rel=1e-12)
    # one view: only its plane's two axes are judged
    got = metrics.two_point_shape_error({"top": front[:8]}, volume, max_distance=3)
    assert got == pytest.approx(brute_shape_error({"top": front[:8]}, volume, 3), rel=1e-12)
    for given in ({"front": front, "right": right}, {"top": front[:8]}):
        got = metrics.two_point_shape_error(given, volume, max_distance=3, reference="isotropic")
        assert got == pytest.approx(brute_shape_error(given, volume, 3, isotropic=True), rel=1e-12)
        assert got != pytest.approx(metrics.two_point_shape_error(given, volume, max_distance=3))


def test_two_point_shape_error_ranks_structure_over_shuffled_voxels():
    layers = np.tile(np.repeat([0.0, 1.0], 3), (12, 2))          # columns: 3 on, 3 off
    stacked = np.broadcast_to(layers[None], (12, 12, 12)).copy()  # every right slice is the image
    shuffled = np.random.default_rng(0).permutation(stacked.ravel()).reshape(stacked.shape)
    assert metrics.two_point_shape_error({"right": layers}, stacked) == 0.0
    assert metrics.two_point_shape_error({"right": layers}, shuffled) > 1.0
    with pytest.raises(ParameterError, match="max_distance"):
        metrics.two_point_shape_error({"right": layers}, stacked, max_distance=7)
    with pytest.raises(ParameterError, match="reference"):
        metrics.two_point_shape_error({"right": layers}, stacked, reference="axes")
    # the layers run along the columns only: an isotropic reference mixes in the flat rows
    assert metrics.two_point_shape_error({"right": layers}, stacked, reference="isotropic") > 0.5


# --------------------------------------------------------------------------- evaluate: sanity


@pytest.mark.parametrize("view", VIEWS)
def test_stacked_exemplar_scores_zero_on_its_view_and_noise_scores_worse(view):
    exemplar = smooth_texture((24, 24), seed=11)
    stacked = stack_along(exemplar, view, 16)
    result = metrics.evaluate(stacked, {view: exemplar})
    scores = result["per_view"][view]
    assert scores["histogram_kl"] == 0.0
    assert scores["autocorrelation_l2"] < 1e-10
    assert scores["orientation_kl"] < 1e-10
    assert scores["sliced_wasserstein"] < 1e-10  # no subsampling at this size: same patch set
    noise = np.random.default_rng(12).random(stacked.shape)
    bad = metrics.evaluate(noise, {view: exemplar})["per_view"][view]
    assert bad["histogram_kl"] > 0.1
    assert bad["autocorrelation_l2"] > 1.0
    assert bad["orientation_kl"] > 0.01
    assert bad["sliced_wasserstein"] > 0.05


def test_stacked_along_right_is_zero_on_right_only_and_subsampled_sw_is_small():
    exemplar = smooth_texture((48, 48), seed=13)
    volume = stack_along(exemplar, "right", 24)  # 24 * 42 * 42 patches > max_patches
    result = metrics.evaluate(volume, exemplar)
    right = result["per_view"]["right"]
    assert right["sliced_wasserstein"] < 0.005
    noise = metrics.evaluate(np.random.default_rng(0).random(volume.shape), exemplar,
                             views="right")["per_view"]["right"]
    assert noise["sliced_wasserstein"] > 10 * right["sliced_wasserstein"]
    for view in ("front", "top"):  # those slices are constant along one axis
        assert result["per_view"][view]["autocorrelation_l2"] > 1.0
        assert result["per_view"][view]["orientation_kl"] > 1.0


@pytest.mark.parametrize("channels", [2, 3, 4])
def test_colour_and_multichannel_volumes(channels):
    exemplar = np.stack([smooth_texture((16, 16), seed=20 + c) for c in range(channels)], -1)
    stacked = stack_along(exemplar, "top", 10)
    result = metrics.evaluate(stacked, {"top": exemplar})
    assert [round(result["mean"][m], 9) for m in metrics.METRICS] == [0.0] * 4
    assert result["settings"]["channels"] == channels
    assert result["settings"]["joint_bins_used"] == 8
    assert len(result["details"]["top"]["histogram_kl_channels"]) == channels
    noise = np.random.default_rng(1).random(stacked.shape)
    bad = metrics.evaluate(noise, {"top": exemplar})
    assert all(bad["mean"][m] > result["mean"][m] for m in metrics.METRICS)
    joint = metrics.joint_histogram_kl(exemplar, noise)
    assert bad["per_view"]["top"]["histogram_kl"] == pytest.approx(joint)


def test_evaluate_contract():
    rng = np.random.default_rng(14)
    volume = rng.random((12, 14, 16))
    ex = {"top": rng.random((12, 16)), "front": rng.random((12, 14))}
    result = metrics.evaluate(volume, ex)
    assert metrics.METRICS == ("histogram_kl", "autocorrelation_l2", "orientation_kl",
                               "sliced_wasserstein")
    assert list(result["per_view"]) == ["front", "top"]  # the mapping's keys, in VIEWS order
    for view, scores in result["per_view"].items():
        assert list(scores) == list(metrics.METRICS)
        assert all(isinstance(v, float) and v >= 0 for v in scores.values())
    for name in metrics.METRICS:
        assert result["mean"][name] == pytest.approx(
            np.mean([result["per_view"][v][name] for v in ("front", "top")]))
    for key in ("bins", "joint_bins", "eps", "max_lag", "gradient_sigma", "integration_sigma",
                "orientation_bins", "coherence_weighting", "patch", "centre_patches", "projections",
                "max_patches", "seed"):
        assert key in result["settings"], key
    assert list(metrics.evaluate(volume, ex, views="Top")["per_view"]) == ["top"]
    single = metrics.evaluate(volume[:12, :12, :12], rng.random((12, 12)))
    assert list(single["per_view"]) == list(VIEWS)
    again = metrics.evaluate(volume, ex)
    assert again["per_view"] == result["per_view"]  # seeded: repeatable


def test_integer_inputs_are_scaled_like_exemplars():
    rng = np.random.default_rng(15)
    ex8 = rng.integers(0, 256, (16, 16), dtype=np.uint8)
    as_float = stack_along(ex8.astype(np.float32) / 255, "right", 8)
    assert metrics.evaluate(as_float, ex8, views="right")["mean"]["histogram_kl"] == 0.0
    ex16 = ex8.astype(np.uint16) * 257
    assert metrics.evaluate(stack_along(ex16, "right", 8), ex8, views="right")["mean"][
        "sliced_wasserstein"] < 1e-9
    assert metrics.evaluate(stack_along(ex8 > 128, "right", 8), ex8 > 128, views="right")[
        "mean"]["histogram_kl"] == 0.0


def test_legacy_helpers_keep_their_signatures():
    rng = np.random.default_rng(16)
    ex = rng.random((16, 16, 1)).astype(np.float32)
    vol = rng.random((8, 8, 8, 1)).astype(np.float32)
    assert metrics.autocorrelation_error(ex, vol, "front", 3) > 0
    assert metrics.histogram_kl(ex, vol) > 0
    assert metrics.view_slices(vol, "right").shape == (8, 8, 8, 1)
    assert metrics.largest_value_share(np.zeros((2, 2, 2, 1))) == 1.0


# --------------------------------------------------------------------------- evaluate: errors


@pytest.mark.parametrize("volume, exemplars, views, message", [
    (np.full((6, 6, 6), np.nan), np.zeros((6, 6)), None, "volume contains 216 NaN"),
    (np.zeros((6, 6)), np.zeros((6, 6)), None, r"volume must be a non-empty array of shape"),
    (np.zeros((6, 6, 6, 1, 1)), np.zeros((6, 6)), None, r"got shape \(6, 6, 6, 1, 1\)"),
    (np.zeros((6, 6, 6), dtype=complex), np.zeros((6, 6)), None, "real numbers"),
    (np.zeros((6, 6, 6)), np.full((6, 6), np.inf), None,
     "exemplar of the front view contains 36 NaN"),
    (np.zeros((6, 6, 6)), np.zeros((6, 6, 3)), None, "has 3 channel.* but the volume has 1"),
    (np.zeros((6, 6, 6, 3)), {"top": np.zeros((6, 6))}, None,
     "has 1 channel.* but the volume has 3"),
    (np.zeros((6, 6, 6)), np.zeros((6, 6, 1, 1)), None, "2D image"),
    (np.zeros((6, 6, 6)), {"side": np.zeros((6, 6))}, None, "exemplar view must be one of front"),
    (np.zeros((6, 6, 6)), np.zeros((6, 6)), "front,back",
     "view must be one of front, right, top; got 'back'"),
    (np.zeros((6, 6, 6)), np.zeros((6, 6)), "top,top", "must not repeat"),
    (np.zeros((6, 6, 6)), np.zeros((6, 6)), [], "empty list"),
    (np.zeros((6, 6, 6)), {"front": np.zeros((6, 6))}, "top", "no exemplar for the top view"),
    (np.zeros((6, 6, 6)), {}, None, "at least one view"),
    (np.zeros((6, 3, 6)), np.zeros((6, 6)), None, "volume of size 6x3x6 is too small"),
    (np.zeros((6, 6, 6)), np.zeros((2, 6)), None, "front view of size 2x6 is too small"),
])
def test_bad_inputs_raise_one_clear_parameter_error(volume, exemplars, views, message):
    with pytest.raises(ParameterError, match=message) as info:
        metrics.evaluate(volume, exemplars, views=views)
    assert "\n" not in str(info.value)


def test_bad_settings_are_parameter_errors():
    with pytest.raises(ParameterError, match="bins must be >= 2"):
        metrics.MetricSettings(bins=1)
    with pytest.raises(ParameterError, match="integration_sigma"):
        metrics.MetricSettings(integration_sigma=0)
    with pytest.raises(ParameterError, match="settings must be a MetricSettings"):
        metrics.evaluate(np.zeros((6, 6, 6)), np.zeros((6, 6)), settings={"bins": 8})
