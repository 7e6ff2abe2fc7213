"""Chen & Wang 2010 (npmrf3d.model.kcoherence and its engine, methods.chen_wang) against literal twins.

Kernels against ``tests/naive.py``; k-coherence sets against brute force; the candidate
set of a site against its definition; discrete copies only; the position histogram spreading a
skewed usage; thread-count independence; a periodic exemplar; user errors; checkpoints.
Everything is tiny (exemplars up to 32x32, volumes 8^3 to 16^3).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from npmrf3d._kernels import candidate_decision as _decide
from npmrf3d._kernels import kcoherence as _k
from npmrf3d._kernels.candidate_decision import HEAT_BATH, METROPOLIS, ML_H1A, ML_H1B, ML_H2A, ML_H2B
from npmrf3d._kernels import kcoherence_solver as _s
from npmrf3d.config import SynthesisResult
from npmrf3d.errors import ParameterError
from npmrf3d.methods import chen_wang as CW
from npmrf3d.methods.chen_wang import ChenWangConfig, chen_wang_synthesize
from npmrf3d.methods.npmrf_coherent import _chen_wang_config, coherent_synthesize, make_coherent_config
from npmrf3d.model import kcoherence as coh
from npmrf3d.model.kcoherence_engine import (CandidateDecision, KCoherenceLevels, ValueHistogram, kernel_table,
                                              pack_exemplars)
from npmrf3d.model.neighbourhood import VIEW_AXES
from tests.naive import (
    naive_central_texels,
    naive_candidates,
    naive_exemplar_patch,
    naive_k_coherence,
    naive_kernel_table,
    naive_search_view,
    naive_solve,
    naive_top_votes,
    naive_upsample_sources,
    naive_value_bin,
    naive_volume_patch,
)

VIEWS3 = ("front", "right", "top")


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def random_exemplar(rng, h=20, w=18, c=1):
    return rng.random((h, w, c)).astype(np.float32)


# --------------------------------------------------------------------------- model layer


@pytest.mark.parametrize("window", [3, 4])
@pytest.mark.parametrize("channels", [1, 3])
def test_level_model_projects_the_valid_centres(rng, window, channels):
    ex = random_exemplar(rng, c=channels)
    m = coh.build_level_model(ex, window, dims=6, k=3)
    lo_r, hi_r, lo_c, hi_c = m.bounds
    assert (lo_r, lo_c) == (coh.anchor(window),) * 2
    assert hi_r == ex.shape[0] - window + coh.anchor(window)
    assert m.basis.shape == (window * window * channels, 6)
    np.testing.assert_allclose(m.basis.T.astype(np.float64) @ m.basis, np.eye(6), atol=1e-5)
    for r, c in [(lo_r, lo_c), (hi_r, hi_c), (lo_r + 1, hi_c - 1)]:
        patch = naive_exemplar_patch(ex, r, c, window)
        want = (patch - m.mean) @ m.basis.astype(np.float64)
        np.testing.assert_allclose(m.proj[r * ex.shape[1] + c], want, atol=1e-4)
    invalid = np.ones((ex.shape[0], ex.shape[1]), bool)
    invalid[lo_r:hi_r + 1, lo_c:hi_c + 1] = False
    assert (m.kcoh.reshape(ex.shape[0], ex.shape[1], -1)[invalid] == -1).all()
    valid = m.kcoh.reshape(ex.shape[0], ex.shape[1], -1)[~invalid]
    rows, cols = valid // ex.shape[1], valid % ex.shape[1]
    assert ((rows >= lo_r) & (rows <= hi_r) & (cols >= lo_c) & (cols <= hi_c)).all()


@pytest.mark.parametrize("exclude", [0.0, 2.0])
def test_k_coherence_sets_equal_brute_force(rng, exclude):
    points = rng.normal(size=(150, 5))
    coords = np.stack(np.unravel_index(np.arange(150), (10, 15)), axis=1)
    got = coh.k_coherence_sets(points, 5, exclude=exclude, coords=coords)
    want = naive_k_coherence(points, 5, exclude, coords)
    np.testing.assert_array_equal(got, want)
    assert not (got == np.arange(150)[:, None]).any()


def test_level_model_k_coherence_sets_equal_brute_force_in_pca_space(rng):
    ex = random_exemplar(rng, 14, 13, 3)
    m = coh.build_level_model(ex, 4, dims=8, k=5)
    lo_r, hi_r, lo_c, hi_c = m.bounds
    flat = np.array([r * 13 + c for r in range(lo_r, hi_r + 1) for c in range(lo_c, hi_c + 1)])
    want = flat[naive_k_coherence(m.proj[flat], 5)]
    np.testing.assert_array_equal(m.kcoh[flat], want)


@pytest.mark.kernels
def test_candidate_set_equals_its_definition(rng):
    ex = random_exemplar(rng, 12, 11)
    m = coh.build_level_model(ex, 4, dims=5, k=2)
    src = rng.integers(0, 12 * 11, size=(5, 6, 7)).astype(np.int32)
    for view in VIEW_AXES:
        for site in [(0, 0, 0), (4, 5, 6), (2, 3, 1)]:
            got = coh.candidate_set(src, view, site, m)
            want = naive_candidates(src, view, site, 11, m.bounds, m.kcoh)
            assert got.tolist() == want
            assert 1 <= len(got) <= 9 * 3


def test_candidate_set_by_hand():
    """A 3x3 block of sources copied coherently from the exemplar gives one shift + its set."""
    ex = np.arange(100, dtype=np.float32).reshape(10, 10, 1)
    m = coh.build_level_model(ex, 3, dims=2, k=1)
    src = np.zeros((3, 3, 1), dtype=np.int32)
    for i in range(3):
        for j in range(3):
            src[i, j, 0] = (4 + i) * 10 + (5 + j)  # voxel (i, j) copied pixel (4 + i, 5 + j)
    got = coh.candidate_set(src, "front", (1, 1, 0), m)
    centre = 5 * 10 + 6
    assert got.tolist() == sorted({centre, int(m.kcoh[centre, 0])})


@pytest.mark.kernels
def test_upsample_sources_matches_twin(rng):
    """Even finer exemplars, and odd ones (the last row and column clipped)."""
    src = rng.integers(0, 6 * 7, size=(3, 4, 5)).astype(np.int32)
    for view in VIEW_AXES:
        for fine in ((12, 14), (11, 13)):
            got = coh.upsample_sources(src, view, 7, fine)
            np.testing.assert_array_equal(got, naive_upsample_sources(src, view, 7, fine))


def test_histogram_factor_is_the_papers_reweighting():
    counts = np.array([0.0, 4.0, 8.0, 20.0])
    np.testing.assert_allclose(coh.histogram_factor(counts, 4.0), [1, 1, 2, 5])
    # strength = even share gives the paper's count form 1 + max(0, H - theta)
    np.testing.assert_allclose(coh.histogram_factor(counts, 4.0, 4.0), 1 + np.maximum(0, counts - 4))


# --------------------------------------------------------------------------- kernels vs twins


def _search_case(rng, view, window, channels, grid):
    ex = random_exemplar(rng, 13, 12, channels)
    m = coh.build_level_model(ex, window, dims=6, k=3)
    vol = rng.random((8, 6, 4, channels)).astype(np.float32)
    src = rng.integers(0, 13 * 12, size=vol.shape[:3]).astype(np.int32)
    assign = np.full(vol.shape[:3], -1, dtype=np.int32)
    return ex, m, vol, src, assign


@pytest.mark.kernels
@pytest.mark.parametrize("view", VIEWS3)
@pytest.mark.parametrize("window,channels,grid,batches,n_random,box,index_weight", [
    (3, 1, 1, 1, 0, None, 2.0), (4, 3, 2, 3, 4, None, 2.0), (4, 1, 1, 2, 0, None, 2.0),
    (3, 1, 2, 2, 0, ((1, 2, 0), (7, 5, 3)), 2.0), (3, 1, 1, 1, 2, ((3, 0, 1), (5, 6, 4)), 2.0),
    (4, 3, 2, 3, 4, None, 0.0), (3, 1, 2, 2, 0, ((1, 2, 0), (7, 5, 3)), 0.0)])
def test_search_view_matches_twin(rng, view, window, channels, grid, batches, n_random, box, index_weight):
    """Every site, or only the sites of a box (a block's pass: the others keep their assignment
    and weight); without an index weight the histogram need not follow the assignments
    (``follow=False``: one parallel loop, the histogram left as it was)."""
    ex, m, vol, src, assign = _search_case(rng, view, window, channels, grid)
    ra, ca = VIEW_AXES[view]
    na = 3 - ra - ca
    lo_r, hi_r, lo_c, hi_c = m.bounds
    # a previous assignment whose counts the index histogram holds, so the penalty bites
    prev = np.full(vol.shape[:3], -1, dtype=np.int32)
    prev_t = np.moveaxis(prev, (na, ra, ca), (0, 1, 2))
    centres = np.array([r * 12 + c for r in range(lo_r, hi_r + 1) for c in range(lo_c, hi_c + 1)])
    prev_t[:, ::grid, ::grid] = rng.choice(centres[:5], size=prev_t[:, ::grid, ::grid].shape)
    hist = np.bincount(prev[prev >= 0], minlength=m.pixels).astype(np.float64)
    n_sites = int((prev >= 0).sum())
    phi = n_sites / m.centres
    want_assign, want_omega, want_energy, want_hist = naive_search_view(
        vol, src, view, m, grid=grid, batches=batches, index_hist=hist, phi=phi, index_weight=index_weight,
        r=0.8, floor=1e-3, assign_v=prev, n_random=n_random, salt=123456789, box=box)
    got_assign = prev.copy()
    got_hist = hist.copy()
    omega = np.zeros(vol.shape[:3], dtype=np.float32)
    energy = np.zeros(vol.shape[na])
    rule = _k.SearchRule(grid, batches, phi, index_weight, 0.8, 1e-3, n_random, 123456789,
                         follow=index_weight > 0.0)
    if box is not None:
        rule = rule._replace(box_lo=np.array(box[0], dtype=np.int64), box_hi=np.array(box[1], dtype=np.int64))
    _k.search_view(vol, src, ra, ca, coh.search_exemplar(m), rule, got_hist, got_assign,
                   np.empty(vol.shape[:3], dtype=np.int32), omega, energy, _k.NO_TRUST)
    np.testing.assert_array_equal(got_assign, want_assign)
    np.testing.assert_allclose(omega, want_omega, rtol=1e-4)
    np.testing.assert_allclose(energy, want_energy, rtol=1e-6)
    np.testing.assert_array_equal(got_hist, want_hist if index_weight > 0.0 else hist)


@pytest.mark.kernels
def test_volume_patch_projection_is_the_models(rng):
    """A volume slice that copies the exemplar coherently finds the copied centre at distance 0."""
    ex = random_exemplar(rng, 16, 16)
    m = coh.build_level_model(ex, 4, dims=40, k=2)
    vol = np.zeros((8, 8, 2, 1), dtype=np.float32)
    src = np.zeros((8, 8, 2), dtype=np.int32)
    for i in range(8):
        for j in range(8):
            vol[i, j] = ex[3 + i, 4 + j]
            src[i, j] = (3 + i) * 16 + 4 + j
    assert np.allclose(naive_volume_patch(vol, "front", (3, 3, 0), 4),
                       naive_exemplar_patch(ex, 6, 7, 4))
    assign = np.full((8, 8, 2), -1, dtype=np.int32)
    omega = np.zeros((8, 8, 2), dtype=np.float32)
    _k.search_view(vol, src, 0, 1, coh.search_exemplar(m), _k.SearchRule(1, 1, 1.0, 0.0, 0.8, 1e-6, 0, 0),
                   np.zeros(m.pixels), assign, np.empty_like(assign), omega, np.zeros(2), _k.NO_TRUST)
    assert assign[3, 3, 0] == 6 * 16 + 7  # interior site: the exact copy


@pytest.mark.kernels
@pytest.mark.parametrize("view", VIEWS3)
@pytest.mark.parametrize("channels", [1, 3])
def test_project_sites_matches_twin(rng, view, channels):
    ex = random_exemplar(rng, 12, 12, channels)
    m = coh.build_level_model(ex, 3, dims=5, k=2)
    vol = rng.random((5, 6, 7, channels)).astype(np.float32)
    sites = rng.choice(5 * 6 * 7, size=20, replace=False).astype(np.int64)
    got = np.empty((20, m.basis.shape[1]))
    ra, ca = VIEW_AXES[view]
    _k.project_sites(vol, ra, ca, 3, m.anchor, m.mean, m.basis, sites, got)
    for i, flat in enumerate(sites):
        site = np.unravel_index(flat, vol.shape[:3])
        want = (naive_volume_patch(vol, view, site, 3) - m.mean) @ m.basis
        np.testing.assert_allclose(got[i], want, rtol=1e-12, atol=1e-12)


def test_global_matches_take_the_brute_force_nearest_centre_where_clearly_better(rng):
    """The worst-matched share of sites is re-matched with its nearest valid centre in the PCA
    space (brute force here) when that is more than (1 + bias) times closer; counts follow."""
    ex = random_exemplar(rng, 12, 12)
    m = coh.build_level_model(ex, 3, dims=9, k=2)
    vol = rng.random((6, 6, 4, 1)).astype(np.float32)
    shape = vol.shape[:3]
    assign = rng.choice(m.valid, size=shape).astype(np.int32)
    omega = (rng.random(shape) + 0.5).astype(np.float32)
    hist = np.bincount(assign.ravel(), minlength=m.pixels).astype(np.float64)
    before_assign, before_omega, before_hist = assign.copy(), omega.copy(), hist.copy()
    r, floor, share, bias = 0.8, 1e-6, 0.25, 0.1
    replaced, change = coh.global_matches(vol, "front", m, assign, omega, hist, share=share, bias=bias,
                                          phi=1e9, index_weight=0.0, r=r, floor=floor)
    flat_w = before_omega.ravel()
    worst = np.argsort(flat_w, kind="stable")[:int(np.ceil(share * flat_w.size))]
    expect_changed = 0
    for flat in range(flat_w.size):
        site = np.unravel_index(flat, shape)
        if flat not in worst:
            assert assign[site] == before_assign[site] and omega[site] == before_omega[site]
            continue
        y = (naive_volume_patch(vol, "front", site, 3) - m.mean) @ m.basis
        d = np.sqrt(((m.proj[m.valid] - y) ** 2).sum(axis=1))
        best = int(np.argmin(d))
        old = float(before_omega[site]) ** (1.0 / (r - 2.0))
        if max(d[best], floor) * (1 + bias) < old:
            assert assign[site] == m.valid[best]
            np.testing.assert_allclose(omega[site], max(d[best], floor) ** (r - 2.0), rtol=1e-5)
            expect_changed += 1
        else:
            assert assign[site] == before_assign[site]
    assert replaced == expect_changed > 0
    np.testing.assert_array_equal(hist, np.bincount(assign.ravel(), minlength=m.pixels))
    assert before_hist.sum() == hist.sum()
    assert change < 0  # every replacement lowers the energy


def test_value_histogram_counts_in_even_bin_units(rng):
    ex = rng.random((10, 12, 2)).astype(np.float32)
    vol = rng.random((4, 5, 6, 2)).astype(np.float32)
    lo, span = ex.reshape(-1, 2).min(axis=0), np.ptp(ex.reshape(-1, 2), axis=0)
    vh = ValueHistogram.build([ex], ex.reshape(-1, 2), vol, bins=8, lo=lo, span=span)
    scale = 8 / span.astype(np.float64)
    for c in range(2):
        want = np.bincount([naive_value_bin(x, float(lo[c]), scale[c], 8) for x in vol[..., c].ravel()],
                           minlength=8)
        np.testing.assert_allclose(vh.hist[c] * vh.unit, want)
        want_ex = np.bincount([naive_value_bin(x, float(lo[c]), scale[c], 8) for x in ex[..., c].ravel()],
                              minlength=8)
        np.testing.assert_allclose(vh.target[c], want_ex / want_ex.sum() * 8)
        np.testing.assert_array_equal(vh.ex_bins[:, c], [naive_value_bin(x, float(lo[c]), scale[c], 8)
                                                         for x in ex[..., c].ravel()])
    assert vh.unit == 4 * 5 * 6 / 8


@pytest.mark.parametrize("weight,prior,likelihood", [(32.0, 0.0, 0), (32.0, 3.0, 0), (32.0, 3.0, 1)])
def test_value_histogram_pulls_the_solver_towards_the_exemplars_histogram(weight, prior, likelihood):
    """Every voxel is voted for by dark and bright texels, dark ones in the majority (the
    exemplar is one bright column in three): without histogram matching the solver copies dark
    almost everywhere; with it the bright share comes close to the exemplar's third, and the
    histogram the solver tracks is the volume's."""
    ex = np.where(np.arange(12) % 3 == 0, 0.9, 0.1).astype(np.float32)[None, :].repeat(12, 0)[..., None]
    m = coh.build_level_model(ex, 4, dims=3, k=2)
    shape, n = (8, 8, 8), 512
    share = {}
    for w in (0.0, weight):
        gen = np.random.default_rng(0)
        assign = gen.choice(m.valid, size=(1, *shape)).astype(np.int32)
        vol = np.full((*shape, 1), 0.1, dtype=np.float32)
        src = np.zeros((1, *shape), dtype=np.int32)
        hist = np.bincount(src.ravel(), minlength=144).astype(np.float64)
        vh = ValueHistogram.build([ex], ex.reshape(-1, 1), vol, bins=4, lo=np.array([0.1]),
                                      span=np.array([0.8]))
        _s.solve(vol, src, assign, np.ones((1, *shape), dtype=np.float32),
                 _packed([[0, 1]], ex.reshape(-1, 1), [0], [12], 4, m.anchor, 1),
                 _histograms(hist, [0], [n / 144.0], 0.0, 0.0, ex.reshape(-1, 1), vh, w, prior if w else 0.0),
                 _s.NO_TRUST, _s.SolverRule(8, False, likelihood, 0.01, 0.01, 0.0, 0),
                 gen.permutation(n).astype(np.int64), np.linspace(0, n, 17).astype(np.int64), 16)
        share[w] = float((vol > 0.5).mean())
        np.testing.assert_allclose(vh.hist[0] * vh.unit, [np.sum(vol < 0.5), 0, 0, np.sum(vol > 0.5)])
    assert share[0.0] < 0.15
    assert 0.25 < share[weight] < 0.42


