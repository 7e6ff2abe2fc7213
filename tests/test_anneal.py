"""Simulated annealing (docs/model.md, section 5): Metropolis rule, heat-bath draws, the class update
against a literal per-site loop, schedules, colour and view behaviour, usage errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import npmrf3d
from npmrf3d._kernels.gemm import rows_log_lcpdfs
from npmrf3d._kernels.parzen import LcpdfOptions
from npmrf3d._kernels.relax import (
    AnnealRule,
    IcmRule,
    LevelArrays,
    anneal_update_class,
    icm_update_class,
    metropolis_accept,
    sample_index,
)
from npmrf3d.config import PRESETS
from npmrf3d.errors import ParameterError
from npmrf3d.model import parzen
from npmrf3d.model.exemplar import make_labels
from npmrf3d.model.heuristics import get_heuristic
from npmrf3d.model.neighbourhood import colour_classes
from npmrf3d.model.parzen import PRUNE, adaptive_floor, build_view_models
from npmrf3d.model.relax.anneal import geometric_schedule, linear_schedule, relax_anneal
from tests import naive

VIEWS3 = ("front", "right", "top")


# --------------------------------------------------------------------------- Metropolis rule


@pytest.mark.kernels
@pytest.mark.parametrize("temperature", [0.0, 1e-6, 0.5, 1e9])
@pytest.mark.parametrize("delta", [0.0, 1e-12, 3.0])
def test_a_proposal_that_does_not_lower_the_objective_is_always_accepted(delta, temperature):
    for u in (0.0, 0.5, np.nextafter(1.0, 0.0)):
        assert metropolis_accept(delta, temperature, u)


@pytest.mark.kernels
@pytest.mark.parametrize("delta", [-1e-9, -0.5, -50.0])
def test_at_zero_temperature_a_worse_value_is_never_accepted(delta):
    for u in (0.0, 1e-300, 0.5):
        assert not metropolis_accept(delta, 0.0, u)
        assert not metropolis_accept(delta, -1.0, u)


def test_acceptance_rate_is_exp_delta_over_t_and_near_one_when_hot():
    u = np.random.default_rng(0).random(20000)
    for delta, temperature in ((-1.0, 1.0), (-2.0, 0.5), (-0.3, 3.0)):
        rate = np.mean([metropolis_accept(delta, temperature, x) for x in u])
        assert abs(rate - np.exp(delta / temperature)) < 0.015
    hot = np.mean([metropolis_accept(-5.0, 1e6, x) for x in u])
    assert hot > 0.999
    cold = np.mean([metropolis_accept(-5.0, 1e-3, x) for x in u])
    assert cold == 0.0


# --------------------------------------------------------------------------- heat-bath draw


@pytest.mark.kernels
def test_heat_bath_draw_matches_the_normalised_distribution():
    rng = np.random.default_rng(1)
    score = rng.normal(0.0, 2.0, size=6)
    temperature = 1.5
    expected = naive.naive_sample_probabilities(score, temperature)
    n = 40000
    draws = np.array([sample_index(score.copy(), temperature, u) for u in rng.random(n)])
    observed = np.bincount(draws, minlength=len(score))
    assert stats.chisquare(observed, expected * n).pvalue > 1e-3
    # exact: the index is the first whose cumulative probability exceeds u
    for u in np.linspace(0.0, 0.999, 37):
        assert sample_index(score.copy(), temperature, u) == int(
            np.searchsorted(np.cumsum(expected), u, side="right"))


@pytest.mark.kernels
def test_heat_bath_at_zero_temperature_is_the_argmax():
    score = np.array([0.1, 3.0, -2.0, 3.0 - 1e-9])
    assert sample_index(score.copy(), 0.0, 0.99) == 1


# --------------------------------------------------------------------------- schedules


def test_schedules_run_from_t0_to_t_end():
    g = geometric_schedule(2.0, 0.02, 5)
    assert g[0] == pytest.approx(2.0) and g[-1] == pytest.approx(0.02)
    assert np.allclose(g[1:] / g[:-1], g[1] / g[0])  # constant ratio
    lin = linear_schedule(2.0, 0.0, 5)
    assert np.allclose(np.diff(lin), -0.5)
    assert geometric_schedule(1.0, 0.1, 1).tolist() == [0.1]


# --------------------------------------------------------------------------- class update


def _tiny_level(channels, heuristic="ML_H2b", shape=(8, 8, 8), window=3, seed=0):
    rng = np.random.default_rng(seed)
    palette = rng.integers(0, 6, size=(5, channels)) / 5
    exemplar = palette[rng.integers(0, 5, size=(10, 12))].astype(np.float32)
    labels, (image,) = make_labels([exemplar], rng=rng)
    freq = np.bincount(image.ravel(), minlength=len(labels)) / image.size
    rule = PRESETS["tuned"]
    models, info = build_view_models({v: image for v in VIEWS3}, labels, window=window,
                                     level=0, rule=rule)
    lab = rng.integers(0, len(labels), size=shape).astype(np.int32)
    volume = np.ascontiguousarray(labels[lab], dtype=np.float32)
    return rng, labels, freq, rule, models, info, lab, volume


@pytest.mark.kernels
@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("sampler", ["metropolis", "heat-bath"])
@pytest.mark.parametrize("heuristic", ["ML_H2a", "ML_H2b"])
def test_anneal_class_update_equals_a_literal_per_site_loop(channels, sampler, heuristic):
    rng, labels, freq, rule, models, info, lab, volume = _tiny_level(channels, heuristic)
    shape = lab.shape
    temps = np.zeros(shape, dtype=np.float32)
    inherited = np.zeros(shape, dtype=bool)
    sites = colour_classes(shape, 3)[0]
    k = len(labels)
    candidates = rng.integers(0, k, size=len(sites)).astype(np.int64)
    uniforms = rng.random(len(sites))
    penalty = rng.normal(0.0, 0.5, size=k)
    temperature = 0.7
    code = get_heuristic(heuristic).code
    # the literal reference, from the volume before the update (class sites never interact)
    expected = []
    for q, site in enumerate(sites):
        log_l = parzen.log_lcpdf(volume, temps, tuple(site), models, outlier=rule.outlier)
        combine = np.min if heuristic == "ML_H2a" else np.sum
        score = combine(log_l, axis=0) + penalty
        current = int(lab[tuple(site)])
        if sampler == "heat-bath":
            p = naive.naive_sample_probabilities(score, temperature)
            expected.append(int(np.searchsorted(np.cumsum(p), uniforms[q], side="right")))
        else:
            delta = score[candidates[q]] - score[current]
            accept = delta >= 0 or uniforms[q] < np.exp(delta / temperature)
            expected.append(int(candidates[q]) if accept else current)
    old = np.empty(len(sites), dtype=np.int64)
    new = np.empty(len(sites), dtype=np.int64)
    before = lab.copy()
    anneal_update_class.parallel(
        LevelArrays(volume, lab, temps, inherited), sites,
        candidates if sampler == "metropolis" else None, uniforms, models, None,
        LcpdfOptions(rule.adaptive, adaptive_floor(info), PRUNE, rule.outlier),
        AnnealRule(code, temperature, True, penalty), old, new)
    np.testing.assert_array_equal(new, expected)
    np.testing.assert_array_equal(old, before[tuple(sites.T)])
    np.testing.assert_array_equal(lab[tuple(sites.T)], expected)
    np.testing.assert_array_equal(volume[tuple(sites.T)], labels[expected])
    others = np.ones(shape, dtype=bool)
    others[tuple(sites.T)] = False
    np.testing.assert_array_equal(lab[others], before[others])


@pytest.mark.kernels
@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("outlier", [0.0, 0.01])
def test_lcpdf_at_two_labels_equals_the_full_lcpdf(channels, outlier):
    """Metropolis evaluates only the current and the proposed label (log domain, no table)."""
    rng, labels, freq, rule, models, info, lab, volume = _tiny_level(channels, seed=channels)
    temps = rng.random(lab.shape).astype(np.float32) * 0.5
    for _ in range(5):
        site = tuple(int(x) for x in rng.integers(0, 8, size=3))
        full = parzen.log_lcpdf(volume, temps, site, models, outlier=outlier)
        query = rng.integers(0, len(labels), size=2).astype(np.int64)
        out = np.empty((1, 3, 2))
        rows_log_lcpdfs(volume, temps, np.array([site], dtype=np.int64), np.zeros(1, np.int64),
                        models, None, LcpdfOptions(0.0, 0.0, PRUNE, outlier), query[None], out)
        np.testing.assert_allclose(out[0], full[:, query], rtol=1e-9, atol=1e-9)


@pytest.mark.kernels
@pytest.mark.parametrize("sampler", ["metropolis", "heat-bath"])
def test_small_class_serial_kernels_equal_the_parallel_ones(sampler):
    """Classes below PARALLEL_MIN_SITES run serially: the same code, the same result."""
    rng, labels, freq, rule, models, info, lab, volume = _tiny_level(3)
    sites = colour_classes(lab.shape, 3)[2]
    k = len(labels)
    candidates = rng.integers(0, k, size=len(sites)).astype(np.int64)
    uniforms = rng.random(len(sites))
    penalty = rng.normal(0.0, 0.3, size=k)
    temps = rng.random(lab.shape).astype(np.float32)
    inherited = rng.random(lab.shape) < 0.3
    code = get_heuristic("ML_H2b").code
    lcpdf = LcpdfOptions(rule.adaptive, adaptive_floor(info), PRUNE, rule.outlier)
    results = []
    for kernel in anneal_update_class:
        v, lb, old, new = volume.copy(), lab.copy(), np.empty(len(sites), np.int64), np.empty(len(sites), np.int64)
        kernel(LevelArrays(v, lb, np.zeros_like(temps), inherited), sites,
               candidates if sampler == "metropolis" else None, uniforms, models, None, lcpdf,
               AnnealRule(code, 0.5, False, penalty), old, new)
        results.append((v, lb, old, new))
    for kernel in icm_update_class:
        v, lb, t = volume.copy(), lab.copy(), temps.copy()
        old, new = np.empty(len(sites), np.int64), np.empty(len(sites), np.int64)
        kernel(LevelArrays(v, lb, t, inherited), sites, uniforms, models, None, lcpdf,
               IcmRule(code, 1, 0.2, -3.0, True, penalty), old, new)
        results.append((v, lb, t, old, new))
    for a, b in ((0, 1), (2, 3)):
        for x, y in zip(results[a], results[b]):
            np.testing.assert_array_equal(x, y)


@pytest.mark.kernels
def test_greedy_at_zero_temperature_never_lowers_a_site_objective():
    rng, labels, freq, rule, models, info, lab, volume = _tiny_level(1)
    temps = np.zeros(lab.shape, dtype=np.float32)
    sites = colour_classes(lab.shape, 3)[1]
    candidates = rng.integers(0, len(labels), size=len(sites)).astype(np.int64)
    penalty = np.zeros(len(labels))

    def objective(lab_now, vol_now):
        return np.array([np.sum(parzen.log_lcpdf(vol_now, temps, tuple(s), models,
                                                 outlier=rule.outlier), axis=0)[lab_now[tuple(s)]]
                         for s in sites])

    before = objective(lab, volume)
    old = np.empty(len(sites), dtype=np.int64)
    new = np.empty(len(sites), dtype=np.int64)
    anneal_update_class.parallel(
        LevelArrays(volume, lab, temps, np.zeros(lab.shape, dtype=bool)), sites, candidates,
        np.zeros(len(sites)), models, None,
        LcpdfOptions(rule.adaptive, adaptive_floor(info), PRUNE, rule.outlier),
        AnnealRule(get_heuristic("ML_H2b").code, 0.0, True, penalty), old, new)
    after = objective(lab, volume)
    assert (after >= before - 1e-9).all()
    assert (old != new).any()  # some proposals were improvements and were taken


def test_relax_anneal_fixed_keeps_inherited_voxels_and_reports_acceptance():
    rng, labels, freq, rule, models, info, lab, volume = _tiny_level(1)
    temps = np.ones(lab.shape, dtype=np.float32)
    inherited = np.zeros(lab.shape, dtype=bool)
    inherited[::2, ::2, ::2] = True
    kept = volume[inherited].copy()
    history, st = relax_anneal(
        volume, lab, temps, inherited, models, colour_classes(lab.shape, 3),
        heuristic=get_heuristic("ML_H2b").code, sampler="metropolis", schedule="geometric",
        t0=1.0, t_end=0.1, proposals=3, proposal="exemplar", resynth=False,
        adaptive=rule.adaptive, min_two_h2=adaptive_floor(info), prune=PRUNE,
        histogram_weight=rule.histogram_weight, outlier=rule.outlier, exemplar_freq=freq, rng=rng)
    np.testing.assert_array_equal(volume[inherited], kept)
    assert (temps == 0).all()  # annealing trusts every neighbour
    assert history == pytest.approx([1.0, 1.0, 0.1 ** 0.5, 0.1])
    assert st["sweeps"] == 3 and st["updates"] == 3 * int((~inherited).sum())
    assert len(st["acceptance"]) == 3 and all(0.0 < a < 1.0 for a in st["acceptance"])


# --------------------------------------------------------------------------- whole runs


def stripes_rgb(period: int = 4, side: int = 24, diagonal: bool = False) -> np.ndarray:
    """Two-colour stripes (red / blue), ``period`` pixels per repeat, along the columns
    (``E[a, b] = s(b)``) or diagonal (``E[a, b] = s(a + b)``).

    Vertical stripes cannot hold in three orthogonal views at once (front wants variation
    along j, right wants none along j); diagonal ones can: ``v[i, j, k] = s(i + j + k)`` shows
    ``s(a + b)`` in every view.
    """
    a, b = np.indices((side, side))
    phase = (a + b) if diagonal else b
    colours = np.array([[220, 40, 40], [30, 60, 200]], dtype=np.uint8)
    return colours[(phase // (period // 2)) % 2]


def stripe_correlation(volume: np.ndarray, view: str, axis_in_slice: int, lag: int) -> float:
    """Correlation at ``lag`` along one in-slice axis of the view's slices (channel 0)."""
    from npmrf3d.analysis.metrics import view_slices

    s = view_slices(volume[..., :1], view)[..., 0].astype(np.float64)
    s = s - s.mean()
    shifted = np.roll(s, lag, axis=1 + axis_in_slice)
    return float((s * shifted).mean() / max((s * s).mean(), 1e-12))


