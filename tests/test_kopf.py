"""NP_K (npmrf3d.methods.kopf) against literal numpy twins of the paper's formulas.

Kopf et al. 2007 (docs/kopf.md): the search (PCA + cKDTree with eps, sparse grid), the IRLS
update (eq. 4) with histogram (eq. 5) and constraint (eq. 6) re-weighting, histogram matching,
periodic exemplars, determinism across thread counts, user errors and the CLI. Everything is
tiny (exemplars up to 32x32, volumes 8^3 to 24^3).
"""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from npmrf3d import cli
from npmrf3d.analysis.metrics import histogram_kl
from npmrf3d.config import SynthesisResult
from npmrf3d.errors import ParameterError
from npmrf3d.methods import kopf as K
from npmrf3d.methods.kopf import KopfConfig, kopf_synthesize
from npmrf3d.model import kopf_levels, kopf_optimise, kopf_search
from npmrf3d.model.kcoherence import centre_patches
from tests.naive import (
    NAIVE_VIEW_AXES,
    naive_kopf_neighbourhood,
    naive_kopf_patches,
    naive_kopf_update,
)

#: Seed of the shared ``rng`` fixture (tests/conftest.py).
RNG_SEED = 1234

REPO = pathlib.Path(__file__).resolve().parents[1]
VIEWS3 = ("front", "right", "top")