def _solve_case(rng, views, window, channels, grid, shared=True):
    exemplars = [random_exemplar(rng, 11, 10, channels)]
    for _ in views[1:]:
        exemplars.append(exemplars[0] if shared else random_exemplar(rng, 11, 10, channels))
    models = [coh.build_level_model(e, window, dims=4, k=2) for e in exemplars]
    shape = (6, 4, 8)
    assign = np.full((len(views), *shape), -1, dtype=np.int32)
    for vi, view in enumerate(views):
        ra, ca = VIEW_AXES[view]
        lo_r, hi_r, lo_c, hi_c = models[vi].bounds
        r = rng.integers(lo_r, hi_r + 1, size=shape)
        c = rng.integers(lo_c, hi_c + 1, size=shape)
        full = (r * 10 + c).astype(np.int32)
        mask = np.zeros(shape, bool)
        sl = [slice(None)] * 3
        sl[ra] = slice(None, None, grid)
        sl[ca] = slice(None, None, grid)
        mask[tuple(sl)] = True
        assign[vi] = np.where(mask, full, -1)
    omega = rng.random((len(views), *shape)).astype(np.float32) + 0.1
    src = rng.integers(0, 110, size=(len(views), *shape)).astype(np.int32)
    volume = rng.random((*shape, channels)).astype(np.float32)
    return exemplars, models, assign, omega, src, volume


