"""The measuring pieces of the materials benchmark (benchmarks/bench_materials.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage

from tests.conftest import benchmark_module

@pytest.fixture(scope="module")
def bm():
    return benchmark_module("bench_materials")


def blobs(shape, seed: int, sigma: float = 2.0) -> np.ndarray:
    """A stationary two-phase-like grey volume in [0, 1]."""
    x = ndimage.gaussian_filter(np.random.default_rng(seed).standard_normal(shape), sigma, mode="wrap")
    return ((x - x.min()) / (x.max() - x.min())).astype(np.float32)


def phase(volume: np.ndarray, share: float = 0.4) -> np.ndarray:
    """The ``share`` of the voxels with the highest values."""
    return volume > np.quantile(volume, 1.0 - share)


def test_verdict_is_zero_inside_and_relative_outside(bm):
    assert bm.verdict(0.5, 0.4, 0.6) == 0.0
    assert bm.verdict(0.66, 0.4, 0.6) == pytest.approx(0.1)
    assert bm.verdict(0.3, 0.4, 0.6) == pytest.approx(-0.25)
    assert np.isnan(bm.verdict(float("nan"), 0.4, 0.6))


def test_crop_corners_are_spread_and_capped(bm):
    corners = bm.crop_corners((64, 64, 96), 32, 100)
    assert len(corners) == 3 * 3 * 5 and corners[0] == (0, 0, 0) and corners[-1] == (32, 32, 64)
    capped = bm.crop_corners((64, 64, 96), 32, 7)
    assert len(capped) == 7 and capped[0] == (0, 0, 0) and capped[-1] == (32, 32, 64)


def test_structure_scores_near_the_crops_and_shuffling_near_one(bm):
    volume = phase(blobs((64, 64, 64), 0))
    crops = [bm.statistics(volume[i:i + 32, j:j + 32, k:k + 32], tau=False)
             for i, j, k in bm.crop_corners(volume.shape, 32, 27)]
    shuffled = np.random.default_rng(1).permutation(volume[:32, :32, :32].ravel()).reshape(32, 32, 32)
    judge = bm.Judge(crops, bm.statistics(shuffled, tau=False))
    other = bm.statistics(phase(blobs((64, 64, 64), 5))[:32, :32, :32], tau=False)  # a new draw
    coarse = bm.statistics(phase(blobs((64, 64, 64), 5, sigma=4.0))[:32, :32, :32], tau=False)  # larger grains
    near, far = judge.judge(other), judge.judge(coarse)
    assert near["s2"]["value"] < 0.5 < far["s2"]["value"]
    assert near["chord"]["outside"] == 0 and far["chord"]["outside"] > 0.2
    again = bm.statistics(shuffled, tau=False)
    assert judge.judge(again)["s2"]["value"] == pytest.approx(1.0)
    assert np.isnan(near["diff0"]["value"])   # not measured without tau


def test_a_run_writes_the_table_record_and_figure(bm, tmp_path, capsys):
    scans = tmp_path / "scans"
    scans.mkdir()
    np.save(scans / "ketton.npy", (blobs((48, 48, 48), 2) > 0.55).astype(np.float32))
    out = tmp_path / "out"
    assert bm.main(["--scans", str(scans), "--names", "ketton", "--size", "32", "--max-crops", "4",
                    "--methods", "kopf", "--option", "kopf:levels=1", "--no-tau", "--out", str(out)]) == 0
    record = json.loads((out / "materials.json").read_text())
    run = record["scans"][0]["runs"]["kopf"]
    assert set(run["judged"]) == set(bm.SCALARS + bm.TAUS + bm.ERRORS + ("perc",))
    assert record["options"] == {"kopf": {"levels": 1}}
    assert (out / "ketton.png").stat().st_size > 10_000
    assert "| | kopf |" in (out / "table.md").read_text()
    assert "| **ketton** |" in capsys.readouterr().out


def test_no_scan_is_refused_in_one_line(bm, tmp_path, capsys):
    assert bm.main(["--scans", str(tmp_path), "--names", "ketton"]) == 2
    assert "materials_scans.py" in capsys.readouterr().err


def test_materials_splits_grey_slices_as_the_command_does(bm):
    slices = [blobs((24, 24, 1), s)[..., 0] for s in (3, 4, 5, 6)]
    views = {"exemplars": {v: s[..., None] for v, s in zip(("front", "right", "top"), slices[1:])}}
    exemplar, phases, values, order = bm.as_phases(slices[0][..., None], views, 0.45, "before")
    assert values.tolist() == [0, 1] and order == "before"
    top = phases["exemplars"]["top"]
    assert top.dtype == np.float32 and top.shape == (24, 24, 1)
    np.testing.assert_array_equal(top[..., 0], slices[3] > 0.45)
    alone, none, _, _ = bm.as_phases(slices[0][..., None], {}, 0.45, "before")
    assert none == {} and alone.dtype == np.float32
    np.testing.assert_array_equal(alone[..., 0], slices[0] > 0.45)
    # a minority phase under the command's cut: the grey slices go to the method as they are
    high = float(np.quantile(np.concatenate([s.ravel() for s in slices]), 0.9))
    grey, same, values, order = bm.as_phases(slices[0][..., None], views, high)
    assert order == "after" and values.tolist() == [0, 1] and same is views
    np.testing.assert_array_equal(grey[..., 0], slices[0])


def test_an_anisotropic_crop_runs_on_its_three_slices(bm):
    volume, _ = bm.synthesize("materials", blobs((32, 32, 32), 8), False, 16, 1, {"levels": 1}, 0.5)
    assert volume.shape == (16, 16, 16) and set(np.unique(volume).tolist()) == {0.0, 1.0}


def test_a_materials_run_makes_a_two_phase_volume(bm):
    crop = blobs((32, 32, 32), 7)
    volume, _ = bm.synthesize("materials", crop, True, 16, 1, {"levels": 1}, 0.5)
    assert volume.shape == (16, 16, 16) and set(np.unique(volume).tolist()) == {0.0, 1.0}
    assert 0.2 < volume.mean() < 0.8