def stripes(period: int = 4, size: int = 32, vertical: bool = True) -> np.ndarray:
    """Binary stripes: value depends on the column (vertical) or the row (horizontal)."""
    line = (np.arange(size) % period < period // 2).astype(np.float32)
    image = np.tile(line, (size, 1)) if vertical else np.tile(line[:, None], (1, size))
    return image[..., None]


def stripe_error(image: np.ndarray, period: int) -> float:
    """Mean absolute difference of a 2D image to the best-phase vertical stripes."""
    cols = image.shape[1]
    best = np.inf
    for shift in range(period):
        pattern = ((np.arange(cols) + shift) % period < period // 2).astype(np.float32)
        best = min(best, float(np.mean(np.abs(image - pattern[None, :]))))
    return best


# --------------------------------------------------------------------------- search


@pytest.mark.parametrize("channels", [1, 3])
def test_patches_and_neighbourhoods_match_naive(rng, channels):
    ex = rng.random((9, 11, channels), dtype=np.float32)
    np.testing.assert_array_equal(centre_patches(ex, 3), naive_kopf_patches(ex, 3).astype(np.float32))
    vol = rng.random((6, 5, 4, channels), dtype=np.float32)
    for view in VIEWS3:
        got = kopf_search.volume_neighbourhoods(vol, view, 4, 2)
        ra, ca = NAIVE_VIEW_AXES[view]
        na = 3 - ra - ca
        expected = []
        for n in range(vol.shape[na]):
            for r in range(0, vol.shape[ra], 2):
                for c in range(0, vol.shape[ca], 2):
                    site = [0, 0, 0]
                    site[na], site[ra], site[ca] = n, r, c
                    expected.append(naive_kopf_neighbourhood(vol, view, site, 4))
        np.testing.assert_array_equal(got, np.array(expected, dtype=np.float32))


@pytest.mark.parametrize("channels", [1, 3])
def test_pca_keeps_the_variance_with_the_fewest_components(rng, channels):
    ex = rng.random((20, 20, channels), dtype=np.float32)
    ex = (ex + np.roll(ex, 1, axis=0) + np.roll(ex, 1, axis=1)) / 3  # correlated texels
    patches = centre_patches(ex, 4)
    for variance in (0.5, 0.8, 0.95, 0.99):
        mean, basis, kept = kopf_search.pca_basis(patches, variance)
        centred = patches.astype(np.float64) - patches.mean(axis=0)
        eig = np.sort(np.linalg.eigvalsh(centred.T @ centred))[::-1]
        total = eig.sum()
        k = basis.shape[1]
        assert kept >= variance
        assert eig[:k].sum() / total >= variance - 1e-9
        assert k == 1 or eig[:k - 1].sum() / total < variance
        np.testing.assert_allclose(kept, eig[:k].sum() / total, rtol=1e-6)
        np.testing.assert_allclose(basis.T.astype(np.float64) @ basis, np.eye(k), atol=1e-5)
        # the kept variance is what projecting on the basis preserves
        proj = centred @ basis.astype(np.float64)
        np.testing.assert_allclose((proj ** 2).sum() / (centred ** 2).sum(), kept, rtol=1e-4)


def test_pca_of_constant_patches_keeps_one_component():
    _, basis, kept = kopf_search.pca_basis(np.ones((10, 12), dtype=np.float32), 0.95)
    assert basis.shape == (12, 1) and kept == 1.0


@pytest.mark.parametrize("channels,variance", [(1, 1.0), (3, 1.0), (1, 0.9), (3, 0.95)])
def test_exact_search_equals_brute_force(rng, channels, variance):
    ex = rng.random((14, 13, channels), dtype=np.float32)
    index = kopf_search.NeighbourhoodIndex(ex, 3, variance)
    queries = rng.random((200, 9 * channels), dtype=np.float32)
    got, dist = index.query(queries, eps=0.0)
    patches = naive_kopf_patches(ex, 3)
    projected = (patches - patches.mean(axis=0)) @ index.basis.astype(np.float64)
    qp = (queries - patches.mean(axis=0)) @ index.basis.astype(np.float64)
    for t in range(len(queries)):
        d_pca = np.sqrt(((projected - qp[t]) ** 2).sum(axis=1))
        assert np.isclose(d_pca[got[t]], d_pca.min(), rtol=1e-5, atol=1e-6)
        d_full = np.sqrt(((patches - queries[t]) ** 2).sum(axis=1))
        np.testing.assert_allclose(dist[t], d_full[got[t]], rtol=1e-5)
        if variance == 1.0:  # nothing dropped: the nearest neighbour in the full space
            assert np.isclose(d_full[got[t]], d_full.min(), rtol=1e-5, atol=1e-6)


def test_approximate_search_is_within_one_plus_eps(rng):
    ex = rng.random((32, 32, 3), dtype=np.float32)
    ex = (ex + np.roll(ex, 1, axis=0) + np.roll(ex, 1, axis=1)) / 3
    index = kopf_search.NeighbourhoodIndex(ex, 4, 0.95)
    queries = rng.random((400, 48), dtype=np.float32) * 0.6 + 0.2
    eps = 2.0
    got, _ = index.query(queries, eps=eps)
    qp = index.project(queries).astype(np.float64)
    for t in range(len(queries)):
        d = np.sqrt(((index.projected.astype(np.float64) - qp[t]) ** 2).sum(axis=1))
        assert d[got[t]] <= (1 + eps) * d.min() * (1 + 1e-5) + 1e-6


@pytest.mark.kernels
def test_search_view_assigns_the_sparse_grid(rng):
    ex = rng.random((12, 12, 1), dtype=np.float32)
    index = kopf_search.NeighbourhoodIndex(ex, 3, 1.0)
    vol = rng.random((6, 8, 4, 1), dtype=np.float32)
    for view in VIEWS3:
        assign, omega, energy, queries = kopf_search.search_view(vol, view, index, grid=2, eps=0.0, r=0.8,
                                                       floor=1e-6)
        ra, ca = NAIVE_VIEW_AXES[view]
        sites = np.argwhere(assign >= 0)
        assert len(sites) == queries == vol.shape[3 - ra - ca] * (vol.shape[ra] // 2) * (vol.shape[ca] // 2)
        assert np.all(sites[:, ra] % 2 == 0) and np.all(sites[:, ca] % 2 == 0)
        total = 0.0
        for site in sites:
            s = naive_kopf_neighbourhood(vol, view, site, 3)
            d = np.sqrt(((naive_kopf_patches(ex, 3) - s) ** 2).sum(axis=1))
            p = assign[tuple(site)]
            assert np.isclose(d[p], d.min(), rtol=1e-5)
            np.testing.assert_allclose(omega[tuple(site)], d[p] ** (0.8 - 2), rtol=1e-4)
            total += d[p] ** 0.8
        np.testing.assert_allclose(energy, total, rtol=1e-5)


# --------------------------------------------------------------------------- optimisation


def _tiny_problem(rng, channels, views=VIEWS3, shape=(4, 6, 4), window=3, grid=2):
    exemplars = [rng.random((7, 8, channels), dtype=np.float32) for _ in views]
    indices = [kopf_search.NeighbourhoodIndex(ex, window, 1.0) for ex in exemplars]
    npatch = [(ex.shape[0] - window + 1) * (ex.shape[1] - window + 1) for ex in exemplars]
    assign = np.full((len(views), *shape), -1, dtype=np.int32)
    omega = np.zeros((len(views), *shape), dtype=np.float32)
    for vi, view in enumerate(views):
        ra, ca = NAIVE_VIEW_AXES[view]
        for site in np.ndindex(*shape):
            if site[ra] % grid == 0 and site[ca] % grid == 0:
                assign[vi][site] = rng.integers(npatch[vi])
                omega[vi][site] = rng.uniform(0.1, 3.0)
    volume = rng.random((*shape, channels), dtype=np.float32)
    return exemplars, indices, assign, omega, volume


def _kernel_update(volume, assign, omega, views, indices, window, grid, order, **kw):
    lo, scale, bins = kw.get("lo"), kw.get("scale"), kw.get("bins", 16)
    channels = volume.shape[3]
    if lo is None:
        lo, scale = np.zeros(channels), np.full(channels, bins / 1.0)
    packed = kopf_optimise.pack_exemplars(indices, lo, scale, bins)
    rows = np.empty_like(assign)
    for vi, idx in enumerate(indices):
        p = assign[vi].astype(np.int64)
        base = packed.offsets[vi] + (p // idx.pwidth) * idx.exemplar.shape[1] + p % idx.pwidth
        rows[vi] = np.where(assign[vi] >= 0, base, -1)
    vol = volume.copy()
    hist = kopf_optimise.channel_histograms(vol, lo, scale, bins)
    target = kw.get("target_hist", np.full((channels, bins), 1.0 / bins))
    view_axes = np.array([NAIVE_VIEW_AXES[v] for v in views], dtype=np.int64)
    kopf_optimise.optimisation_phase(vol, rows, omega, view_axes, packed, window=window, grid=grid, order=order,
                         hist=hist, hist_target=target, histogram_weight=kw.get("hist_weight", 0.0),
                         lo=lo, scale=scale, bins=bins, constraint=kw.get("constraint"),
                         tau=kw.get("tau"))
    np.testing.assert_array_equal(hist, kopf_optimise.channel_histograms(vol, lo, scale, bins))
    return vol


@pytest.mark.kernels
@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("views", [VIEWS3, ("front", "top"), ("right",)])
def test_irls_update_is_equation_4(rng, channels, views):
    exemplars, indices, assign, omega, volume = _tiny_problem(rng, channels, views)
    order = rng.permutation(volume[..., 0].size)
    got = _kernel_update(volume, assign, omega, views, indices, 3, 2, order)
    expected = naive_kopf_update(volume, assign, omega, views, exemplars, 3, order)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)


@pytest.mark.kernels
@pytest.mark.parametrize("channels", [1, 3])
def test_histogram_and_constraint_reweighting_are_equations_5_and_6(rng, channels):
    views = ("front", "right")
    exemplars, indices, assign, omega, volume = _tiny_problem(rng, channels, views, window=2)
    bins = 4
    lo, scale = np.zeros(channels), np.full(channels, float(bins))
    target = rng.dirichlet(np.ones(bins), size=channels)
    constraint = rng.random(volume.shape, dtype=np.float32)
    tau = (rng.random(volume.shape[:3]) * 5 * (rng.random(volume.shape[:3]) < 0.5)).astype(np.float32)
    order = rng.permutation(volume[..., 0].size)
    kw = dict(hist_weight=7.0, lo=lo, scale=scale, bins=bins, target_hist=target,
              constraint=constraint, tau=tau)
    got = _kernel_update(volume, assign, omega, views, indices, 2, 2, order, **kw)
    expected = naive_kopf_update(volume, assign, omega, views, exemplars, 2, order, **kw)
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6)


def test_histogram_reweighting_moves_a_skewed_volume_towards_the_exemplar(rng):
    from scipy import ndimage

    ex = ndimage.uniform_filter(rng.random((32, 32)), 2, mode="wrap")
    ex = ((ex - ex.min()) / np.ptp(ex)).astype(np.float32)[..., None]
    index = kopf_search.NeighbourhoodIndex(ex, 4, 0.95)
    # exemplar texels cubed: a deliberately dark, skewed volume
    vol = np.ascontiguousarray(ex.reshape(-1)[rng.integers(0, ex.size, (16, 16, 16))][..., None] ** 3)
    lo, scale, bins = np.zeros(1), np.full(1, 16.0), 16
    packed = kopf_optimise.pack_exemplars([index] * 3, lo, scale, bins)
    view_axes = np.array([NAIVE_VIEW_AXES[v] for v in VIEWS3], dtype=np.int64)
    assign = np.empty((3, 16, 16, 16), dtype=np.int32)
    omega = np.empty((3, 16, 16, 16), dtype=np.float32)
    for vi, view in enumerate(VIEWS3):
        assign[vi], omega[vi], _, _ = kopf_search.search_view(vol, view, index, grid=2, eps=0.0, r=0.8,
                                                    floor=1e-3, offset=0)
    target = kopf_optimise.channel_histograms(ex, lo, scale, bins) / ex.size
    order = rng.permutation(16 ** 3)
    kl, mean = {"before": histogram_kl(ex, vol)}, {}
    for name, weight in (("plain", 0.0), ("fractions", 1.0 / 16 ** 3), ("paper", 1.0)):
        out = vol.copy()
        kopf_optimise.optimisation_phase(out, assign, omega, view_axes, packed, window=4, grid=2, order=order,
                             hist=kopf_optimise.channel_histograms(out, lo, scale, bins), hist_target=target,
                             histogram_weight=weight, lo=lo, scale=scale, bins=bins)
        kl[name], mean[name] = histogram_kl(ex, out), float(out.mean())
    assert kl["paper"] < kl["before"]
    assert kl["paper"] < kl["fractions"] < kl["plain"]
    assert mean["plain"] < mean["fractions"] < mean["paper"] < float(ex.mean())


@pytest.mark.kernels
def test_mean_shift_returns_the_mode_of_the_dominant_cluster(rng):
    """Two clusters of texels: mean-shift returns the mean of the heavier one (a fixed point: the
    weighted mean of the points within h of it); the plain average lies in between."""
    from npmrf3d._kernels import kopf as kk

    for channels in (1, 3):
        dark = rng.normal(0.1, 0.01, size=(7, channels))
        bright = rng.normal(0.9, 0.01, size=(4, channels))
        texels = np.concatenate([bright, dark])
        weights = rng.uniform(0.5, 1.0, size=len(texels))
        mode = np.full(channels, -1.0)
        found = kk._mean_shift_mode(texels, weights, len(texels), 0.2, 20, mode, np.empty(2 * channels))
        assert found
        members = np.linalg.norm(texels - mode, axis=1) <= 0.2
        np.testing.assert_array_equal(members, np.r_[np.zeros(4, bool), np.ones(7, bool)])
        np.testing.assert_allclose(mode, np.average(dark, axis=0, weights=weights[4:]), rtol=1e-9)
        # a heavy bright cluster wins instead
        weights[:4] *= 10
        kk._mean_shift_mode(texels, weights, len(texels), 0.2, 20, mode, np.empty(2 * channels))
        np.testing.assert_allclose(mode, np.average(bright, axis=0, weights=weights[:4]), rtol=1e-9)
        # a bandwidth that covers everything gives the plain weighted average
        kk._mean_shift_mode(texels, weights, len(texels), 10.0, 20, mode, np.empty(2 * channels))
        np.testing.assert_allclose(mode, np.average(texels, axis=0, weights=weights), rtol=1e-9)


# --------------------------------------------------------------------------- whole runs


def test_result_object_and_config(rng):
    ex = rng.random((24, 24, 3), dtype=np.float32)
    res = kopf_synthesize(ex, size=16, window=4, levels=2, iterations=(2, 1), rng=3)
    assert isinstance(res, SynthesisResult)
    assert res.volume.shape == (16, 16, 16, 3) and res.volume.dtype == np.float32
    assert np.isfinite(res.volume).all()
    assert res.volume.min() >= ex.min() - 1e-6 and res.volume.max() <= ex.max() + 1e-6
    assert isinstance(res.config, KopfConfig) and res.config.iterations == (2, 1)
    assert res.config.seed == 3
    json.dumps(res.config.to_dict())
    assert [len(h) for h in res.history] == [2, 1]
    assert res.labels.shape == (0, 3)
    assert set(res.timings) == {"setup", "level_1", "level_0", "total"}
    assert res.stats["levels"]["level_0"]["queries"] == 3 * 16 * 8 * 8


@pytest.mark.parametrize("upsample", ["trilinear", "8/8", "1/8"])
def test_upsampling_modes(rng, upsample):
    coarse = rng.random((4, 4, 4, 2), dtype=np.float32)
    fine = kopf_levels.upsample_volume(coarse, upsample, rng.random((10, 2), dtype=np.float32), np.random.default_rng(0))
    assert fine.shape == (8, 8, 8, 2)
    if upsample == "8/8":
        np.testing.assert_array_equal(fine, coarse.repeat(2, 0).repeat(2, 1).repeat(2, 2))
    elif upsample == "1/8":
        np.testing.assert_array_equal(fine[::2, ::2, ::2], coarse)
    else:  # trilinear on a torus: the mean is kept, a constant stays constant, a ramp's average
        np.testing.assert_allclose(fine.mean(axis=(0, 1, 2)), coarse.mean(axis=(0, 1, 2)), rtol=1e-5)
        const = kopf_levels.upsample_volume(np.ones((4, 4, 4, 1), np.float32), upsample, None, None)
        np.testing.assert_allclose(const, 1.0, rtol=1e-6)
        # child at 2x + 1 lies a quarter of the way from parent x to parent x + 1
        np.testing.assert_allclose(fine[1, 0, 0], 0.75 * (0.75 * (0.75 * coarse[0, 0, 0] + 0.25 * coarse[0, 0, 3])
                                                           + 0.25 * (0.75 * coarse[0, 3, 0] + 0.25 * coarse[0, 3, 3]))
                                   + 0.25 * (0.75 * (0.75 * coarse[1, 0, 0] + 0.25 * coarse[1, 0, 3])
                                             + 0.25 * (0.75 * coarse[1, 3, 0] + 0.25 * coarse[1, 3, 3])),
                                   rtol=1e-5)


def test_periodic_exemplar_appears_in_the_constrained_slices():
    period = 4
    res = kopf_synthesize(stripes(period), size=16, window=4, levels=2, views="front",
                          iterations=(4, 4), rng=0)
    errors = [stripe_error(res.volume[:, :, k, 0], period) for k in range(16)]
    assert np.median(errors) < 0.05, errors
    assert np.mean(errors) < 0.15, errors
    # a random volume is far from stripes
    noise = (np.random.default_rng(0).random((16, 16)) < 0.5).astype(np.float32)
    assert stripe_error(noise, period) > 0.35


def test_different_exemplars_per_view_and_two_views():
    """Front: value depends on j (vertical stripes); right (rows j, columns k): horizontal
    stripes also depend on j only. Both views can be satisfied at once."""
    period = 4
    res = kopf_synthesize(stripes(period), size=16, window=4, levels=2, views=("front", "right"),
                          exemplars={"right": stripes(period, vertical=False)}, iterations=(3, 3),
                          rng=1)
    vol = res.volume[..., 0]
    front = [stripe_error(vol[:, :, k], period) for k in range(16)]
    right = [stripe_error(vol[i].T, period) for i in range(16)]  # rows j -> transpose to columns
    assert np.median(front) < 0.12, front
    assert np.median(right) < 0.12, right


def test_voxel_constraints_pull_the_constrained_slice():
    rng = np.random.default_rng(5)
    ex = rng.random((24, 24, 1), dtype=np.float32)
    target = np.zeros((16, 16, 16, 1), dtype=np.float32)
    smile = (rng.random((16, 16)) < 0.5).astype(np.float32)
    target[:, :, 3, 0] = smile
    weight = np.zeros((16, 16, 16), dtype=np.float32)
    weight[:, :, 3] = 50.0
    kw = dict(size=16, window=4, levels=1, iterations=3, rng=2)
    free = kopf_synthesize(ex, **kw).volume
    held = kopf_synthesize(ex, constraint=target, constraint_weight=weight, **kw).volume
    err_free = np.abs(free[:, :, 3, 0] - smile).mean()
    err_held = np.abs(held[:, :, 3, 0] - smile).mean()
    assert err_held < 0.6 * err_free
    # voxels far from the constrained slice are not affected much
    assert abs(np.abs(held[:, :, 10, 0] - smile).mean() - np.abs(free[:, :, 10, 0] - smile).mean()) < 0.1


def test_same_seed_same_volume_and_other_seed_differs():
    ex = stripes(4, 24)
    kw = dict(size=16, window=4, levels=2, iterations=2)
    a = kopf_synthesize(ex, rng=7, **kw).volume
    b = kopf_synthesize(ex, rng=np.random.default_rng(7), **kw).volume
    c = kopf_synthesize(ex, rng=8, **kw).volume
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_identical_volume_with_one_and_two_threads(tmp_path):
    script = textwrap.dedent(
        """
        import hashlib, sys
        import numpy as np
        from npmrf3d.methods.kopf import kopf_synthesize
        rng = np.random.default_rng(0)
        ex = rng.random((24, 24, 3), dtype=np.float32)
        res = kopf_synthesize(ex, size=16, window=4, levels=2, iterations=2, mean_shift=(1.0, 0.3), rng=11)
        print(hashlib.sha256(res.volume.tobytes()).hexdigest())
        """
    )
    hashes = []
    for threads in (1, 2):
        env = {**os.environ, "NUMBA_NUM_THREADS": str(threads), "PYTHONPATH": str(REPO)}
        out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                             check=True, cwd=tmp_path)
        hashes.append(out.stdout.strip())
    assert hashes[0] == hashes[1] and len(hashes[0]) == 64


# --------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(window=20, size=32), "exemplar of size 16x16 is too small for window 20"),
        (dict(exemplar=np.full((16, 16), np.nan)), "NaN"),
        (dict(views=("front", "side")), "view must be one of front, right, top; got 'side'"),
        (dict(upsample="cubic"), "upsample must be one of trilinear, 8/8, 1/8; got 'cubic'"),
        (dict(size=9, levels=2), "size 9 is not divisible by 2\\*\\*\\(levels-1\\) = 2"),
        (dict(size=8, levels=2, window=5), "coarsest level has 4 voxels per side, needs at least 5"),
        (dict(size=10, levels=1, grid=4), "multiple of grid"),
        (dict(iterations=(1, 2)), "iterations must be one integer \\(one level\\)"),
        (dict(iterations=0), "iterations must be >= 1; got 0"),
        (dict(r=3.0), "r must be a finite number in \\(0.0, 2.0\\]; got 3.0"),
        (dict(eps=-1), "eps must be a finite number"),
        (dict(variance=0.0), "variance must be a finite number"),
        (dict(histogram_bins=1), "histogram_bins must be between 2 and 4096; got 1"),
        (dict(mean_shift=(1.0, 0.5, 0.2)), "mean_shift must be None, a bandwidth or a pair"),
        (dict(mean_shift=-1.0), "mean_shift must be a finite number"),
        (dict(exemplars={"top": np.zeros((16, 16))}, views=("front",)), "not constrained: top"),
        (dict(constraint=np.zeros((8, 8, 7, 1))), "constraint must have shape \\(8, 8, 8, 1\\)"),
        (dict(constraint=np.full((8, 8, 8, 1), np.nan)), "constraint contains 512 NaN"),
        (dict(constraint=np.zeros((8, 8, 8, 1)), constraint_weight=np.ones((8, 8))), "constraint_weight must be a number or an array of shape \\(8, 8, 8\\)"),
        (dict(constraint=np.zeros((8, 8, 8, 1)), constraint_weight=-1.0), "constraint_weight must be a finite number"),
        (dict(constraint_weight=1.0), "constraint_weight was given without a constraint volume"),
        (dict(rng=-3), "seed must be >= 0; got -3"),
    ],
)
def test_bad_input_raises_parameter_error(kwargs, match):
    base = dict(exemplar=np.random.default_rng(0).random((16, 16)), size=8, window=4, levels=1,
                iterations=1)
    base.update(kwargs)
    with pytest.raises(ParameterError, match=match):
        kopf_synthesize(**base)