def _values(exemplars, models, volume, bins=5):
    """The value histograms of a solver case (views' distinct exemplars pooled)."""
    packed, _, _ = pack_exemplars(models)
    distinct = list({id(e): e for e in exemplars}.values())
    pooled = np.concatenate([e.reshape(-1, e.shape[2]) for e in distinct]).astype(np.float64)
    return ValueHistogram.build(exemplars, packed, volume, bins=bins, lo=pooled.min(axis=0),
                                    span=pooled.max(axis=0) - pooled.min(axis=0))


def _packed(axes, texels, offsets, widths, window, anchor, grid):
    """The solver's view of the packed exemplars (:class:`npmrf3d._kernels.kcoherence_solver.PackedViews`)."""
    return _s.PackedViews(np.asarray(axes, dtype=np.int64), texels, np.asarray(offsets, dtype=np.int64),
                          np.asarray(widths, dtype=np.int64), int(window), int(anchor), int(grid))


def _histograms(positions, offsets, theta, weight, boost, texels, values=None, value_weight=0.0, value_prior=0.0,
                follow=True):
    """The solver's histograms; without ``values`` (a :class:`ValueHistogram`) histogram matching is off."""
    offsets, theta = np.asarray(offsets, dtype=np.int64), np.asarray(theta, dtype=np.float64)
    if values is None:
        channels = texels.shape[1]
        zeros = np.zeros((channels, 2))
        return _s.SolverHistograms(positions, offsets, theta, weight, boost, np.zeros(texels.shape, np.int64),
                                   zeros, zeros, 0.0, 0.0, np.zeros(channels), np.zeros(channels), 1.0)
    return _s.SolverHistograms(positions, offsets, theta, weight, boost, values.ex_bins, values.hist,
                               values.target, value_weight, value_prior, values.lo, values.scale, values.unit, follow)


