"""The measuring pieces of the paper-scale quality benchmark (benchmarks/_quality.py)."""

from __future__ import annotations


import numpy as np
import pytest
from scipy import ndimage

from npmrf3d.analysis import metrics
from tests.conftest import benchmark_module

@pytest.fixture(scope="module")
def q():
    return benchmark_module("_quality")


@pytest.fixture(scope="module")
def photo():
    """A stationary 'photograph': 128 x 128 smoothed noise, grain about 2 pixels, in [0, 1]."""
    x = ndimage.gaussian_filter(np.random.default_rng(3).standard_normal((128, 128)), 2.0,
                                mode="wrap")
    x = (x - x.min()) / (x.max() - x.min())
    return x[..., None].astype(np.float32)


def test_control_ratio_is_one(q, photo):
    a = photo[:32, :32]
    control = q.structureless(a, 16, np.random.default_rng(0))
    row = q.measure(a, control)
    assert set(row) == set(q.MEASURES)
    assert all(v == pytest.approx(1.0) for v in q.ratios(row, row).values())


def test_floor_beats_control_and_exact_crop_scores_zero(q, photo):
    a, crops_b = photo[:64, :64], [photo[64:, 64:], photo[:64, 64:], photo[64:, :64]]
    control = q.measure(a, q.structureless(a, 32, np.random.default_rng(0)))
    floor = q.ratios(q.measure(a, q.floor_volume(crops_b, 64), views=("front",)), control)
    assert floor["ac"] < 0.5 and floor["sw"] < 0.5     # measured 0.26 and 0.25
    exact = q.measure(a, q.floor_volume(a, 64), views=("front",))
    assert exact["ac"] == pytest.approx(0.0, abs=1e-9)
    assert exact["sw"] == pytest.approx(0.0, abs=1e-9)


def test_floor_volume_weighs_tiles_equally(q, photo):
    tiles = q.floor_volume([photo[:32, :32], photo[32:64, :32], photo[64:96, :32]], 32)
    assert tiles.shape == (32, 32, 6, 1)          # 3 crops, each twice (at least 4 slices)
    np.testing.assert_array_equal(tiles[:, :, 1], tiles[:, :, 4])
    assert q.floor_volume([photo[:32, :32]], 16).shape == (16, 16, 4, 1)   # its 4 tiles


def test_blurred_control_keeps_mean_and_spread_and_grain(q, photo):
    a = photo[:64, :64]
    assert 1.2 < q.grain_sigma(a) < 3.0           # smoothed with sigma 2
    blurred = q.blurred(a, q.structureless(a, 16, np.random.default_rng(1)))
    assert blurred.mean() == pytest.approx(a.mean(), abs=1e-4)
    assert blurred.std() == pytest.approx(a.std(), rel=1e-3)


def test_multiscale_sliced_wasserstein_scale_one_is_sliced_wasserstein(photo):
    volume = np.random.default_rng(2).random((24, 24, 24, 1)).astype(np.float32)
    a = photo[:32, :32]
    settings = metrics.MetricSettings(patch=7)
    one = metrics.multiscale_sliced_wasserstein(a, volume, "top", scales=(1,), patch=7)
    assert one == pytest.approx(metrics.sliced_wasserstein(a, volume, "top", settings=settings))
    # scales whose reduced images are too small are left out rather than failing
    assert np.isfinite(metrics.multiscale_sliced_wasserstein(a, volume, "top", scales=(1, 8)))


def test_bundled_crops_do_not_overlap(q):
    a, crops_b = q.BY_NAME["gravel"].crops()
    assert a.shape == (64, 64, 1) and len(crops_b) == 3
    image = q.BY_NAME["gravel"].image()
    np.testing.assert_array_equal(crops_b[0], image[64:, 64:])


def test_a_method_added_in_one_line_runs_and_is_cached(q, tmp_path, monkeypatch):
    monkeypatch.setitem(q.METHODS, "noise", lambda ex, size, levels, seed, **_:
                        q.structureless(ex, size, np.random.default_rng(seed)))
    results = {"runs": {}, "references": {}}
    size = 8
    results["references"]["gravel|seed0|size8"] = q.references(q.BY_NAME["gravel"], size, 0)
    lines = []
    q.run_all(["noise"], ["gravel"], [0], size, 1, None, results, tmp_path, echo=lines.append)
    run = results["runs"][q.run_key("noise", "gravel", 0, size, None)]
    assert run["ratio"]["ac"] == pytest.approx(1.0)    # the same draw as the control
    q.run_all(["noise"], ["gravel"], [0], size, 1, None, results, tmp_path, echo=lines.append)
    assert lines[-1].startswith("0 run(s)")
    summary = q.summarise(results, ["noise"], ["gravel"], [0], size, None)
    assert summary["tuning"]["methods"]["noise"]["count"] == 1