@pytest.mark.parametrize("sampler", ["metropolis", "heat-bath"])
def test_colour_stripes_period_appears_in_constrained_views(sampler):
    res = npmrf3d.synthesize(stripes_rgb(diagonal=True), size=16, window=5, levels=2, relaxation="anneal", support="full",
                             sampler=sampler, proposals=6, rng=0)
    assert res.volume.shape == (16, 16, 16, 3)
    assert res.config.upsample == "8/8"  # the paper's default for annealing
    for view in VIEWS3:  # s(a + b): anti-correlated at lag 2, correlated at lag 4 on either axis
        assert stripe_correlation(res.volume, view, 1, 4) > 0.5, view
        assert stripe_correlation(res.volume, view, 1, 2) < -0.3, view


def test_with_two_views_the_unconstrained_view_is_free():
    """A layered texture (the paper's two-view case): horizontal stripes (varying along the
    slice's first axis, i in both views) constrain front (slices (i, j)) and top (slices
    (i, k)); a volume of layers ``s(i)`` satisfies both. The right view (slices (j, k), no
    i in them) is free: it shows flat layers, nothing like the exemplar's stripes."""
    horizontal = stripes_rgb().transpose(1, 0, 2)
    res = npmrf3d.synthesize(horizontal, size=16, window=5, levels=2, relaxation="anneal", support="full",
                             sampler="heat-bath", views="front,top", proposals=6, rng=1)
    for view in ("front", "top"):
        assert stripe_correlation(res.volume, view, 0, 4) > 0.5, view
        assert stripe_correlation(res.volume, view, 0, 2) < -0.3, view
    right = metrics_view(res.volume, "right")
    assert stripe_correlation(res.volume, "right", 0, 2) > 0.5  # no stripes in the free view
    assert stripe_correlation(res.volume, "right", 1, 2) > 0.5
    assert right.std(axis=(1, 2)).mean() < 0.5 * right.std()  # slices nearly flat, layers differ