@pytest.mark.parametrize("views", [("front",), ("front", "top"), VIEWS3])
@pytest.mark.parametrize("medoid,balance,boost,likelihood,value_weight,temperature", [
    (0, False, 0.0, 0, 0.0, 0.0), (0, True, 2.0, 0, 4.0, 0.0), (3, False, 0.0, 0, 0.0, 0.0),
    (8, True, 5.0, 0, 4.0, 0.0), (8, False, 0.0, 1, 4.0, 0.0), (3, True, 2.0, 2, 0.0, 0.0),
    (3, False, 2.0, 2, 4.0, 0.0), (8, False, 0.0, 1, 4.0, 0.7), (3, True, 2.0, 2, 0.0, 2.0)])
@pytest.mark.kernels
@pytest.mark.parametrize("grid,channels", [(1, 1), (2, 3)])
def test_solve_matches_twin(rng, views, medoid, balance, boost, likelihood, value_weight, temperature, grid,
                            channels):
    _check_solve_against_twin(rng, views, medoid, balance, boost, likelihood, value_weight, temperature, grid,
                              channels)


@pytest.mark.parametrize("views", [("front",), ("front", "top"), VIEWS3])
@pytest.mark.parametrize("likelihood,balance,value_weight,temperature,sampler", [
    (ML_H1A, False, 0.0, 0.0, HEAT_BATH), (ML_H1A, True, 4.0, 0.0, HEAT_BATH),
    (ML_H1B, False, 0.0, 0.0, HEAT_BATH), (ML_H1B, True, 4.0, 0.0, HEAT_BATH),
    (ML_H2B, False, 4.0, 0.7, METROPOLIS), (ML_H2B, True, 0.0, 0.05, METROPOLIS),
    (ML_H2A, False, 4.0, 2.0, METROPOLIS), (ML_H2A, True, 0.0, 0.3, METROPOLIS)])
@pytest.mark.kernels
@pytest.mark.parametrize("grid,channels", [(1, 1), (2, 3)])
def test_solve_candidate_heuristics_and_metropolis_match_twin(rng, views, likelihood, balance, value_weight,
                                                              temperature, sampler, grid, channels):
    """ML_H1a, ML_H1b (ICM) and the Metropolis step over the candidates, against the twin."""
    _check_solve_against_twin(rng, views, 6, balance, 2.0, likelihood, value_weight, temperature, grid, channels,
                              sampler)


@pytest.mark.kernels
@pytest.mark.parametrize("likelihood,sampler,temperature", [
    (0, HEAT_BATH, 0.0), (ML_H2B, HEAT_BATH, 0.0), (ML_H2A, HEAT_BATH, 0.7), (ML_H1B, HEAT_BATH, 0.0),
    (ML_H2B, METROPOLIS, 0.3)])
def test_solve_with_histograms_set_by_the_caller_matches_twin(rng, likelihood, sampler, temperature):
    """``follow=False`` (a block reading its pilot's histograms): one batch decides as the twin
    does, every voxel's sources are written, and the histograms are left as they were."""
    _check_solve_against_twin(rng, VIEWS3, 6, False, 2.0, likelihood, 4.0, temperature, 2, 3, sampler,
                              follow=False)