def test_unknown_bundled_exemplar_is_a_parameter_error():
    with pytest.raises(ParameterError, match="no_such"):
        kopf_synthesize("no_such_file.png", size=8, window=4, levels=1)


# --------------------------------------------------------------------------- command line


def run_cli(capsys, *argv):
    code = cli.main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_cli_help_lists_every_option_with_its_default(capsys):
    code, out, _ = run_cli(capsys, "baseline", "kopf", "--help")
    assert code == 0
    text = " ".join(out.split())
    for option, default in [("--size", "64"), ("--window", "8"), ("--levels", "3"),
                            ("--iterations", "5"), ("--upsample", "trilinear"), ("--r", "0.8"),
                            ("--eps", "2.0"), ("--variance", "0.95"), ("--grid", "2"),
                            ("--histogram-bins", "16"), ("--histogram-weight", str(K.DEFAULT_HISTOGRAM_WEIGHT)),
                            ("--mean-shift", "1.0,0.25"), ("--views", "front,right,top"),
                            ("--seed", "0"), ("--out", "npmrf3d-kopf-out")]:
        assert option in text
        assert f"(default: {default})" in text, option
    for option in ("--exemplar-front", "--constraint", "--constraint-weight", "--quiet", "--overwrite"):
        assert option in text
    code, out, _ = run_cli(capsys, "baseline", "--help")
    assert code == 0 and "kopf" in out