def metrics_view(volume, view):
    from npmrf3d.analysis.metrics import view_slices

    return view_slices(volume[..., :1], view)[..., 0]


@pytest.mark.parametrize("channels", [2, 4])
def test_multichannel_anneal_runs_and_keeps_exemplar_values(channels):
    rng = np.random.default_rng(channels)
    base = stripes_rgb().astype(np.float32) / 255
    extra = [base[..., :1] * 0.5 + 0.1] if channels == 4 else []
    exemplar = np.concatenate([base, *extra], axis=2)[..., :channels]
    res = npmrf3d.synthesize(exemplar, size=8, window=3, levels=1, relaxation="anneal", support="full",
                             proposals=2, rng=rng)
    assert res.volume.shape == (8, 8, 8, channels)
    values = {tuple(v) for v in res.volume.reshape(-1, channels).tolist()}
    allowed = {tuple(v) for v in exemplar.reshape(-1, channels).tolist()}
    assert values <= allowed


def test_anneal_is_deterministic_for_a_seed():
    kw = dict(size=8, window=3, levels=2, relaxation="anneal", support="full", proposals=2, sampler="heat-bath")
    a = npmrf3d.synthesize(stripes_rgb(), rng=5, **kw).volume
    b = npmrf3d.synthesize(stripes_rgb(), rng=5, **kw).volume
    np.testing.assert_array_equal(a, b)