@pytest.mark.kernels
@pytest.mark.parametrize("channels,levels", [(1, 9), (3, 4)])
def test_kernel_table_matches_twin(rng, channels, levels):
    """The NP-MRF kernel between the distinct colours, and each texel's colour, against the twin."""
    texels = (rng.integers(0, levels, size=(60, channels)) / (levels - 1)).astype(np.float32)
    ids, table = kernel_table(texels, 0.05)
    want_ids, want_table = naive_kernel_table(texels, 0.05)
    np.testing.assert_array_equal(ids, want_ids)
    np.testing.assert_allclose(table, want_table, rtol=1e-13, atol=0)  # numpy's exp differs in the last bit
    assert kernel_table(texels, 0.05, most=2)[1].shape == (0, 0)  # too many colours: none
    # the look-up gives the very bits the solver's direct estimate gives
    u, n_views = 40, 3
    ug = rng.integers(0, len(texels), size=u).astype(np.int64)
    uv = np.sort(rng.integers(0, n_views, size=u)).astype(np.int64)
    uw = rng.random(u)
    vsum = np.array([uw[uv == v].sum() for v in range(n_views)])
    for ga in range(len(texels)):
        want, got = np.empty(n_views), np.empty(n_views)
        _decide.view_likelihoods(texels[ga], texels, ug, uv, uw, u, vsum, 0.05, 0.01, want)
        _decide.view_likelihoods_table(table[ids[ga]], ids[ug], uv, uw, u, vsum, 0.01, got)
        np.testing.assert_array_equal(got, want)
    # every candidate at once (votes sorted by view, and not), the same bits again
    rows = ids[rng.permutation(len(texels))[:7]].astype(np.int64)
    for order in (np.arange(u), rng.permutation(u)):
        many = np.empty((7, n_views))
        _decide.candidate_likelihoods(table, rows, 7, ids[ug][order], uv[order], uw[order], u, vsum, 0.01, many)
        for a in range(7):
            one = np.empty(n_views)
            _decide.view_likelihoods_table(table[rows[a]], ids[ug][order], uv[order], uw[order], u, vsum, 0.01, one)
            np.testing.assert_array_equal(many[a], one)


@pytest.mark.kernels
@pytest.mark.parametrize("views,channels", [(2, 1), (3, 1), (3, 3)])
def test_central_texels_match_their_twin(rng, views, channels):
    """The most central of the views' texels, with ties (equal texels, and a texel equidistant
    from two others) going to the first view."""
    levels = rng.integers(0, 4, size=(views, 300, channels)).astype(np.float32) / 3
    out = np.empty((300, channels), dtype=np.float32)
    _k.central_texels(levels, out)
    np.testing.assert_array_equal(out, naive_central_texels(levels))


@pytest.mark.kernels
@pytest.mark.parametrize("likelihood", [ML_H2B, ML_H2A])
def test_the_highest_objective_ranked_by_products_is_the_objectives(rng, likelihood):
    """Ranked by products of the estimates, settled by the objectives among near ties: the
    first candidate of the highest objective (the literal loop over :func:`objective`), with
    candidates whose estimates are permutations of one another (equal products, log-sums that
    may differ in the last bit), equal candidates, zero priors and an extreme prior."""
    for trial in range(300):
        n_try, n_views = int(rng.integers(1, 9)), 3
        liks = rng.uniform(0.01, 1.0, size=(n_try, n_views))
        for a in range(1, n_try):
            if rng.random() < 0.4:
                liks[a] = rng.permutation(liks[int(rng.integers(0, a))])
        prior = np.where(rng.random(n_try) < 0.5, 0.0, rng.normal(0.0, 3.0, n_try))
        if trial % 50 == 0:
            prior[:] = 900.0 * rng.choice([-1.0, 1.0])  # products out of range: every objective
        with np.errstate(over="ignore"):
            if likelihood == ML_H2B:
                products = np.exp(prior) * liks.prod(axis=1)
            else:
                products = liks.min(axis=1) * np.exp(prior)
        with np.errstate(over="ignore"):  # the extreme prior's exp(900), without the compiler
            scores = [_decide.objective(liks[a], likelihood, prior[a]) for a in range(n_try)]
            got = _decide.highest_objective(products, n_try, liks, likelihood, prior, -1)
        want = -1
        for a in range(n_try):
            if want < 0 and scores[a] > -np.inf or want >= 0 and scores[a] > scores[want]:
                want = a
        assert got == want
    if likelihood == ML_H2B:
        # a permutation whose product is one bit higher and whose log-sum is one bit lower
        liks = np.array([[0.8294255678822373, 0.4151071450054697, 0.554097750796329],
                         [0.4151071450054697, 0.554097750796329, 0.8294255678822373]])
        products = np.array([liks[0, 0] * liks[0, 1] * liks[0, 2], liks[1, 0] * liks[1, 1] * liks[1, 2]])
        scores = [_decide.objective(row, ML_H2B, 0.0) for row in liks]
        assert products[1] > products[0] and scores[0] > scores[1]
        assert _decide.highest_objective(products, 2, liks, ML_H2B, np.zeros(2), -1) == 0


@pytest.mark.parametrize("views", [("front", "top"), VIEWS3])
@pytest.mark.parametrize("likelihood,temperature,sampler", [
    (ML_H2B, 0.0, HEAT_BATH), (ML_H2A, 0.0, HEAT_BATH), (ML_H1A, 0.0, HEAT_BATH), (ML_H1B, 0.0, HEAT_BATH),
    (ML_H2B, 0.7, HEAT_BATH), (ML_H2B, 0.7, METROPOLIS)])
@pytest.mark.kernels
@pytest.mark.parametrize("grid,channels", [(1, 1), (2, 3)])
def test_solve_with_kernel_table_matches_twin(rng, views, likelihood, temperature, sampler, grid, channels):
    """The NP-MRF rules with the kernel looked up (:func:`kernel_table`), against the twin."""
    _check_solve_against_twin(rng, views, 6, False, 2.0, likelihood, 4.0, temperature, grid, channels, sampler,
                              tabled=True)