def test_cli_writes_a_run_folder(capsys, tmp_path):
    out_dir = tmp_path / "run"
    code, out, err = run_cli(capsys, "baseline", "kopf", "bundled:gravel64", "--size", "16",
                             "--levels", "2", "--window", "4", "--iterations", "2,1",
                             "--out", str(out_dir), "--seed", "4")
    assert code == 0, err
    assert "level 0 (16^3)" in err  # the progress bar
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(["volume.npy", "volume.tif", "preview.png", "run.json"])
    record = json.loads((out_dir / "run.json").read_text())
    assert record["command"] == "baseline kopf" and record["seed"] == 4
    assert record["config"]["iterations"] == [2, 1] and record["exemplars"]["front"] == "bundled:gravel64"
    vol = np.load(out_dir / "volume.npy")
    assert vol.shape == (16, 16, 16, 1)
    # the library with the same arguments gives the same volume
    from npmrf3d import data, load_exemplar

    again = kopf_synthesize(load_exemplar(data.path("gravel64")), size=16, levels=2, window=4,
                            iterations=(2, 1), rng=4)
    np.testing.assert_array_equal(vol, again.volume)
    code, out, err = run_cli(capsys, "baseline", "kopf", "--size", "16", "--levels", "2",
                             "--window", "4", "--out", str(out_dir), "--quiet")
    assert code == 2 and "already holds a run" in err


