"""The batched neighbour distances (one matrix product per block of sites) against
their naive twins: operands, distances (with a float32 error bound), per-view LCPDFs, the class
updates (thread-count independence: tests/test_gemm_threads.py)."""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d._kernels._jit import single_threaded_blas
from npmrf3d._kernels.gemm import (
    BLOCK,
    block_distances,
    gemm_rows,
    make_gemm_operands,
    sites_best_distances,
)
from npmrf3d._kernels.parzen import LcpdfOptions
from npmrf3d._kernels.relax import (
    AnnealRule,
    IcmRule,
    LevelArrays,
    anneal_update_class,
    icm_update_class,
)
from npmrf3d.config import DecisionRule
from npmrf3d.model import parzen
from npmrf3d.model.parzen import PRUNE
from npmrf3d.model.relax._sweep import mean_class_sites, resolve_distances
from tests import naive
from tests.test_kernels import VIEWS3, assert_matches, make_case, naive_for, random_volume

pytestmark = pytest.mark.kernels

EPS32 = float(np.finfo(np.float32).eps)


def case(rng, channels, window, temps_mode, views=VIEWS3, rule=None, shape=(7, 8, 9)):
    labels, _, models, _, ref = make_case(rng, channels=channels, window=window, views=views,
                                          distinct_exemplars=True, rule=rule)
    for r in ref.values():  # the models keep the patches grouped by centre label
        order = np.argsort(r["centres"], kind="stable")
        r["patches"], r["centres"] = r["patches"][order], r["centres"][order]
    volume, temps, _ = random_volume(rng, labels, shape, temps_mode)
    sites = np.stack([rng.integers(0, n, size=11) for n in shape], axis=1).astype(np.int64)
    return labels, models, ref, volume, temps, sites


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("window", [3, 5])
def test_gemm_operands_match_naive(channels, window, rng):
    labels, models, ref, *_ = case(rng, channels, window, "zeros")
    ops = make_gemm_operands(models.patches_t, models.n_patches, channels)
    centre, centred, q = naive.naive_gemm_operands([ref[v]["patches"] for v in VIEWS3], channels)
    np.testing.assert_allclose(ops.centre, centre, rtol=1e-6, atol=1e-7)
    n_m = window * window - 1
    for a, v in enumerate(VIEWS3):
        n = models.n_patches[a]
        # rows m*C + c hold y'_{p,m,c}; rows M*C + m hold q_{p,m}; norms = sum_m q_{p,m}
        got = ops.patches[a, : n_m * channels, :n].T.reshape(n, n_m, channels)
        np.testing.assert_allclose(got, centred[a], rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(ops.patches[a, n_m * channels:, :n].T, q[a], rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(ops.norms[a, :n], q[a].sum(axis=1), rtol=1e-5, atol=1e-6)
        assert (ops.patches[a, :, n:] == 0).all() and (ops.norms[a, n:] == 0).all()


def lattice_temps(rng, shape, partial: bool):
    """Temperature 0 on the even lattice (inherited voxels), 1 elsewhere (hot), and with
    ``partial`` a few voxels in between: sites on the lattice then have fully trusted, untrusted
    and (``partial``) partly trusted neighbour columns in one block."""
    grid = np.indices(shape)
    temps = np.where((grid % 2 == 0).all(axis=0), 0.0, 1.0).astype(np.float32)
    if partial:
        temps[rng.random(shape) < 0.1] = 0.5
    return temps


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("window", [3, 5])
@pytest.mark.parametrize("temps_mode", ["zeros", "ones", "random", "lattice", "lattice+partial"])
def test_block_distances_match_the_direct_sum(channels, window, temps_mode, rng):
    """``D_p`` from the product equals the direct float64 sum within the expansion's float32
    error bound ``(K + 4) eps32 sum_i |terms_i|`` (the sum of the absolute values of what is
    added), and is never negative; with every mix of untrusted, fully and partly trusted
    neighbour columns (the packed products)."""
    mode = "zeros" if temps_mode.startswith("lattice") else temps_mode
    labels, models, ref, volume, temps, sites = case(rng, channels, window, mode, shape=(8, 8, 10))
    if temps_mode.startswith("lattice"):
        temps = lattice_temps(rng, temps.shape, temps_mode.endswith("partial"))
        sites = 2 * (sites // 2)
    ops = make_gemm_operands(models.patches_t, models.n_patches, channels)
    n_m = window * window - 1
    width = n_m * channels + n_m
    rows = np.arange(len(sites))
    for a, v in enumerate(VIEWS3):
        offsets = ref[v]["offsets"]
        a_rows, s0 = np.empty((BLOCK, width), np.float32), np.empty(BLOCK)
        gemm_rows(volume, temps, sites, rows, models.offsets[a], ops.centre, a_rows, s0)
        want_rows, want_s0 = naive.naive_gemm_rows(volume, temps, sites, offsets,
                                                   ops.centre.astype(np.float64))
        np.testing.assert_allclose(a_rows[: len(sites)], want_rows, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(s0[: len(sites)], want_s0, rtol=1e-6, atol=1e-6)
        n = int(models.n_patches[a])
        product = np.empty((BLOCK, models.patches_t.shape[2]), np.float32)
        with single_threaded_blas():
            block_distances(a_rows, s0, len(sites), n_m, ops.patches[a], ops.norms[a], n, product)
        got = product[: len(sites), :n].astype(np.float64)
        want = naive.naive_block_distances(volume, temps, sites, offsets, ref[v]["patches"])
        yc = np.abs(ref[v]["patches"] - ops.centre.astype(np.float64))  # (n, M, C)
        abs_terms = (np.abs(want_rows[:, : n_m * channels]) @ yc.reshape(n, -1).T
                     + np.abs(want_rows[:, n_m * channels:]) @ (yc**2).sum(axis=2).T
                     + want_s0[:, None])
        bound = (width + 4) * EPS32 * abs_terms
        assert (got >= 0).all()
        assert (np.abs(got - want) <= bound + 1e-30).all(), np.abs(got - want).max()


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("window", [3, 5])
@pytest.mark.parametrize("temps_mode", ["zeros", "ones", "random"])
@pytest.mark.parametrize("rule", [DecisionRule(), DecisionRule(bandwidth=0.5, centre_bandwidth=0.3,
                                                                outlier=0.01)],
                         ids=["literal", "sharp-ish"])
def test_log_lcpdf_sites_matches_naive(channels, window, temps_mode, rule, rng):
    labels, models, ref, volume, temps, sites = case(rng, channels, window, temps_mode, rule=rule)
    got = parzen.log_lcpdf_sites(volume, temps, sites, models, prune=700.0, outlier=rule.outlier)
    assert got.shape == (len(sites), 3, len(labels))
    for s, site in enumerate(sites):
        expected, spread = naive_for(VIEWS3, ref, volume, temps, tuple(site), labels)
        assert spread < 700.0
        if rule.outlier:
            expected = np.log((1 - rule.outlier) * np.exp(expected) + rule.outlier / len(labels))
        assert_matches(got[s], expected)


def test_log_lcpdf_sites_agrees_with_the_direct_kernel(rng):
    """The same sites through :func:`parzen.log_lcpdf` (direct sum) and the batched path,
    more sites than one block, default pruning."""
    labels, models, ref, volume, temps, _ = case(rng, 3, 3, "random", shape=(9, 9, 9))
    sites = np.argwhere(np.ones((9, 9, 9), bool))[:: 5][: BLOCK + 17].astype(np.int64)
    got = parzen.log_lcpdf_sites(volume, temps, sites, models)
    for s, site in enumerate(sites):
        np.testing.assert_allclose(got[s], parzen.log_lcpdf(volume, temps, tuple(site), models),
                                   rtol=1e-4, atol=1e-6)


def _class_state(rng, channels=1, window=3, shape=(16, 16, 16)):
    labels, models, ref, volume, temps, _ = case(rng, channels, window, "random", shape=shape)
    lab = rng.integers(0, len(labels), size=shape).astype(np.int32)
    volume = labels[lab].astype(np.float32)
    inherited = rng.random(shape) < 0.2
    temps[rng.random(shape) < 0.3] = 0.0
    # one class of the (r+1)-periodic colouring: its sites never interact
    grid = np.argwhere(np.ones(shape, bool))
    sites = grid[(grid % (window // 2 + 1) == 0).all(axis=1)].astype(np.int64)
    return labels, models, volume, lab, temps, inherited, sites


def test_icm_class_update_serial_equals_parallel(rng):
    labels, models, volume, lab, temps, inherited, sites = _class_state(rng)
    assert len(sites) > BLOCK
    ops = make_gemm_operands(models.patches_t, models.n_patches, 1)
    uniforms = rng.random(len(sites))
    out = []
    for kernel in icm_update_class:
        v, lv, t = volume.copy(), lab.copy(), temps.copy()
        old, new = np.empty(len(sites), np.int64), np.empty(len(sites), np.int64)
        with single_threaded_blas():
            kernel(LevelArrays(v, lv, t, inherited), sites, uniforms, models, ops,
                   LcpdfOptions(0.0, 0.0, PRUNE, 0.01),
                   IcmRule(3, 1, 0.1, -3.0, True, np.zeros(len(labels))), old, new)
        out.append((v, lv, t, old, new))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)
    v, lv, t, old, new = out[0]
    visited = (temps[tuple(sites.T)] > 0) | inherited[tuple(sites.T)]
    np.testing.assert_array_equal(old != -2, visited)
    np.testing.assert_array_equal(lv[tuple(sites.T)][visited], new[visited])


@pytest.mark.parametrize("sampler", ["metropolis", "heat-bath"])
def test_anneal_class_update_serial_equals_parallel_and_keeps_unchanged_sites(sampler, rng):
    labels, models, volume, lab, _, inherited, sites = _class_state(rng, channels=3)
    temps = np.zeros(lab.shape, np.float32)
    ops = make_gemm_operands(models.patches_t, models.n_patches, 3)
    candidates = rng.integers(0, len(labels), size=len(sites)).astype(np.int64)
    candidates[::3] = lab[tuple(sites[::3].T)]  # proposals equal to the current label
    uniforms = rng.random(len(sites))
    out = []
    for kernel in anneal_update_class:
        v, lv = volume.copy(), lab.copy()
        old, new = np.empty(len(sites), np.int64), np.empty(len(sites), np.int64)
        with single_threaded_blas():
            kernel(LevelArrays(v, lv, temps, inherited), sites,
                   candidates if sampler == "metropolis" else None, uniforms, models, ops,
                   LcpdfOptions(0.0, 0.0, PRUNE, 0.0),
                   AnnealRule(3, 0.5, False, np.zeros(len(labels))), old, new)
        out.append((v, lv, old, new))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)
    v, lv, old, new = out[0]
    skipped = inherited[tuple(sites.T)]
    assert (old[skipped] == -2).all() and (old[~skipped] == lab[tuple(sites[~skipped].T)]).all()
    if sampler == "metropolis":
        assert set(new[~skipped]) <= set(candidates) | set(old)
        same = ~skipped & (candidates == lab[tuple(sites.T)])
        np.testing.assert_array_equal(new[same], old[same])
    np.testing.assert_array_equal(v[tuple(sites.T)], labels[lv[tuple(sites.T)]])


@pytest.mark.parametrize("temps_mode", ["zeros", "random", "lattice"])
def test_best_distances_match_naive_on_both_paths(temps_mode, rng):
    labels, models, ref, volume, temps, _ = case(rng, 3, 3, "zeros" if temps_mode == "lattice"
                                                 else temps_mode, shape=(8, 8, 8))
    if temps_mode == "lattice":
        temps = lattice_temps(rng, temps.shape, False)
    sites = np.argwhere(np.ones((8, 8, 8), bool))[::2].astype(np.int64)  # 256 + 0: two blocks
    ops = make_gemm_operands(models.patches_t, models.n_patches, 3)
    got = np.empty((len(sites), 3), np.float32)
    direct = np.empty((len(sites), 3), np.float32)
    with single_threaded_blas():
        sites_best_distances(volume, temps, sites, models, ops, got)
    sites_best_distances(volume, temps, sites, models, None, direct)
    want = np.array([[naive.naive_block_distances(volume, temps, [s], ref[v]["offsets"],
                                                  ref[v]["patches"]).min() for v in VIEWS3]
                     for s in sites])
    np.testing.assert_allclose(direct, want, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-5)


def test_auto_distances_take_the_product_from_the_measured_dimension_and_class_size(rng):
    grey = case(rng, 1, 5, "zeros")[1]  # d = 24
    colour = case(rng, 3, 7, "zeros", views=("front",))[1]  # d = 144
    assert resolve_distances("auto", grey) == "direct"
    assert resolve_distances("auto", colour) == "gemm"
    assert resolve_distances("direct", colour) == "direct"
    grey7 = case(rng, 1, 7, "zeros", views=("front",))[1]  # d = 48
    assert resolve_distances("auto", grey7) == "gemm"
    assert resolve_distances("auto", grey7, class_sites=4096) == "gemm"
    assert resolve_distances("auto", grey7, class_sites=64) == "direct"  # less than one block
    assert resolve_distances("auto", colour, class_sites=511) == "direct"
    assert resolve_distances("gemm", colour, class_sites=64) == "gemm"
    assert resolve_distances("auto", grey, class_sites=4096) == "direct"
    assert mean_class_sites([np.zeros((3, 3)), np.zeros((5, 3))]) == 4.0
    with pytest.raises(ValueError, match="distances must be one of auto, gemm, direct; got 'blas'"):
        resolve_distances("blas", grey)