def _check_solve_against_twin(rng, views, medoid, balance, boost, likelihood, value_weight, temperature, grid,
                              channels, sampler=HEAT_BATH, tabled=False, follow=True):
    window = 4
    exemplars, models, assign, omega, src, volume = _solve_case(rng, views, window, channels, grid,
                                                                shared=len(views) != 2)
    vh = _values(exemplars, models, volume)
    values = {"hist": vh.hist.tolist(), "target": vh.target.tolist(), "weight": value_weight,
              "prior": 2.0 * (likelihood > 0 and value_weight > 0),
              "lo": vh.lo.tolist(), "scale": vh.scale.tolist(), "unit": vh.unit}
    packed, ex_off, hist_off = pack_exemplars(models)
    n = volume.shape[0] * volume.shape[1] * volume.shape[2]
    order = rng.permutation(n).astype(np.int64)
    # histograms that do not follow the sources: one batch (between batches they would differ)
    bounds = np.array([0, 50, 120, n] if follow else [0, n], dtype=np.int64)
    pos_hist = [np.bincount(src[vi].ravel(), minlength=110).astype(np.float64) for vi in range(len(views))]
    before = np.concatenate(pos_hist), vh.hist.copy()
    theta = np.full(len(views), n / 110.0)
    want_vol, want_src, want_hist, want_changed = naive_solve(
        volume, src, assign, omega, views, exemplars, window=window, grid=grid, order=order,
        bounds=bounds, pos_hist=pos_hist, theta=theta, position_weight=3.0, position_boost=boost, medoid=medoid,
        balance=balance, likelihood=likelihood, h2c=0.05, outlier=0.01, values=values,
        temperature=temperature, salt=12345, sampler=sampler)
    got_vol, got_src = volume.copy(), src.copy()
    got_hist = np.concatenate(pos_hist)
    changed = _s.solve(got_vol, got_src, assign, omega,
                       _packed([VIEW_AXES[v] for v in views], packed, ex_off, [10] * len(views), window,
                               coh.anchor(window), grid),
                       _histograms(got_hist, hist_off, theta, 3.0, boost, packed, vh, value_weight, values["prior"],
                                   follow),
                       _s.NO_TRUST, _s.SolverRule(medoid, balance, likelihood, 0.05, 0.01, temperature, 12345, sampler,
                                                  np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64),
                                                  *(kernel_table(packed, 0.05) if tabled else
                                                    (np.zeros(0, dtype=np.int64), np.zeros((0, 0))))),
                       order, bounds, 7)
    np.testing.assert_array_equal(got_vol, want_vol)
    np.testing.assert_array_equal(got_src, want_src)
    assert changed == want_changed
    if follow:
        np.testing.assert_allclose(vh.hist, np.array(values["hist"]), atol=1e-12)
        np.testing.assert_array_equal(got_hist, np.concatenate(want_hist))
    else:  # left as they were
        np.testing.assert_array_equal(got_hist, before[0])
        np.testing.assert_array_equal(vh.hist, before[1])


def test_solve_copies_only_voted_exemplar_texels(rng):
    views = VIEWS3
    exemplars, models, assign, omega, src, volume = _solve_case(rng, views, 4, 3, 1)
    packed, ex_off, hist_off = pack_exemplars(models)
    n = volume.shape[0] * volume.shape[1] * volume.shape[2]
    hist = np.concatenate([np.bincount(s.ravel(), minlength=110) for s in src]).astype(np.float64)
    _s.solve(volume, src, assign, omega, _packed([VIEW_AXES[v] for v in views], packed, ex_off, [10] * 3, 4, 1, 1),
             _histograms(hist, hist_off, [n / 110] * 3, 1.0, 0.0, packed), _s.NO_TRUST, _s.SolverRule(0, False, 0, 1.0, 0.0, 0.0, 0),
             np.arange(n, dtype=np.int64), np.array([0, n]), 64)
    colours = {tuple(c) for c in exemplars[0].reshape(-1, 3).tolist()}
    assert {tuple(c) for c in volume.reshape(-1, 3).tolist()} <= colours
    # every view's source is a pixel whose colour is a voted texel of that view
    np.testing.assert_array_equal(hist, np.concatenate([np.bincount(s.ravel(), minlength=110) for s in src]))


@pytest.mark.parametrize("medoid", [0, 8])
def test_position_histogram_flattens_a_skewed_usage(medoid):
    """Every neighbourhood matched with the same centre: all voxels get the same w^2 votes. Without
    the position histogram they all copy one texel; with it the usage spreads over the votes --
    over at least half of the 16 with the medoid solver, only to the two texels nearest the mean with the mean
    solver (down-weighting one of 16 votes hardly moves their mean: docs/chen_wang.md)."""
    ex = np.linspace(0, 1, 100, dtype=np.float32).reshape(10, 10, 1)
    m = coh.build_level_model(ex, 4, dims=3, k=2)
    shape = (8, 8, 8)
    assign = np.full((1, *shape), 5 * 10 + 5, dtype=np.int32)
    omega = np.ones((1, *shape), dtype=np.float32)
    n = 512
    order = np.random.default_rng(0).permutation(n).astype(np.int64)
    used = {}
    for weight in (0.0, 50.0):
        src = np.zeros((1, *shape), dtype=np.int32)
        vol = np.zeros((*shape, 1), dtype=np.float32)
        hist = np.bincount(src.ravel(), minlength=100).astype(np.float64)
        texels = m.exemplar.reshape(-1, 1)
        _s.solve(vol, src, assign, omega, _packed([[0, 1]], texels, [0], [10], 4, m.anchor, 1),
                 _histograms(hist, [0], [n / 100.0], weight, 0.0, texels), _s.NO_TRUST, _s.SolverRule(medoid, False, 0, 1.0, 0.0, 0.0, 0),
                 order, np.linspace(0, n, 65).astype(np.int64), 16)
        counts = np.bincount(src.ravel(), minlength=100)
        used[weight] = (int((counts > 0).sum()), int(counts.max()))
    assert used[0.0] == (1, n)  # skewed: one texel everywhere
    if medoid:
        assert used[50.0][0] >= 8  # at least half the 16 voted texels in use
        assert used[50.0][1] <= n // 4
    else:
        assert used[50.0][0] >= 2 and used[50.0][1] <= n // 2


# --------------------------------------------------------------------------- the method


def test_colours_are_exemplar_colours(rng):
    ex = (rng.random((24, 24, 3)) * 255).astype(np.uint8)
    for solver in CW.SOLVERS:
        res = chen_wang_synthesize(ex, size=16, window=(4, 4), levels=2, iterations=2, solver=solver,
                                   rng=0)
        colours = {tuple(c) for c in (ex.reshape(-1, 3) / np.float32(255)).astype(np.float32).tolist()}
        assert {tuple(c) for c in res.volume.reshape(-1, 3).tolist()} <= colours
        assert isinstance(res, SynthesisResult) and isinstance(res.config, ChenWangConfig)
        assert res.volume.dtype == np.float32 and res.volume.shape == (16, 16, 16, 3)


@pytest.mark.parametrize("channels", [1, 2])
def test_any_channel_count_and_views(rng, channels):
    ex = rng.random((20, 20, channels)).astype(np.float32)
    res = chen_wang_synthesize(ex, size=8, window=4, levels=1, iterations=1, views="front,top", rng=1)
    assert res.volume.shape == (8, 8, 8, channels)
    assert res.stats["levels"]["level_0"]["candidates_per_site"] == 54 + 8


