"""Ground-truth statistics of two-phase volumes, each against an independent implementation."""

from __future__ import annotations

import importlib
import itertools

import numpy as np
import pytest
from scipy import ndimage

from npmrf3d.analysis import materials
from npmrf3d.errors import ParameterError
from npmrf3d.model.otsu import otsu_threshold


@pytest.fixture
def porous(rng) -> np.ndarray:
    """A 20^3 porous-like grey volume: smoothed noise, periodic."""
    return ndimage.gaussian_filter(rng.random((20, 20, 20)), 1.5, mode="wrap")


def test_phase_and_fraction_follow_otsu_or_a_given_threshold(porous):
    from skimage.filters import threshold_otsu

    t = threshold_otsu(porous)
    assert otsu_threshold(porous) == pytest.approx(t, abs=1e-12)
    assert materials.volume_fraction(porous) == pytest.approx(float((porous > t).mean()))
    assert materials.volume_fraction(porous, threshold=float(np.median(porous))) == pytest.approx(0.5, abs=0.01)
    colour = np.stack([porous] * 3, axis=-1)
    np.testing.assert_array_equal(materials.phase(colour), porous > t)
    with pytest.raises(ParameterError, match="threshold must be one of otsu; got 'mean'"):
        materials.phase(porous, threshold="mean")


def test_radial_two_point_matches_a_brute_force_average(rng):
    ind = rng.random((6, 7, 8)) < 0.4
    r_max = 3
    sums, counts = np.zeros(r_max + 1), np.zeros(r_max + 1)
    for d in itertools.product(range(6), range(7), range(8)):
        wrapped = [min(di, n - di) for di, n in zip(d, ind.shape)]
        r = int(np.rint(np.sqrt(sum(w * w for w in wrapped))))
        if r <= r_max:
            shifted = np.roll(ind, shift=[-di for di in d], axis=(0, 1, 2))
            sums[r] += (ind & shifted).mean()
            counts[r] += 1
    np.testing.assert_allclose(materials.radial_two_point(ind, max_distance=r_max), sums / counts, atol=1e-12)
    assert materials.radial_two_point(ind, max_distance=0)[0] == pytest.approx(ind.mean())


def test_non_periodic_radial_two_point_averages_the_pairs_inside(rng):
    ind = rng.random((5, 6, 7)) < 0.4
    r_max = 2
    sums, counts = np.zeros(r_max + 1), np.zeros(r_max + 1)
    for d in itertools.product(*(range(-n + 1, n) for n in ind.shape)):
        r = int(np.rint(np.sqrt(sum(di * di for di in d))))
        if r > r_max:
            continue
        a = ind[tuple(slice(max(0, -di), n - max(0, di)) for di, n in zip(d, ind.shape))]
        b = ind[tuple(slice(max(0, di), n - max(0, -di)) for di, n in zip(d, ind.shape))]
        sums[r] += (a & b).mean()
        counts[r] += 1
    got = materials.radial_two_point(ind, max_distance=r_max, periodic=False)
    np.testing.assert_allclose(got, sums / counts, atol=1e-12)
    assert not np.allclose(got, materials.radial_two_point(ind, max_distance=r_max))


def test_specific_surface_area_of_a_sphere_and_by_stereology(porous):
    z, y, x = np.mgrid[:40, :40, :40].astype(np.float64)
    radius = 11.0
    field = radius - np.sqrt((z - 19.5) ** 2 + (y - 20.2) ** 2 + (x - 19.8) ** 2)
    exact = 4 * np.pi * radius ** 2 / 40 ** 3
    assert materials.specific_surface_area(field, threshold=0.0) == pytest.approx(exact, rel=0.01)
    assert materials.specific_surface_area(field, threshold=0.0, spacing=0.5) == pytest.approx(2 * exact, rel=0.01)
    # stereology (S_V = 2 P_L, averaged over the three axes) on an isotropic porous phase
    ind = materials.phase(porous)
    crossings = sum(np.count_nonzero(np.diff(ind.astype(np.int8), axis=a)) / (ind.size * (n - 1) / n)
                    for a, n in enumerate(ind.shape)) / 3
    assert materials.specific_surface_area(ind) == pytest.approx(2 * crossings, rel=0.25)
    assert materials.specific_surface_area(np.zeros((8, 8, 8), dtype=bool)) == 0.0


def _runs(line, include_border):
    out, n, start = [], len(line), None
    for i, v in enumerate([*line, False]):
        if v and start is None:
            start = i
        if not v and start is not None:
            if include_border or (start > 0 and i < n):
                out.append(i - start)
            start = None
    return out


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("include_border", [False, True])
def test_chord_lengths_match_a_loop(rng, axis, include_border):
    ind = rng.random((5, 6, 7)) < 0.6
    moved = np.moveaxis(ind, axis, -1).reshape(-1, ind.shape[axis])
    expected = [r for line in moved for r in _runs(list(line), include_border)]
    got = materials.chord_lengths(ind, axis, include_border=include_border)
    assert got.tolist() == expected
    dist = materials.chord_length_distribution(ind, axis, include_border=include_border)
    assert dist.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(dist, np.bincount(np.array(expected) - 1, minlength=ind.shape[axis])
                               / len(expected))


def test_summary_of_a_layered_volume():
    layers = np.zeros((16, 16, 16), dtype=bool)
    layers[:, :, ::4] = layers[:, :, 1::4] = True
    s = materials.structure_summary(layers, max_distance=4)
    assert s["fraction"] == 0.5 and s["mean_chord"][2] == 2.0
    assert s["two_point"][2][:5] == [0.5, 0.25, 0.0, 0.25, 0.5]
    assert s["two_point"][0] == [0.5] * 5


def test_missing_optional_packages_name_the_extra(monkeypatch):
    real = importlib.import_module

    def without(name, *args):
        if name in ("taufactor", "skimage.measure"):
            raise ImportError(f"No module named {name!r}")
        return real(name, *args)

    monkeypatch.setattr(materials.importlib, "import_module", without)
    with pytest.raises(ParameterError, match=r"tortuosity needs the optional package taufactor.*"
                                             r"pip install 'npmrf3d\[materials\]'"):
        materials.tortuosity(np.ones((8, 8, 8), dtype=bool))
    half = np.zeros((8, 8, 8), dtype=bool)
    half[:4] = True
    with pytest.raises(ParameterError, match=r"needs the optional package scikit-image.*\[materials\]"):
        materials.specific_surface_area(half)


@pytest.mark.parametrize("cuda", [False, True])
def test_tortuosity_calls_taufactor_along_the_axis_on_the_available_device(monkeypatch, cuda):
    seen = {}

    class Solver:
        def __init__(self, img, device):
            seen["shape"], seen["device"] = img.shape, device
            self.tau = np.array([1.5])

        def solve(self, verbose=""):
            seen["solved"] = True

    # one stand-in for both imports: taufactor's Solver and torch's CUDA query
    fake = type("taufactor_and_torch", (), {
        "Solver": Solver, "cuda": type("cuda", (), {"is_available": staticmethod(lambda: cuda)})})
    monkeypatch.setattr(materials.importlib, "import_module", lambda name, *a: fake)
    assert materials.tortuosity(np.ones((4, 5, 6), dtype=bool), axis=2) == 1.5
    assert seen == {"shape": (6, 4, 5), "device": "cuda" if cuda else "cpu", "solved": True}