# --------------------------------------------------------------------------- usage errors


@pytest.mark.parametrize("heuristic", ["ML_H1a", "ML_H1b"])
def test_annealing_with_an_objective_free_heuristic_is_a_usage_error(heuristic):
    with pytest.raises(ParameterError, match=rf"{heuristic} cannot drive annealing.*ML_H2a or ML_H2b"):
        npmrf3d.synthesize(stripes_rgb(), size=8, levels=1, window=3, relaxation="anneal", support="full",
                           heuristic=heuristic)


@pytest.mark.parametrize(("kwargs", "message"), [
    (dict(t0=0.0), "t0 must be"),
    (dict(t0=1.0, t_end=2.0), "t_end must be"),
    (dict(t_end=0.0), "t_end must be"),
    (dict(proposals=0), "proposals must be"),
    (dict(sampler="gibbs"), "sampler must be one of"),
    (dict(schedule="cosine"), "schedule must be one of"),
    (dict(proposal="uniform"), "proposal must be one of"),
])
def test_bad_annealing_parameters(kwargs, message):
    with pytest.raises(ParameterError, match=message):
        npmrf3d.synthesize(stripes_rgb(), size=8, levels=1, window=3, relaxation="anneal", support="full", **kwargs)


def test_linear_schedule_may_end_at_zero():
    res = npmrf3d.synthesize(stripes_rgb(), size=8, levels=1, window=3, relaxation="anneal", support="full",
                             schedule="linear", t_end=0.0, proposals=2, rng=0)
    assert res.history[0][-1] == 0.0