def test_an_exemplar_per_view(rng):
    a = np.zeros((20, 20), dtype=np.float32)
    b = np.ones((20, 20), dtype=np.float32)
    res = chen_wang_synthesize(a, exemplars={"right": b}, size=8, window=4, levels=1, iterations=1,
                               views="front,right", rng=0)
    assert set(np.unique(res.volume)) <= {0.0, 1.0}


def test_same_seed_same_volume_at_one_and_two_threads(tmp_path):
    # each thread count in its own process: numba's pool size is fixed at start-up
    script = textwrap.dedent(
        """
        import sys, numba, numpy as np
        from npmrf3d.methods import chen_wang
        assert numba.get_num_threads() == int(sys.argv[2])
        ex = np.random.default_rng(3).random((24, 24, 3)).astype(np.float32)
        from npmrf3d.methods.npmrf_coherent import coherent_synthesize
        vols = [chen_wang.chen_wang_synthesize(ex, size=16, window=(4, 4), levels=2, iterations=2,
                                               solver=solver, rng=7).volume
                for solver in chen_wang.SOLVERS]
        vols.append(coherent_synthesize(ex, size=16, window=(4, 4), levels=2, iterations=(2, 2),
                                        t0=2.0, rng=7).volume)  # annealed: hashed draws
        vols.append(coherent_synthesize(ex, size=16, window=(4, 4), levels=2, iterations=(2, 2),
                                        t0=2.0, sampler="metropolis", rng=7).volume)
        for heuristic in ("ML_H1a", "ML_H1b"):
            vols.append(coherent_synthesize(ex, size=16, window=(4, 4), levels=2, iterations=(2, 2),
                                            heuristic=heuristic, rng=7).volume)
        np.save(sys.argv[1], np.stack(vols))
        """
    )
    volumes = []
    for threads in (1, 2):
        out = tmp_path / f"v{threads}.npy"
        env = {**os.environ, "NUMBA_NUM_THREADS": str(threads)}
        subprocess.run([sys.executable, "-c", script, str(out), str(threads)], check=True, env=env)
        volumes.append(np.load(out))
    np.testing.assert_array_equal(volumes[0], volumes[1])


def _period4_agreement(volume: np.ndarray) -> tuple[float, float]:
    """Share of voxels equal to the voxel 4 (the stripes' period) and 2 (half of it) along j."""
    v = volume[..., 0]
    return float((v == np.roll(v, 4, axis=1)).mean()), float((v == np.roll(v, 2, axis=1)).mean())


#: Stripes of period 4 along the columns; voxels drawn independently from it agree with the voxel
#: 4 and the voxel 2 along j half of the time each (the structureless control).
_STRIPES = np.tile(np.array([0, 0, 1, 1], dtype=np.uint8) * 255, (24, 6))


def test_annealed_coherent_decision_explores_hot_and_settles_cold():
    """Hot (T = 1e4 throughout, draws almost uniform among the candidates) the stripes' period
    breaks up more than at T = 0 (highest score); annealed from hot to cold it is kept. The
    candidates of a periodic exemplar mostly agree, so even uniform draws keep most of the
    period: the means over four seeds are compared, not one run (one seed's margin depends on
    the CPU's rounding)."""
    same4 = {}
    for t0, t_end in ((0.0, 0.05), (1e4, 1e4), (5.0, 0.01)):
        same4[t0] = np.mean([
            _period4_agreement(coherent_synthesize(
                _STRIPES, size=16, window=(4, 4), levels=2, iterations=(3, 3), views="front",
                t0=t0, t_end=t_end, rng=seed).volume)[0]
            for seed in range(4)])
    assert same4[1e4] < same4[0.0] - 0.03
    assert same4[5.0] > 0.9


def test_periodic_exemplar_pattern_appears_in_the_constrained_slices():
    """Mean over three seeds: the period (agreement at 4) is kept and its half (agreement at 2)
    is not, far from the control's 0.5 and 0.5."""
    runs = [chen_wang_synthesize(_STRIPES, size=16, window=(4, 4), levels=2, iterations=3,
                                 views="front", rng=seed).volume for seed in range(3)]
    same4, same2 = np.mean([_period4_agreement(v) for v in runs], axis=0)
    assert same4 > 0.8 and same2 < 0.15
    for v in runs:
        assert 0.3 < v.mean() < 0.7


@pytest.mark.parametrize("count,texels", [(147, 40), (147, 4096), (20, 3), (5, 100)])
@pytest.mark.parametrize("most", [1, 8])
def test_top_votes_match_their_twin(count, texels, most):
    """The candidates: repeated (texel, view)s with tied weights, all distinct, fewer than asked."""
    rng = np.random.default_rng(count + texels)
    vg = rng.integers(0, texels, count).astype(np.int64)
    vv = rng.integers(0, 3, count).astype(np.int64)
    vw = rng.integers(1, 6, count).astype(np.float64)
    tops, keys, bits = np.empty(most, dtype=np.int64), np.empty(count, dtype=np.int64), np.empty(count, dtype=np.int64)
    n = _s._top_votes(vg, vv, vw, count, 3, most, tops, keys, bits)
    np.testing.assert_array_equal(tops[:n], naive_top_votes(vg, vv, vw, most))


@pytest.mark.parametrize("phase_weight,blockwise", [(0.0, {}), (8.0, {}), (8.0, {"blockwise": True, "pilot": 8})])
def test_progress_and_checkpoint_resume(tmp_path, phase_weight, blockwise):
    """With the phase control the checkpoint carries its state, and a block-local run's its
    pilot's histograms: the resumed run is the uninterrupted one."""
    ex = np.random.default_rng(0).random((24, 24)).astype(np.float32)
    calls = []
    path = tmp_path / "cw.npz"
    kw = dict(size=16, window=(4, 4), levels=2, iterations=(2, 1), rng=5, phase_weight=phase_weight, **blockwise)
    res = chen_wang_synthesize(ex, progress=lambda *a: calls.append(a), checkpoint=path, **kw)
    assert [(c[0], c[1], c[2]) for c in calls] == [(1, 0, 2), (1, 1, 2), (1, 2, 2), (0, 0, 1), (0, 1, 1)]
    assert path.exists()
    again = chen_wang_synthesize(ex, checkpoint=path, **kw)  # resumes after the last level
    np.testing.assert_array_equal(again.volume, res.volume)
    # interrupted after the coarse level, then resumed: the uninterrupted result
    coarse = tmp_path / "coarse.npz"

    def stop(level, it, n, energy):
        if level == 0:
            raise _Stop

    with pytest.raises(_Stop):
        chen_wang_synthesize(ex, progress=stop, checkpoint=coarse, **kw)
    resumed = chen_wang_synthesize(ex, checkpoint=coarse, **kw)
    np.testing.assert_array_equal(resumed.volume, res.volume)
    assert resumed.history == res.history
    with pytest.raises(ParameterError, match="different configuration"):
        chen_wang_synthesize(ex, checkpoint=path, **{**kw, "iterations": 3})


