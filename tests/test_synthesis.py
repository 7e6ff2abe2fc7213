"""End-to-end behaviour of the sampler: determinism, stopping, inheritance, patterns, resume."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import npmrf3d
from npmrf3d.analysis import metrics
from npmrf3d.config import PRESETS
from npmrf3d.model.exemplar import make_labels
from npmrf3d.model.heuristics import DECISIONS, get_heuristic
from npmrf3d.model.neighbourhood import colour_classes
from npmrf3d.model.parzen import PRUNE, adaptive_floor, build_view_models
from npmrf3d.model.pyramid import random_state, upsample
from npmrf3d.model.relax import relax_icm


def checkerboard(side: int = 24, block: int = 2) -> np.ndarray:
    """A 2D checkerboard of period ``2 * block``; every axis-aligned slice of the 3D
    checkerboard ``((i//b) + (j//b) + (k//b)) % 2`` is a shifted copy of it."""
    r = np.arange(side) // block
    return (((r[:, None] + r[None, :]) % 2) * 255).astype(np.uint8)


def lag_correlation(volume: np.ndarray, view: str, lag: int) -> float:
    """Mean normalised autocorrelation of the view's slices at lags (0, lag) and (lag, 0)."""
    ac = metrics.autocorrelation(metrics.view_slices(volume, view)[..., 0], lag)
    return float((ac[lag, 2 * lag] + ac[2 * lag, lag]) / 2)


SMALL = dict(size=16, window=5, levels=2)


def test_same_seed_same_volume_and_different_seed_differs():
    a = npmrf3d.synthesize(checkerboard(), rng=3, **SMALL).volume
    b = npmrf3d.synthesize(checkerboard(), rng=3, **SMALL).volume
    c = npmrf3d.synthesize(checkerboard(), rng=4, **SMALL).volume
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.slow
def test_volume_does_not_depend_on_thread_count(tmp_path):
    script = textwrap.dedent(
        """
        import sys, numpy as np, numba, npmrf3d
        assert numba.get_num_threads() == int(sys.argv[2])
        res = npmrf3d.synthesize(None, size=16, window=5, levels=2, rng=11)
        vols = [res.volume]
        for sampler in ("metropolis", "heat-bath"):
            vols.append(npmrf3d.synthesize(npmrf3d.data.path("ihc64"), size=16, window=5,
                                           levels=2, relaxation="anneal", sampler=sampler, support="full",
                                           palette=16, proposals=2, rng=11).volume)
        np.save(sys.argv[1], np.concatenate(vols, axis=3))
        """
    )
    volumes = []
    for threads in (1, 2):
        out = tmp_path / f"v{threads}.npy"
        env = {**os.environ, "NUMBA_NUM_THREADS": str(threads)}
        subprocess.run([sys.executable, "-c", script, str(out), str(threads)], check=True, env=env)
        volumes.append(np.load(out))
    np.testing.assert_array_equal(volumes[0], volumes[1])


def _level_setup(window=5, shape=(16, 16, 16), seed=0):
    rng = np.random.default_rng(seed)
    ex = npmrf3d.load_exemplar(None)[:32, :32]
    labels, (image,) = make_labels([ex], rng=rng)
    freq = np.bincount(image.ravel(), minlength=len(labels)) / image.size
    rule = PRESETS["tuned"]
    models, info = build_view_models({"front": image, "right": image, "top": image}, labels,
                                     window=window, level=0, rule=rule)
    parent = random_state(tuple(n // 2 for n in shape), labels, freq, rng)
    state = upsample(parent, "1/8", labels, freq, rng)
    kwargs = dict(heuristic=get_heuristic("ML_H2b").code, decision=DECISIONS[rule.decision],
                  tau=rule.tau, xi=-3.0, max_sweeps=30, adaptive=rule.adaptive,
                  min_two_h2=adaptive_floor(info), prune=PRUNE,
                  histogram_weight=rule.histogram_weight, outlier=rule.outlier,
                  exemplar_freq=freq, rng=rng)
    return state, models, colour_classes(shape, window), kwargs


@pytest.mark.parametrize("stop", [0.5, 0.95])
def test_icm_stops_at_the_requested_fraction(stop):
    state, models, classes, kwargs = _level_setup()
    history, stats = relax_icm(state.volume, state.labels_volume, state.temps, state.inherited,
                               models, classes, stop=stop, resynth=True, **kwargs)
    initial = history[0]
    assert history[-1] <= (1 - stop) * initial
    assert all(t > (1 - stop) * initial for t in history[:-1])
    assert stats["sweeps"] == len(history) - 1


@pytest.mark.parametrize("resynth", [False, True])
def test_fixed_keeps_inherited_voxels_and_resynth_may_change_them(resynth):
    state, models, classes, kwargs = _level_setup()
    before = state.volume[state.inherited].copy()
    temps_before = state.temps[state.inherited].copy()
    relax_icm(state.volume, state.labels_volume, state.temps, state.inherited, models, classes,
              stop=0.95, resynth=resynth, **kwargs)
    after = state.volume[state.inherited]
    assert np.all(state.temps[state.inherited] == temps_before)  # temperature stays 0
    if resynth:
        assert not np.array_equal(before, after)
    else:
        np.testing.assert_array_equal(before, after)


@pytest.mark.parametrize("variant", ["default"])
def test_checkerboard_period_appears_in_every_constrained_view(variant):
    """A sampler that ignores its neighbours gives ~0 correlation at every lag; the pattern
    of period 4 gives +1 at lag 4 and -1 at lag 2."""
    res = npmrf3d.synthesize(checkerboard(), size=16, window=5, levels=2, heuristic="ML_H2b",
                             variant=variant, rng=0)
    for view in ("front", "right", "top"):
        assert lag_correlation(res.volume, view, 4) > 0.5, view
        assert lag_correlation(res.volume, view, 2) < -0.3, view


def test_structureless_control_fails_the_checkerboard_check():
    """The check above can fail: voxels drawn independently from the exemplar."""
    rng = np.random.default_rng(0)
    control = rng.choice([0.0, 1.0], size=(16, 16, 16, 1)).astype(np.float32)
    assert lag_correlation(control, "front", 4) < 0.3


@pytest.mark.slow
def test_default_on_bundled_exemplar_beats_structureless_control_and_is_not_flat():
    """Fixed seed, 32^3: the default variant's slices carry the exemplar's autocorrelation
    structure clearly better than voxels drawn independently from the exemplar (docs/quality.md
    gives ~0.5 of the control on this exemplar), with the right histogram and no dominant value."""
    ex = npmrf3d.load_exemplar(None)
    res = npmrf3d.synthesize(ex, size=32, window=7, levels=2, rng=0)
    rng = np.random.default_rng(0)
    flat = ex.reshape(-1, ex.shape[2])
    control = flat[rng.integers(0, len(flat), size=32**3)].reshape(32, 32, 32, -1)
    for view in ("front", "right", "top"):
        ratio = (metrics.autocorrelation_error(ex, res.volume, view, 8)
                 / metrics.autocorrelation_error(ex, control, view, 8))
        assert ratio < 0.7, (view, ratio)
    assert metrics.histogram_kl(ex, res.volume) < 0.5
    assert metrics.largest_value_share(res.volume) < 0.1
    literal = npmrf3d.synthesize(ex, size=16, window=5, levels=2, variant="literal", rng=0)
    assert metrics.largest_value_share(literal.volume) > metrics.largest_value_share(res.volume)


# --------------------------------------------------------------------------- segmented exemplars

def _phase_slice(side: int = 24) -> np.ndarray:
    """A two-phase image with round pores of several sizes (a thresholded micro-CT slice)."""
    r, c = np.mgrid[:side, :side]
    pores = np.zeros((side, side), dtype=bool)
    for (y, x, rad) in ((4, 5, 3), (15, 6, 2), (9, 16, 4), (20, 19, 2), (19, 11, 1.5)):
        pores |= (r - y) ** 2 + (c - x) ** 2 <= rad ** 2
    return np.where(pores, 0, 255).astype(np.uint8)


def _preset_twins(image, size, levels, seed):
    """The segmented preset's two runs, made by hand: the coherent sampler with the preset's
    window, vote weighting and smoothness prior and the default's phase control, ``levels`` then ``levels - 1``
    levels, on one generator in turn."""
    from npmrf3d.methods.npmrf_coherent import SEGMENTED, coherent_synthesize
    generator = np.random.default_rng(seed)
    return [coherent_synthesize(image, size=size, levels=n, window=(SEGMENTED.window,) * n,
                                value_weight=SEGMENTED.value_weight, smoothness=SEGMENTED.smoothness,
                                attached=SEGMENTED.attached,
                                phase_weight=npmrf3d.SynthesisConfig.phase_weight, rng=generator)
            for n in (levels, levels - SEGMENTED.fewer_levels)]


def test_segmented_preset_keeps_the_trial_nearer_the_exemplars_two_point_shape():
    from npmrf3d.methods.npmrf_coherent import SEGMENTED
    image = _phase_slice()
    res = npmrf3d.synthesize(image, size=16, levels=2, rng=3)
    assert res.stats["segmented"] is True
    twins = _preset_twins(image, 16, 2, 3)
    errors = [metrics.two_point_shape_error(image, t.volume, reference="isotropic") for t in twins]
    trials = res.stats["level_trials"]
    assert [t["levels"] for t in trials] == [2, 1]
    assert [t["two_point_shape_error"] for t in trials] == pytest.approx(errors, rel=1e-12)
    kept = int(np.argmin(errors))
    assert res.stats["levels_kept"] == (2, 1)[kept]
    assert np.array_equal(res.volume, twins[kept].volume)
    assert [lv["window"] for lv in res.stats["levels"].values()] == [SEGMENTED.window] * (2 - kept)
    assert res.timings["total"] >= sum(t["seconds"] for t in trials) * 0.999
    assert np.array_equal(npmrf3d.synthesize(image, size=16, levels=2, rng=3, segmented="yes").volume,
                          res.volume)


@pytest.mark.parametrize("kept", [0, 1])
def test_segmented_preset_returns_whichever_trial_scores_lower(monkeypatch, kept):
    from npmrf3d.methods import npmrf_coherent
    image = _phase_slice()
    scores = iter([0.5, 0.9] if kept == 0 else [0.9, 0.5])
    monkeypatch.setattr(npmrf_coherent, "two_point_shape_error", lambda exemplars, volume, reference: next(scores))
    res = npmrf3d.synthesize(image, size=16, levels=2, rng=4)
    assert res.stats["levels_kept"] == (2, 1)[kept]
    assert np.array_equal(res.volume, _preset_twins(image, 16, 2, 4)[kept].volume)
    assert len(res.history) == 2 - kept


def test_segmented_preset_resumes_inside_its_second_pyramid(tmp_path):
    image = _phase_slice(32)  # 32^3 in 3 levels, then 2: the second pyramid checkpoints its first level
    full = npmrf3d.synthesize(image, size=32, levels=3, rng=6)
    seen = []

    class Stop(Exception):
        pass

    def interrupt(level, step, steps, value):
        seen.append((level, step))
        if seen.count((0, 1)) == 2:  # the second pyramid's finest level, after one iteration
            raise Stop

    path = tmp_path / "run.npz"
    with pytest.raises(Stop):
        npmrf3d.synthesize(image, size=32, levels=3, rng=6, progress=interrupt, checkpoint=path)
    assert path.is_file() and (tmp_path / "run.levels2.npz").is_file()
    again = []
    resumed = npmrf3d.synthesize(image, size=32, levels=3, rng=6, checkpoint=path,
                                 progress=lambda level, *rest: again.append(level))
    assert np.array_equal(resumed.volume, full.volume)
    assert set(again) == {0}  # the first pyramid came whole from its file, the second from level 0
    assert resumed.stats["level_trials"] == [
        {**t, "seconds": r["seconds"]} for t, r in zip(full.stats["level_trials"], resumed.stats["level_trials"])]


def test_segmented_preset_with_one_level_runs_once():
    res = npmrf3d.synthesize(_phase_slice(), size=16, levels=1, rng=3)
    assert res.stats["segmented"] is True and res.stats["levels_kept"] == 1
    assert "level_trials" not in res.stats


def test_segmented_no_and_photographs_keep_the_window():
    image = _phase_slice()
    off = npmrf3d.synthesize(image, size=16, levels=2, rng=3, segmented="no")
    assert off.stats["segmented"] is False
    assert [lv["window"] for lv in off.stats["levels"].values()] == [7, 7]
    assert not np.array_equal(off.volume, npmrf3d.synthesize(image, size=16, levels=2, rng=3).volume)
    photo = np.random.default_rng(0).integers(0, 256, (24, 24)).astype(np.uint8)  # ~200 grey values
    res = npmrf3d.synthesize(photo, size=16, levels=2, rng=3)
    assert res.stats["segmented"] is False
    assert np.array_equal(res.volume, npmrf3d.synthesize(photo, size=16, levels=2, rng=3, segmented="no").volume)


def test_is_segmented_counts_grey_values_over_all_exemplars():
    from npmrf3d.methods.npmrf_coherent import SEGMENTED_MAX_VALUES, is_segmented
    n = SEGMENTED_MAX_VALUES
    values = np.arange(n, dtype=np.float32).reshape(-1, 1)
    assert is_segmented([np.tile(values, (1, 3))])
    assert not is_segmented([np.arange(n + 1, dtype=np.float32).reshape(-1, 1)])
    # together: two exemplars of n values each, n + n distinct in all
    assert not is_segmented([values, values + n])
    # colour: the grey value is the mean over channels (two colours of equal mean are one value)
    colours = np.array([[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]])
    assert is_segmented([colours]) and is_segmented([np.tile(colours, (n, n, 1))])


def test_segmented_mode_is_validated():
    with pytest.raises(npmrf3d.ParameterError, match="segmented"):
        npmrf3d.synthesize(_phase_slice(), size=16, levels=2, segmented="maybe")
