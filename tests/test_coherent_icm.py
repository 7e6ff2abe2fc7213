"""ICM with per-voxel temperatures over coherent candidates (Urs et al. 2014; npmrf3d.model.kcoherence_icm):
the trusted search and votes against their numpy twins, the cooling and window sums, the
configuration, a resumed run and the thread count."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from npmrf3d._kernels import kcoherence as _k
from npmrf3d._kernels import kcoherence_solver as _s
from npmrf3d.errors import ParameterError
from npmrf3d.methods.npmrf_coherent import coherent_synthesize, make_coherent_config
from npmrf3d.model import kcoherence as coh
from npmrf3d.model.kcoherence_engine import pack_exemplars
from npmrf3d.model.kcoherence_icm import cool, inherited_mask, visit_mask, window_trust
from npmrf3d.model.neighbourhood import VIEW_AXES

from tests.naive import naive_cool, naive_search_view, naive_solve, naive_window_trust
from tests.test_chen_wang import VIEWS3, _histograms, _packed, _solve_case, _values



def _dyadic_trust(rng, shape):
    """Trust in quarters (0 included), so float32 window sums are exact."""
    return (rng.integers(0, 5, size=shape) / 4.0).astype(np.float32)


@pytest.mark.kernels  # the twin tests run again with NUMBA_DISABLE_JIT=1 (.ci/run)
@pytest.mark.parametrize("view", VIEWS3)
@pytest.mark.parametrize("window,channels,grid,n_random", [(3, 1, 1, 0), (4, 3, 2, 4)])
def test_trusted_search_matches_twin(rng, view, window, channels, grid, n_random):
    ex = rng.random((13, 12, channels)).astype(np.float32)
    m = coh.build_level_model(ex, window, dims=6, k=3)
    vol = rng.random((8, 6, 4, channels)).astype(np.float32)
    src = rng.integers(0, 13 * 12, size=vol.shape[:3]).astype(np.int32)
    trust = _dyadic_trust(rng, vol.shape[:3])
    ra, ca = VIEW_AXES[view]
    na = 3 - ra - ca
    prev = np.full(vol.shape[:3], -1, dtype=np.int32)
    hist = np.zeros(m.pixels)
    want_assign, want_omega, want_energy, want_hist = naive_search_view(
        vol, src, view, m, grid=grid, batches=2, index_hist=hist, phi=0.5, index_weight=2.0,
        r=0.8, floor=1e-3, assign_v=prev, n_random=n_random, salt=99, trust=trust)
    got_assign, got_hist = prev.copy(), hist.copy()
    omega = np.zeros(vol.shape[:3], dtype=np.float32)
    energy = np.zeros(vol.shape[na])
    _k.search_view(vol, src, ra, ca, coh.search_exemplar(m), _k.SearchRule(grid, 2, 0.5, 2.0, 0.8, 1e-3, n_random, 99),
                   got_hist, got_assign, np.empty(vol.shape[:3], dtype=np.int32), omega, energy, trust)
    np.testing.assert_array_equal(got_assign, want_assign)
    np.testing.assert_allclose(omega, want_omega, rtol=1e-4)
    np.testing.assert_allclose(energy, want_energy, rtol=1e-6)
    np.testing.assert_array_equal(got_hist, want_hist)


@pytest.mark.kernels  # the twin tests run again with NUMBA_DISABLE_JIT=1 (.ci/run)
@pytest.mark.parametrize("views", [("front",), VIEWS3])
@pytest.mark.parametrize("medoid,balance,likelihood,value_weight", [(0, False, 0, 0.0), (8, True, 0, 4.0),
                                                                    (8, False, 1, 4.0), (3, False, 2, 0.0)])
@pytest.mark.parametrize("grid,channels", [(1, 1), (2, 3)])
def test_trusted_solve_matches_twin(rng, views, medoid, balance, likelihood, value_weight, grid, channels):
    window = 4
    exemplars, models, assign, omega, src, volume = _solve_case(rng, views, window, channels, grid)
    vh = _values(exemplars, models, volume)
    values = {"hist": vh.hist.tolist(), "target": vh.target.tolist(), "weight": value_weight,
              "prior": 2.0 * (likelihood > 0 and value_weight > 0),
              "lo": vh.lo.tolist(), "scale": vh.scale.tolist(), "unit": vh.unit}
    trust = _dyadic_trust(rng, volume.shape[:3])
    trust[:2] = 0.0  # neighbourhoods without a trusted pixel: no vote, the voxel may keep its state
    packed, ex_off, hist_off = pack_exemplars(models)
    n = volume.shape[0] * volume.shape[1] * volume.shape[2]
    order = rng.permutation(n)[: n - 20].astype(np.int64)  # not every voxel visited
    bounds = np.array([0, 50, 120, len(order)], dtype=np.int64)
    pos_hist = [np.bincount(src[vi].ravel(), minlength=110).astype(np.float64) for vi in range(len(views))]
    theta = np.full(len(views), n / 110.0)
    want_vol, want_src, want_hist, want_changed = naive_solve(
        volume, src, assign, omega, views, exemplars, window=window, grid=grid, order=order, bounds=bounds,
        pos_hist=pos_hist, theta=theta, position_weight=3.0, medoid=medoid, balance=balance,
        likelihood=likelihood, h2c=0.05, outlier=0.01, values=values, trust=trust)
    axes = np.array([VIEW_AXES[v] for v in views], dtype=np.int64)
    votes_trust = _s.VoteTrust(trust, window_trust(trust, axes, window, coh.anchor(window)))
    got_vol, got_src, got_hist = volume.copy(), src.copy(), np.concatenate(pos_hist)
    changed = _s.solve(got_vol, got_src, assign, omega,
                       _packed(axes, packed, ex_off, [10] * len(views), window, coh.anchor(window), grid),
                       _histograms(got_hist, hist_off, theta, 3.0, 0.0, packed, vh, value_weight, values["prior"]),
                       votes_trust, _s.SolverRule(medoid, balance, likelihood, 0.05, 0.01, 0.0, 0), order, bounds, 7)
    np.testing.assert_array_equal(got_vol, want_vol)
    np.testing.assert_array_equal(got_src, want_src)
    np.testing.assert_array_equal(got_hist, np.concatenate(want_hist))
    assert changed == want_changed


@pytest.mark.kernels  # the twin tests run again with NUMBA_DISABLE_JIT=1 (.ci/run)
@pytest.mark.parametrize("window", [2, 3, 4])
def test_window_trust_matches_twin(rng, window):
    trust = rng.random((5, 6, 7)).astype(np.float32)
    axes = np.array([VIEW_AXES[v] for v in VIEWS3], dtype=np.int64)
    got = window_trust(trust, axes, window, coh.anchor(window))
    for vi, view in enumerate(VIEWS3):
        for site in [(0, 0, 0), (4, 5, 6), (2, 1, 3)]:
            assert got[vi][site] == pytest.approx(naive_window_trust(trust, view, site, window), rel=1e-6)


@pytest.mark.kernels  # the twin tests run again with NUMBA_DISABLE_JIT=1 (.ci/run)
def test_cooling_matches_twin(rng):
    temps = rng.random((5, 4, 6)).astype(np.float32)
    temps[0, 0, 0] = 0.0
    inherited = inherited_mask(temps.shape)
    for resynth in (True, False):
        visited = visit_mask(temps, inherited, resynth)
        assert visited[0, 0, 0] == resynth  # cold and inherited: visited only with resynth
        want = naive_cool(temps, visited, inherited, -1.5)
        got = temps.copy()
        cool(got, visited, inherited, -1.5)
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7)
        assert np.all(got[inherited] == temps[inherited])  # inherited voxels keep temperature 0


def test_config_validates_the_icm_options():
    assert make_coherent_config().icm is False
    c = make_coherent_config(icm=True, xi=-3, stop=1.0, max_sweeps=5, upsample="1/8", inherit="fixed")
    assert (c.xi, c.stop, c.max_sweeps, c.upsample, c.inherit) == (-3.0, 1.0, 5, "1/8", "fixed")
    for bad, match in [({"xi": 0.0}, "xi"), ({"stop": 0.0}, "stop"), ({"stop": 1.5}, "stop"),
                       ({"max_sweeps": 0}, "max_sweeps"), ({"upsample": "trilinear"}, "upsample"),
                       ({"inherit": "keep"}, "inherit"), ({"t0": 1.0}, "t0")]:
        with pytest.raises(ParameterError, match=match):
            make_coherent_config(icm=True, **bad)


KW = dict(size=16, window=(4, 4), levels=2, rng=5, icm=True, max_sweeps=4)


def _exemplar():
    return np.random.default_rng(0).random((24, 24)).astype(np.float32)


def test_icm_options_change_the_volume_and_the_temperatures_fall():
    ex = _exemplar()
    base = coherent_synthesize(ex, **KW)
    levels = base.stats["levels"]
    for name, level in levels.items():
        t = level["temperature"]
        assert all(b <= a for a, b in zip(t, t[1:])), name
        assert 1 <= level["iterations"] <= KW["max_sweeps"]
    assert levels["level_1"]["temperature"][0] == 16 ** 3 / 8  # the coarsest level starts all hot
    assert levels["level_0"]["temperature"][0] == 16 ** 3 * 7 / 8  # inherited voxels start cold
    plain = coherent_synthesize(ex, **{**{k: v for k, v in KW.items() if k != "max_sweeps"}, "icm": False,
                                       "iterations": (2, 2)})  # max_sweeps without icm is refused
    assert not np.array_equal(plain.volume, base.volume)
    for change in ({"xi": -3.0}, {"stop": 0.5}, {"upsample": "1/8"}, {"inherit": "fixed"}):
        other = coherent_synthesize(ex, **{**KW, **change})
        assert not np.array_equal(other.volume, base.volume), change


class _Stop(Exception):
    pass


def test_icm_checkpoint_resume(tmp_path):
    ex = _exemplar()
    res = coherent_synthesize(ex, **KW)
    path = tmp_path / "coarse.npz"

    def stop(level, it, n, value):
        if level == 0:
            raise _Stop

    with pytest.raises(_Stop):
        coherent_synthesize(ex, progress=stop, checkpoint=path, **KW)
    with np.load(path) as saved:
        assert saved["temps"].dtype == np.float32 and saved["temps"].shape == (8, 8, 8)
    resumed = coherent_synthesize(ex, checkpoint=path, **KW)
    np.testing.assert_array_equal(resumed.volume, res.volume)
    assert resumed.history == res.history
    with pytest.raises(ParameterError, match="different configuration"):
        coherent_synthesize(ex, checkpoint=path, **{**KW, "xi": -2.0})


def test_icm_same_volume_at_one_and_two_threads(tmp_path):
    script = textwrap.dedent(
        """
        import sys, numba, numpy as np
        from npmrf3d.methods.npmrf_coherent import coherent_synthesize
        assert numba.get_num_threads() == int(sys.argv[2])
        ex = np.random.default_rng(3).random((24, 24, 3)).astype(np.float32)
        vols = [coherent_synthesize(ex, size=16, window=(4, 4), levels=2, icm=True, max_sweeps=3,
                                    upsample=up, rng=7).volume for up in ("1/8", "8/8")]
        np.save(sys.argv[1], np.stack(vols))
        """
    )
    root = Path(__file__).resolve().parents[1]
    volumes = []
    for threads in (1, 2):
        out = tmp_path / f"v{threads}.npy"
        env = {**os.environ, "NUMBA_NUM_THREADS": str(threads), "PYTHONPATH": str(root)}
        subprocess.run([sys.executable, "-c", script, str(out), str(threads)], check=True, env=env, cwd=root,
                       timeout=600)
        volumes.append(np.load(out))
    np.testing.assert_array_equal(volumes[0], volumes[1])
