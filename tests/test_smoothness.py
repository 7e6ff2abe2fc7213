"""The coherent decision's smoothness prior (npmrf3d/_kernels/smoothness.py): the kernel against
its twin in tests/naive.py, the solver with it against the twin solver, and what it does to a
segmented exemplar's volume."""

from __future__ import annotations

import numpy as np
import pytest

import npmrf3d
from npmrf3d._kernels import kcoherence_solver as _s
from npmrf3d._kernels.candidate_decision import HEAT_BATH, METROPOLIS, ML_H1A, ML_H2A, ML_H2B
from npmrf3d._kernels.smoothness import smoothness_prior
from npmrf3d.analysis import materials
from npmrf3d.model.kcoherence_engine import pack_exemplars
from npmrf3d.model.neighbourhood import VIEW_AXES
from tests.naive import naive_smoothness, naive_solve
from tests.test_chen_wang import _histograms, _packed, _solve_case, _values

VIEWS3 = ("front", "right", "top")


@pytest.mark.parametrize("channels", [1, 3])
def test_smoothness_prior_matches_twin(channels):
    rng = np.random.default_rng(channels)
    previous = rng.random((5, 3, 4, channels)).astype(np.float32)
    span = rng.random(channels) + 0.5
    for site in [(0, 0, 0), (4, 2, 3), (2, 1, 0)]:
        colour = rng.random(channels).astype(np.float32)
        got = smoothness_prior(colour, previous, *site, 1.0 / span, 1.7)
        assert got == pytest.approx(naive_smoothness(colour, previous, site, span, 1.7), rel=1e-12)
    # two phases: -beta per neighbour of the other phase
    labels = np.zeros((3, 3, 3, 1), dtype=np.float32)
    labels[1, 1, 0] = labels[0, 1, 1] = 1.0
    assert smoothness_prior(np.ones(1, np.float32), labels, 1, 1, 1, np.ones(1), 2.0) == -2.0 * 4
    assert smoothness_prior(np.zeros(1, np.float32), labels, 1, 1, 1, np.ones(1), 2.0) == -2.0 * 2


@pytest.mark.parametrize("likelihood,temperature,sampler", [
    (ML_H2B, 0.0, HEAT_BATH), (ML_H2A, 0.0, HEAT_BATH), (ML_H2B, 0.7, HEAT_BATH), (ML_H2B, 0.7, METROPOLIS),
    (ML_H1A, 0.0, HEAT_BATH)])
def test_solve_with_smoothness_matches_twin(likelihood, temperature, sampler):
    rng = np.random.default_rng(3)
    exemplars, models, assign, omega, src, volume = _solve_case(rng, VIEWS3, 4, 2, 1)
    vh = _values(exemplars, models, volume)
    values = {"hist": vh.hist.tolist(), "target": vh.target.tolist(), "weight": 4.0, "prior": 2.0,
              "lo": vh.lo.tolist(), "scale": vh.scale.tolist(), "unit": vh.unit}
    packed, ex_off, hist_off = pack_exemplars(models)
    n = volume.size // volume.shape[3]
    order = rng.permutation(n).astype(np.int64)
    bounds = np.array([0, 60, n], dtype=np.int64)
    pos_hist = [np.bincount(s.ravel(), minlength=110).astype(np.float64) for s in src]
    theta = np.full(3, n / 110.0)
    span = np.array([0.9, 1.1])
    common = dict(window=4, grid=1, order=order, bounds=bounds, theta=theta, position_weight=3.0, medoid=8,
                  likelihood=likelihood, h2c=0.05, outlier=0.01, values=values, temperature=temperature,
                  salt=99, sampler=sampler)
    want = naive_solve(volume, src, assign, omega, VIEWS3, exemplars, pos_hist=pos_hist, smoothness=1.5,
                       span=span, **common)
    plain = naive_solve(volume, src, assign, omega, VIEWS3, exemplars, pos_hist=pos_hist, **common)
    got_vol, got_src = volume.copy(), src.copy()
    values["hist"] = vh.hist.tolist()  # the twin moved its copy; the kernel starts from the same
    rule = _s.SolverRule(8, False, likelihood, 0.05, 0.01, temperature, 99, sampler, smoothness=1.5,
                         previous=volume.copy(), inv_span=1.0 / span)
    changed = _s.solve(got_vol, got_src, assign, omega,
                       _packed([VIEW_AXES[v] for v in VIEWS3], packed, ex_off, [10] * 3, 4, 1, 1),
                       _histograms(np.concatenate(pos_hist), hist_off, theta, 3.0, 0.0, packed, vh, 4.0, 2.0),
                       _s.NO_TRUST, rule, order, bounds, 7)
    np.testing.assert_array_equal(got_vol, want[0])
    np.testing.assert_array_equal(got_src, want[1])
    assert changed == want[3]
    assert not np.array_equal(want[0], plain[0])   # the prior decided some voxels


def _bands(side: int = 32) -> np.ndarray:
    """A two-phase slice: wavy pore bands a few pixels wide (a quarter of the pixels)."""
    r, c = np.mgrid[:side, :side]
    return ((np.sin(r / 2.3 + 2 * np.sin(c / 5.0)) > 0.5).astype(np.float32))[..., None]


def test_smoothness_keeps_a_phase_together():
    exemplar = _bands()
    kw = dict(method="coherent", size=16, levels=2, window=5, value_weight=8.0, rng=0)
    rough = npmrf3d.synthesize(exemplar, **kw).volume[..., 0] > 0.5
    smooth = npmrf3d.synthesize(exemplar, smoothness=2.0, **kw).volume[..., 0] > 0.5
    again = npmrf3d.synthesize(exemplar, smoothness=2.0, **kw).volume[..., 0] > 0.5
    np.testing.assert_array_equal(smooth, again)
    assert set(np.unique(smooth)) == {False, True}
    # fewer phase boundaries along every axis
    for axis in range(3):
        assert materials.interface_density(smooth, axis) < materials.interface_density(rough, axis)