@pytest.mark.parametrize(
    "argv,match",
    [
        (["--window", "80"], "--window must be between 2 and 64; got 80"),
        (["--views", "front,back"], "view must be one of"),
        (["--histogram-bins", "1"], "--histogram-bins must be between 2 and 4096"),
        (["--mean-shift", "a,b"], "--mean-shift must be"),
        (["--iterations", "x"], "--iterations must be"),
        (["--upsample", "cubic"], "upsample must be one of"),
        (["bundled:no_such"], "no_such"),
        (["missing.png"], "missing.png"),
        (["--constraint", "missing.npy"], "missing.npy"),
    ],
)
def test_cli_user_errors_exit_2_with_one_line(capsys, tmp_path, argv, match):
    out_dir = tmp_path / "out"
    code, out, err = run_cli(capsys, "baseline", "kopf", "--size", "16", "--levels", "1",
                             "--out", str(out_dir), *argv)
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2
    assert len(lines) == 1 and lines[0].startswith("npmrf3d: error: "), err
    assert match in lines[0]
    assert "Traceback" not in err and out == ""
    assert not out_dir.exists()


def test_cli_bad_constraint_shape_exits_2(capsys, tmp_path):
    path = tmp_path / "c.npy"
    np.save(path, np.zeros((8, 8, 4), dtype=np.float32))
    out_dir = tmp_path / "out"
    code, out, err = run_cli(capsys, "baseline", "kopf", "--size", "16", "--levels", "1",
                             "--constraint", str(path), "--out", str(out_dir))
    assert code == 2 and "constraint must have shape (16, 16, 16, 1)" in err
    assert len(err.strip().splitlines()) == 1 and not out_dir.exists()