class _Stop(Exception):
    pass


@pytest.mark.parametrize("kwargs,match", [
    ({"window": (8, 8, 6), "size": 16}, "too small for window 8 at level 2"),
    ({"iterations": (1, 2)}, "iterations must be one integer or 3 integers"),
    ({"solver": "mode"}, "solver must be one of mean, medoid; got 'mode'"),
    ({"size": 30}, "not divisible by 2\\*\\*\\(levels-1\\) = 4"),
    ({"grid": 3, "window": 4, "size": 16}, "not a multiple of 3"),
    ({"views": "front,side"}, "view must be one of front, right, top; got 'side'"),
    ({"k": 0}, "k must be between 1 and 64; got 0"),
    ({"position_weight": -1}, "position_weight must be a finite number in \\[0.0, inf\\); got -1"),
    ({"rng": -3}, "seed must be >= 0; got -3"),
])
def test_bad_input_raises_parameter_error(kwargs, match):
    ex = np.zeros((64, 64), dtype=np.float32)
    base = {"size": 32, "window": 4, "levels": 3, "iterations": 1}
    with pytest.raises(ParameterError, match=match):
        chen_wang_synthesize(ex, **{**base, **kwargs})


def test_exemplar_too_small_for_a_level_window():
    with pytest.raises(ParameterError, match="exemplar of size 16x16 is too small for window 8"):
        chen_wang_synthesize(np.zeros((16, 16)), size=32, window=(3, 8, 4), levels=3, iterations=1)
    with pytest.raises(ParameterError, match="same number of channels"):
        chen_wang_synthesize(np.zeros((32, 32)), exemplars={"top": np.zeros((32, 32, 3))}, size=16,
                             window=4, levels=1, iterations=1)


@pytest.mark.kernels
def test_solve_does_not_depend_on_the_order_within_a_batch(rng):
    """The run visits each batch in memory order (faster); only the batches' order matters."""
    views = VIEWS3
    exemplars, models, assign, omega, src, volume = _solve_case(rng, views, 4, 3, 1)
    packed, ex_off, hist_off = pack_exemplars(models)
    n = volume.shape[0] * volume.shape[1] * volume.shape[2]
    order = rng.permutation(n).astype(np.int64)
    bounds = np.array([0, 60, 130, n], dtype=np.int64)
    out = []
    for shuffle in (False, True):
        o = order.copy()
        for b in range(3):
            seg = o[bounds[b]:bounds[b + 1]]
            seg[:] = rng.permutation(seg) if shuffle else np.sort(seg)
        vol, s = volume.copy(), src.copy()
        hist = np.concatenate([np.bincount(x.ravel(), minlength=110) for x in src]).astype(np.float64)
        _s.solve(vol, s, assign, omega, _packed([VIEW_AXES[v] for v in views], packed, ex_off, [10] * 3, 4, 1, 1),
                 _histograms(hist, hist_off, [n / 110] * 3, 3.0, 4.0, packed), _s.NO_TRUST, _s.SolverRule(8, False, 0, 1.0, 0.0, 0.0, 0),
                 o, bounds, 16)
        out.append((vol, s, hist))
    for a, b in zip(*out):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("heuristic", ["ML_H1a", "ML_H1b"])
def test_coherent_per_view_heuristics_refuse_annealing(heuristic):
    with pytest.raises(ParameterError, match=f"heuristic {heuristic} cannot be annealed .* ICM-only per-view argmax"):
        make_coherent_config(size=16, levels=2, window=4, heuristic=heuristic, t0=1.0)
    assert make_coherent_config(size=16, levels=2, window=4, heuristic=heuristic).heuristic == heuristic


def test_coherent_sampler_is_validated_and_in_the_checkpoint_key():
    with pytest.raises(ParameterError, match="sampler must be one of heat-bath, metropolis; got 'gibbs'"):
        make_coherent_config(size=16, levels=2, window=4, sampler="gibbs")
    assert make_coherent_config(size=16, levels=2, window=4).sampler == "heat-bath"
    ex = np.random.default_rng(0).random((24, 24, 1)).astype(np.float32)
    keys = {KCoherenceLevels("coherent", _chen_wang_config(make_coherent_config(size=16, levels=2, window=4)),
                             {v: ex for v in VIEWS3}, CandidateDecision("ML_H2b", 0.1, 0.01, None, sampler)).key
            for sampler in ("heat-bath", "metropolis")}
    assert len(keys) == 2


def test_ml_h1b_averages_the_views_picks_into_new_colours():
    """ML_H1b's mean of the views' picks makes colours the exemplar lacks (Urs et al. 2014's
    averaging artefact); ML_H1a, like ML_H2b, copies exemplar colours only."""
    ex = np.random.default_rng(5).random((24, 24, 3)).astype(np.float32)
    colours = {tuple(c) for c in ex.reshape(-1, 3)}
    for heuristic, only_exemplar in (("ML_H1a", True), ("ML_H1b", False)):
        vol = coherent_synthesize(ex, size=16, window=(4, 4), levels=2, iterations=(2, 2), heuristic=heuristic,
                                  rng=1).volume
        new = sum(tuple(c) not in colours for c in vol.reshape(-1, 3))
        assert (new == 0) == only_exemplar


@pytest.mark.kernels
def test_division_free_index_helpers_match_python(rng):
    """The search's quotient without an integer division and its toroidal wrap, against Python's
    divmod and %."""
    for b in (1, 2, 3, 7, 61, 64, 1000, 4093):
        for a in np.concatenate([np.arange(0, 3 * b + 2), rng.integers(0, 2**31, size=500)]):
            assert _k.split(int(a), b, 1.0 / b) == divmod(int(a), b)
    for n in (1, 5, 64):
        for i in range(-2 * n - 1, 2 * n + 2):
            assert _k.wrap(i, n) == i % n
