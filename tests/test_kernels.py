"""The compiled Parzen kernels against their naive twins (docs/model.md, section 2).

``npmrf3d.model.parzen.log_lcpdf`` (label-histogram identity, kernel tables, pruning, float32
distances) is compared with ``tests.naive.naive_log_lcpdf`` (every patch and label in float64,
straight from docs/model.md, section 2) on tiny random inputs.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from npmrf3d._kernels.parzen import label_kernel_table, label_log_norm_const
from npmrf3d.config import DecisionRule
from npmrf3d.model import parzen
from npmrf3d.model.exemplar import decimation_phases, make_labels
from tests import naive

pytestmark = pytest.mark.kernels

VIEWS3 = ("front", "right", "top")
#: Largest neighbour-exponent spread for which ``prune=np.inf`` is safe: beyond ~745 a patch
#: weight underflows to 0.0 and the kernel corrupts its ``nonzero`` buffer (see
#: ``test_prune_inf_survives_underflowing_weights``). The exact comparisons stay below it.
SAFE_SPREAD = 700.0
#: Probabilities above this are compared in the log domain with a relative tolerance.
P_MIN = 1e-12
RTOL, ATOL = 1e-4, 1e-6


# --------------------------------------------------------------------------- helpers


def tiny_exemplar(rng, channels: int, *, size=None, n_values: int = 6) -> np.ndarray:
    """A 9..12 square-ish exemplar with few distinct values (so the label set is small)."""
    h, w = size if size is not None else rng.integers(9, 13, size=2)
    if channels == 1:
        return (rng.integers(0, n_values, size=(h, w, 1)) / (n_values - 1)).astype(np.float32)
    palette = rng.integers(0, 6, size=(n_values, channels)) / 5
    return palette[rng.integers(0, n_values, size=(h, w))].astype(np.float32)


def make_case(rng, *, channels, window, views, distinct_exemplars, rule=None, level=0,
              constant=False, exemplars=None):
    """Exemplars, labels, models and the naive per-view patches of one random case."""
    n_ex = len(views) if distinct_exemplars else 1
    if constant:
        exemplars = [np.full((10, 11, channels), 0.4, dtype=np.float32)]
    elif exemplars is None:
        exemplars = [tiny_exemplar(rng, channels) for _ in range(n_ex)]
    labels, images = make_labels(exemplars, rng=rng)
    label_images = {v: images[a % len(images)] for a, v in enumerate(views)}
    rule = rule or DecisionRule()
    models, info = parzen.build_view_models(label_images, labels, window=window, level=level,
                                            rule=rule)
    ref = {}
    for v in views:
        parts = [naive.naive_extract_patches(ph, labels, window)
                 for ph in decimation_phases(label_images[v], level) if min(ph.shape) >= window]
        patches = np.concatenate([p for p, _ in parts])
        centres = np.concatenate([c for _, c in parts])
        sigma = naive.naive_sigma(labels[label_images[v]])
        sigma = 1.0 if sigma == 0.0 else sigma  # documented choice of build_view_models
        hopt = naive.naive_h_opt(sigma, len(centres), channels * window * window)
        ref[v] = {"patches": patches, "centres": centres, "h_opt": hopt,
                  "h": rule.bandwidth * hopt, "h_centre": rule.centre_bandwidth * hopt,
                  "offsets": naive.naive_view_offsets(v, window)}
    return labels, label_images, models, info, ref


def random_volume(rng, labels, shape, temps_mode):
    volume = labels[rng.integers(0, len(labels), size=shape)]
    if temps_mode == "zeros":
        temps = np.zeros(shape, dtype=np.float32)
    elif temps_mode == "ones":
        temps = np.ones(shape, dtype=np.float32)
    else:
        temps = rng.random(shape).astype(np.float32)
    site = tuple(int(rng.integers(0, n)) for n in shape)
    return volume, temps, site


def naive_for(views, ref, volume, temps, site, labels, *, adaptive=0.0, min_two_h2=0.0):
    """(V, K) naive log-LCPDFs and the largest neighbour-exponent spread over the views."""
    rows, spread = [], 0.0
    for v in views:
        r = ref[v]
        dist = naive.naive_neighbour_distances(volume, temps, site, r["offsets"], r["patches"])
        two_h2 = 2.0 * r["h"] ** 2
        if adaptive > 0.0:
            two_h2 = max(adaptive * dist.min(), min_two_h2)
        spread = max(spread, (dist.max() - dist.min()) / two_h2)
        rows.append(naive.naive_log_lcpdf(volume, temps, site, r["offsets"], r["patches"],
                                          r["centres"], labels, r["h"], r["h_centre"],
                                          neighbour_two_h2=two_h2))
    return np.array(rows), spread


def exact_log_lcpdf(volume, temps, site, models, spread, **kw):
    """``log_lcpdf`` with ``prune=np.inf`` once the inputs are known to be in its safe range."""
    assert spread < SAFE_SPREAD, "test inputs would hit the prune=inf underflow bug"
    return parzen.log_lcpdf(volume, temps, site, models, prune=np.inf, **kw)


def assert_matches(lib, ref, *, p_min=P_MIN):
    """Same shape; probabilities above ``p_min`` agree in log with rtol; rows sum to 1."""
    assert lib.shape == ref.shape
    assert np.isfinite(lib).all()
    np.testing.assert_allclose(np.exp(lib).sum(axis=1), 1.0, rtol=1e-9)
    mask = ref > np.log(p_min)
    assert mask.any()
    np.testing.assert_allclose(lib[mask], ref[mask], rtol=RTOL, atol=ATOL)
    # tiny probabilities stay tiny
    assert (lib[~mask] < np.log(p_min) + 1.0).all()


def assert_same_mode(got, expected):
    """The kernel's most probable label is a most probable label of the naive twin (labels
    whose probabilities tie within float32 rounding may be ordered either way)."""
    rows = np.arange(len(got))
    np.testing.assert_allclose(expected[rows, got.argmax(axis=1)], expected.max(axis=1),
                               rtol=RTOL, atol=ATOL)


def assert_table_close(table, expected):
    """Kernel tables agree in the exponent: the kernel squares float32 label differences, so
    ``log`` of an entry carries a float32 relative error (not float64)."""
    assert table.shape == expected.shape
    live = expected > 1e-290
    np.testing.assert_allclose(np.log(table[live]), np.log(expected[live]), rtol=1e-6, atol=1e-7)
    assert (table[~live] < 1e-280).all()
    np.testing.assert_array_equal(np.diag(table), 1.0)


@pytest.fixture(scope="session")
def compiled():
    """Compile (or load from numba's cache) every kernel these tests call, once per session."""
    rng = np.random.default_rng(12345)
    labels, _, models, _, _ = make_case(rng, channels=1, window=3, views=("front",),
                                        distinct_exemplars=False)
    volume, temps, site = random_volume(rng, labels, (6, 6, 6), "random")
    out = parzen.log_lcpdf(volume, temps, site, models)
    assert np.isfinite(out).all()
    return True


# --------------------------------------------------------------------------- small kernels


@pytest.mark.parametrize(("sigma", "n", "d"), [(1.0, 3364, 49), (0.3, 64, 9), (0.25, 4, 75),
                                                (2.0, 100000, 27)])
def test_h_opt_formula(sigma, n, d):
    assert parzen.h_opt(sigma, n, d) == pytest.approx(naive.naive_h_opt(sigma, n, d), rel=1e-12)
    assert parzen.h_opt(sigma, n, d) == pytest.approx(sigma * (4 / (n * (d + 2))) ** (1 / (d + 4)),
                                                      rel=1e-12)


def test_h_opt_decreases_with_samples():
    assert parzen.h_opt(1.0, 100, 9) > parzen.h_opt(1.0, 1000, 9) > parzen.h_opt(1.0, 10000, 9)


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("inv_two_hc2", [0.1, 5.0, 1e6])
def test_label_log_norm_const_and_kernel_table(compiled, channels, inv_two_hc2):
    rng = np.random.default_rng(channels)
    labels = (rng.integers(0, 6, size=(7, channels)) / 5).astype(np.float32)
    labels = np.unique(labels, axis=0)
    np.testing.assert_allclose(label_log_norm_const(labels, inv_two_hc2),
                               naive.naive_label_log_norm_const(labels, inv_two_hc2), rtol=1e-6,
                               atol=1e-9)
    table = label_kernel_table(labels, inv_two_hc2)
    assert_table_close(table, naive.naive_label_kernel_table(labels, inv_two_hc2))
    np.testing.assert_array_equal(np.diag(table), 1.0)
    np.testing.assert_allclose(table, table.T)


@pytest.mark.parametrize("channels", [1, 3])
@pytest.mark.parametrize("window", [3, 5])
def test_build_view_models_matches_naive(compiled, channels, window):
    rng = np.random.default_rng(10 * channels + window)
    rule = DecisionRule(bandwidth=0.7, centre_bandwidth=0.3)
    labels, label_images, models, info, ref = make_case(
        rng, channels=channels, window=window, views=VIEWS3, distinct_exemplars=True, rule=rule)
    d = channels * window * window
    for a, v in enumerate(VIEWS3):
        r = ref[v]
        h, w = label_images[v].shape
        n = (h - window + 1) * (w - window + 1)
        assert info[v]["n"] == n == len(r["centres"]) == models.n_patches[a]
        assert info[v]["d"] == d
        assert info[v]["h_opt"] == pytest.approx(r["h_opt"], rel=1e-9)
        assert info[v]["h"] == pytest.approx(r["h"], rel=1e-9)
        assert info[v]["h_centre"] == pytest.approx(r["h_centre"], rel=1e-9)
        assert models.inv_two_h2[a] == pytest.approx(1 / (2 * r["h"] ** 2), rel=1e-9)
        assert models.inv_two_hc2[a] == pytest.approx(1 / (2 * r["h_centre"] ** 2), rel=1e-9)
        np.testing.assert_array_equal(models.offsets[a], r["offsets"])
        # the patches are kept grouped by centre label (stable: raster order within a label)
        order = np.argsort(r["centres"], kind="stable")
        patches = models.patches_t[a, :, :n].T.reshape(n, window * window - 1, channels)
        np.testing.assert_array_equal(patches, r["patches"][order])
        np.testing.assert_array_equal(models.centre_labels[a, :n], r["centres"][order])
        starts = models.label_starts[a]
        assert starts[0] == 0 and starts[-1] == n and len(starts) == len(labels) + 1
        for j in range(len(labels)):
            assert (models.centre_labels[a, starts[j]:starts[j + 1]] == j).all()
        np.testing.assert_allclose(models.log_norm_const[a], naive.naive_label_log_norm_const(
            labels, 1 / (2 * r["h_centre"] ** 2)), rtol=1e-6, atol=1e-9)
        assert_table_close(models.kernel_tables[a],
                           naive.naive_label_kernel_table(labels, 1 / (2 * r["h_centre"] ** 2)))
    assert {tuple(o) for o in models.union_offsets} == naive.naive_union_offsets(VIEWS3, window)


# --------------------------------------------------------------------------- log_lcpdf


@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("window", [3, 5])
@pytest.mark.parametrize("temps_mode", ["zeros", "ones", "random"])
@pytest.mark.parametrize(("views", "distinct"), [(("front",), False), (VIEWS3, False),
                                                 (VIEWS3, True)])
def test_log_lcpdf_matches_naive(compiled, channels, window, temps_mode, views, distinct):
    seed = [channels, window, len(temps_mode), len(views), int(distinct)]
    rng = np.random.default_rng(seed)
    labels, _, models, _, ref = make_case(rng, channels=channels, window=window, views=views,
                                          distinct_exemplars=distinct)
    shape = tuple(int(x) for x in rng.integers(6, 9, size=3))
    for _ in range(3):
        volume, temps, site = random_volume(rng, labels, shape, temps_mode)
        expected, spread = naive_for(views, ref, volume, temps, site, labels)
        got = exact_log_lcpdf(volume, temps, site, models, spread)
        assert_matches(got, expected)


def test_all_hot_neighbourhood_is_smoothed_label_histogram(compiled):
    """With every t_r = 1 the neighbour term vanishes: L is the Gaussian-smoothed histogram of
    the patch centres (docs/model.md, section 2), whatever the neighbour values."""
    rng = np.random.default_rng(7)
    labels, _, models, _, ref = make_case(rng, channels=1, window=3, views=("front",),
                                          distinct_exemplars=False)
    volume, temps, site = random_volume(rng, labels, (6, 7, 8), "ones")
    got = parzen.log_lcpdf(volume, temps, site, models, prune=np.inf)[0]
    r = ref["front"]
    hist = np.bincount(r["centres"], minlength=len(labels)).astype(float)
    lab = labels[:, 0].astype(np.float64)
    kern = np.exp(-((lab[:, None] - lab[None, :]) ** 2) / (2 * r["h_centre"] ** 2))
    f = kern @ hist
    np.testing.assert_allclose(got, np.log(f / f.sum()), rtol=1e-6, atol=1e-7)
    other = random_volume(rng, labels, (6, 7, 8), "ones")[0]
    np.testing.assert_allclose(parzen.log_lcpdf(other, temps, site, models)[0], got, rtol=1e-12)


def test_constant_exemplar(compiled):
    rng = np.random.default_rng(3)
    labels, _, models, info, ref = make_case(rng, channels=3, window=3, views=VIEWS3,
                                             distinct_exemplars=False, constant=True)
    assert labels.shape == (1, 3)
    assert info["front"]["sigma"] == 1.0  # documented fallback for a constant exemplar
    volume, temps, site = random_volume(rng, labels, (6, 6, 6), "random")
    volume = volume + rng.normal(0, 0.3, size=volume.shape).astype(np.float32)
    expected, spread = naive_for(VIEWS3, ref, volume, temps, site, labels)
    got = exact_log_lcpdf(volume, temps, site, models, spread)
    np.testing.assert_allclose(got, 0.0, atol=1e-12)
    np.testing.assert_allclose(expected, 0.0, atol=1e-12)


@pytest.mark.parametrize("channels", [1, 3])
def test_default_prune_keeps_argmax_and_values(compiled, channels):
    rng = np.random.default_rng(40 + channels)
    labels, _, models, _, ref = make_case(rng, channels=channels, window=5, views=VIEWS3,
                                          distinct_exemplars=True,
                                          rule=DecisionRule(bandwidth=0.5))
    for temps_mode in ("zeros", "random"):
        for _ in range(4):
            volume, temps, site = random_volume(rng, labels, (7, 7, 7), temps_mode)
            _, spread = naive_for(VIEWS3, ref, volume, temps, site, labels)
            exact = exact_log_lcpdf(volume, temps, site, models, spread)
            pruned = parzen.log_lcpdf(volume, temps, site, models)  # prune = PRUNE = 40
            np.testing.assert_array_equal(pruned.argmax(axis=1), exact.argmax(axis=1))
            np.testing.assert_allclose(np.exp(pruned), np.exp(exact), rtol=0, atol=1e-12)
            np.testing.assert_allclose(np.exp(pruned).sum(axis=1), 1.0, rtol=1e-9)
            big = exact > np.log(1e-6)
            np.testing.assert_allclose(pruned[big], exact[big], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("adaptive", [0.05, 0.2, 1.0])
@pytest.mark.parametrize("temps_mode", ["zeros", "ones", "random"])
def test_adaptive_bandwidth_matches_naive(compiled, adaptive, temps_mode):
    """``2h^2 = max(adaptive * D_min, min_two_h2)`` per view, D_min computed naively."""
    rng = np.random.default_rng([int(100 * adaptive), len(temps_mode)])
    labels, _, models, info, ref = make_case(rng, channels=3, window=3, views=("front", "top"),
                                             distinct_exemplars=True)
    floor = parzen.adaptive_floor(info)
    assert floor == pytest.approx(min(2 * (parzen.ADAPTIVE_FLOOR * ref[v]["h_opt"]) ** 2
                                      for v in ("front", "top")), rel=1e-9)
    for _ in range(3):
        volume, temps, site = random_volume(rng, labels, (6, 7, 8), temps_mode)
        # off-label neighbour values: D_min > 0, so the adaptive term (not the floor) decides
        volume = np.clip(volume + rng.normal(0, 0.1, volume.shape), 0, 1).astype(np.float32)
        expected, _ = naive_for(("front", "top"), ref, volume, temps, site, labels,
                                adaptive=adaptive, min_two_h2=floor)
        # adaptive bandwidths can be very sharp: prune=700 keeps every representable weight
        got = parzen.log_lcpdf(volume, temps, site, models, adaptive=adaptive, min_two_h2=floor,
                               prune=SAFE_SPREAD)
        assert_matches(got, expected)
        fixed, _ = naive_for(("front", "top"), ref, volume, temps, site, labels)
        if temps_mode != "ones":  # the adaptive mode must actually change the answer
            assert np.abs(got - fixed).max() > 1e-3


def test_adaptive_floor_applies_on_exact_match(compiled):
    """All neighbours hot: every D_p = 0, so 2h^2 is the floor and nothing is NaN."""
    rng = np.random.default_rng(5)
    labels, _, models, info, ref = make_case(rng, channels=1, window=3, views=("front",),
                                             distinct_exemplars=False)
    floor = parzen.adaptive_floor(info)
    volume, temps, site = random_volume(rng, labels, (6, 6, 6), "ones")
    expected, _ = naive_for(("front",), ref, volume, temps, site, labels, adaptive=0.2,
                            min_two_h2=floor)
    got = parzen.log_lcpdf(volume, temps, site, models, adaptive=0.2, min_two_h2=floor,
                           prune=SAFE_SPREAD)
    assert_matches(got, expected)


@pytest.mark.parametrize("channels", [1, 3])
def test_log_domain_fallback_matches_naive(compiled, channels):
    """A very sharp centre kernel underflows the kernel table: the log-domain path must agree."""
    rng = np.random.default_rng(60 + channels)
    rule = DecisionRule(centre_bandwidth=1e-3)
    # each view's exemplar uses only some of the values: the others carry no weight there
    palette = (rng.integers(0, 6, size=(6, channels)) / 5).astype(np.float32)
    palette[:, 0] = np.arange(6) / 5  # 6 distinct labels
    subsets = ([0, 1, 2], [2, 3, 4], [0, 5])
    exemplars = [palette[rng.choice(sub, size=(10, 11))] for sub in subsets]
    labels, _, models, _, ref = make_case(rng, channels=channels, window=3, views=VIEWS3,
                                          distinct_exemplars=True, rule=rule, exemplars=exemplars)
    assert len(labels) == 6
    off_diagonal = models.kernel_tables[0][~np.eye(len(labels), dtype=bool)]
    assert (off_diagonal == 0.0).all()  # the table alone cannot represent these labels
    for temps_mode in ("zeros", "random"):
        volume, temps, site = random_volume(rng, labels, (6, 6, 7), temps_mode)
        expected, spread = naive_for(VIEWS3, ref, volume, temps, site, labels)
        got = exact_log_lcpdf(volume, temps, site, models, spread)
        assert (expected < -1000).any()  # the fallback was needed
        assert_matches(got, expected)
        # even the astronomically small probabilities agree in the log domain (up to the
        # float32 precision of the squared label differences, ~1e-7 of an exponent ~1e5)
        np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-4)


def test_without_kernel_tables_matches_naive(compiled, monkeypatch):
    """Label sets too large for a table are computed entirely in the log domain."""
    monkeypatch.setattr(parzen, "KERNEL_TABLE_BYTES", 0)
    rng = np.random.default_rng(77)
    labels, _, models, _, ref = make_case(rng, channels=3, window=3, views=VIEWS3,
                                          distinct_exemplars=True)
    assert models.kernel_tables.shape == (3, 0, 0)
    volume, temps, site = random_volume(rng, labels, (7, 6, 6), "random")
    expected, spread = naive_for(VIEWS3, ref, volume, temps, site, labels)
    got = exact_log_lcpdf(volume, temps, site, models, spread)
    assert_matches(got, expected)


def test_level_one_uses_all_decimation_phases(compiled):
    rng = np.random.default_rng(91)
    exemplar = tiny_exemplar(rng, 1, size=(20, 22))
    labels, (image,) = make_labels([exemplar], rng=rng)
    models, info = parzen.build_view_models({"front": image}, labels, window=3, level=1,
                                            rule=DecisionRule())
    # 4 phases of 10x11 -> 4 * 8 * 9 patches
    assert info["front"]["n"] == 4 * 8 * 9
    parts = [naive.naive_extract_patches(ph, labels, 3) for ph in decimation_phases(image, 1)]
    patches = np.concatenate([p for p, _ in parts])
    centres = np.concatenate([c for _, c in parts])
    hopt = naive.naive_h_opt(naive.naive_sigma(labels[image]), len(centres), 9)
    assert info["front"]["h"] == pytest.approx(hopt, rel=1e-9)
    offsets = naive.naive_view_offsets("front", 3)
    volume, temps, site = random_volume(rng, labels, (6, 6, 6), "random")
    expected = naive.naive_log_lcpdf(volume, temps, site, offsets, patches, centres, labels, hopt)
    got = parzen.log_lcpdf(volume, temps, site, models, prune=np.inf)
    assert_matches(got, expected[None, :])


def test_views_use_their_own_axes(compiled):
    """Rotating the volume's axes together with the views gives the same LCPDF."""
    rng = np.random.default_rng(8)
    exemplar = tiny_exemplar(rng, 1, size=(11, 10))
    labels, (image,) = make_labels([exemplar], rng=rng)
    front, _ = parzen.build_view_models({"front": image}, labels, window=3, level=0,
                                        rule=DecisionRule())
    right, _ = parzen.build_view_models({"right": image}, labels, window=3, level=0,
                                        rule=DecisionRule())
    volume, temps, (i, j, k) = random_volume(rng, labels, (6, 7, 8), "random")
    # right view reads plane (j, k) as (row, col); moving axes (0, 1) to (1, 2) maps front onto it
    moved_v = np.ascontiguousarray(np.moveaxis(volume, (0, 1, 2), (1, 2, 0)))
    moved_t = np.ascontiguousarray(np.moveaxis(temps, (0, 1, 2), (1, 2, 0)))
    a = parzen.log_lcpdf(volume, temps, (i, j, k), front)
    b = parzen.log_lcpdf(moved_v, moved_t, (k, i, j), right)
    np.testing.assert_allclose(a, b, rtol=1e-12)


@settings(max_examples=25, deadline=None, database=None)
@given(seed=st.integers(0, 2**32 - 1), channels=st.sampled_from([1, 2, 3]),
       window=st.sampled_from([3, 5]), n_views=st.integers(1, 3), distinct=st.booleans(),
       temps_mode=st.sampled_from(["zeros", "ones", "random"]),
       bandwidth=st.sampled_from([0.5, 1.0, 2.0]), centre=st.sampled_from([0.1, 1.0, 3.0]))
def test_property_log_lcpdf_matches_naive(compiled, seed, channels, window, n_views, distinct,
                                          temps_mode, bandwidth, centre):
    rng = np.random.default_rng(seed)
    views = tuple(rng.permutation(VIEWS3)[:n_views])
    labels, _, models, _, ref = make_case(
        rng, channels=channels, window=window, views=views, distinct_exemplars=distinct,
        rule=DecisionRule(bandwidth=bandwidth, centre_bandwidth=centre))
    shape = tuple(int(x) for x in rng.integers(6, 9, size=3))
    volume, temps, site = random_volume(rng, labels, shape, temps_mode)
    expected, spread = naive_for(views, ref, volume, temps, site, labels)
    got = exact_log_lcpdf(volume, temps, site, models, spread)
    assert_matches(got, expected)
    assert_same_mode(got, expected)


# --------------------------------------------------------------------------- known bug

PRUNE_INF_SCRIPT = textwrap.dedent("""
    import numpy as np
    from npmrf3d.config import DecisionRule
    from npmrf3d.model.exemplar import make_labels
    from npmrf3d.model.parzen import build_view_models, log_lcpdf

    def case(seed, shape, bandwidth, size):
        rng = np.random.default_rng(seed)
        ex = (rng.integers(0, 6, size=shape) / 5).astype(np.float32)
        labels, (img,) = make_labels([ex], rng=rng)
        # a sharp neighbour bandwidth: some weights exp(-(D_p - D_min)/2h^2) underflow to 0.0
        models, _ = build_view_models({"front": img}, labels, window=3, level=0,
                                      rule=DecisionRule(bandwidth=bandwidth))
        vol = labels[rng.integers(0, len(labels), size=(size,) * 3)]
        temps = np.zeros((size,) * 3, np.float32)
        exact = log_lcpdf(vol, temps, (1, 2, 3), models, prune=np.inf)
        safe = log_lcpdf(vol, temps, (1, 2, 3), models, prune=700.0)  # keeps every weight > 0
        assert np.isfinite(exact).all(), exact
        err = np.abs(np.exp(exact) - np.exp(safe)).max()
        assert err < 1e-12, f"seed {seed}: prune=inf and prune=700 differ by {err}"

    case(335, (8, 8, 3), 0.15, 4)  # silent: duplicated labels re-weight L by up to 0.03
    case(0, (10, 10, 1), 0.05, 6)  # buffer overrun: heap corruption, segfault or abort
    print("ok")
""")


def test_prune_inf_survives_underflowing_weights():
    """``prune=np.inf`` ("keeps all") must equal keeping every representable weight.

    KNOWN LIBRARY BUG (reported): ``log_lcpdf_from_distances`` uses ``weights[lab] == 0.0`` as
    "label not seen yet"; a patch whose weight underflows to 0.0 (log weight < ~-745, reachable
    only with prune > 745) re-appends its label to ``nonzero``: duplicated labels count their
    weight twice in f and Z, and more than K appends overrun the (K,) buffer. Runs in a
    subprocess because the failure mode is memory corruption (segfault/abort).
    """
    root = Path(__file__).resolve().parents[1]
    proc = subprocess.run([sys.executable, "-c", PRUNE_INF_SCRIPT], capture_output=True,
                          text=True, timeout=300, cwd=root,
                          env={**os.environ, "PYTHONPATH": str(root)})
    assert proc.returncode == 0, f"rc={proc.returncode}\n{proc.stdout}\n{proc.stderr[-2000:]}"
    assert proc.stdout.strip().endswith("ok")


# --------------------------------------------------------------------------- robust (outlier) LCPDF


@pytest.mark.parametrize("table", [True, False])
@pytest.mark.parametrize("channels", [1, 3])
def test_outlier_mixture_equals_the_mixed_naive_lcpdf(compiled, monkeypatch, table, channels):
    """``outlier = a`` gives ``log((1 - a) L + a / K)`` of the naive LCPDF, with the kernel
    table and without it, and also where the sharp centre kernel makes ``L`` underflow."""
    if not table:
        monkeypatch.setattr(parzen, "KERNEL_TABLE_BYTES", 0)
    rng = np.random.default_rng(71 + channels)
    views = ("front", "right", "top")
    rule = DecisionRule(bandwidth=0.5, centre_bandwidth=0.01)
    labels, _, models, _, ref = make_case(rng, channels=channels, window=3, views=views,
                                          distinct_exemplars=False, rule=rule)
    assert (models.kernel_tables.shape[1] > 0) == table
    volume, temps, site = random_volume(rng, labels, (6, 6, 6), "random")
    expected, spread = naive_for(views, ref, volume, temps, site, labels)
    a = 0.05
    mixed = np.log((1 - a) * np.exp(expected) + a / len(labels))
    got = exact_log_lcpdf(volume, temps, site, models, spread, outlier=a)
    np.testing.assert_allclose(np.exp(got).sum(axis=1), 1.0, rtol=1e-9)
    np.testing.assert_allclose(got, mixed, rtol=1e-5, atol=1e-7)
    assert got.min() >= np.log(a / len(labels)) - 1e-9
