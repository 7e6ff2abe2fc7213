"""Each path of a k-coherence level's relaxation (npmrf3d.model.kcoherence_pass.LevelPass) run
alone at 16^3: a whole level with fixed iterations, ICM with per-voxel temperatures, a block
reading its pilot's histograms, global matches and the phase control. Each run by hand ends on
the volume the method makes for the same seed."""

from __future__ import annotations

import numpy as np
import pytest

from npmrf3d.methods import METHODS
from npmrf3d.methods.chen_wang import make_chen_wang_config
from npmrf3d.methods.npmrf_coherent import coherent_levels, make_coherent_config
from npmrf3d.model import kcoherence_engine
from npmrf3d.model.kcoherence_engine import KCoherenceLevels
from npmrf3d.model.kcoherence_pass import LevelPass, active_box
from npmrf3d.model.phases import bin_phase_error
from npmrf3d.model.regions import plan_region, whole_frame
from npmrf3d.studies.catalog import load_exemplar

SIDE = 16


def _views() -> dict[str, np.ndarray]:
    image = np.ascontiguousarray(load_exemplar("gravel64")[:32, :32], dtype=np.float32)
    return {v: image for v in ("front", "right", "top")}


def _phases() -> dict[str, np.ndarray]:
    """A two-phase exemplar (dark and light bands of uneven width), for the phase control."""
    rows = (np.arange(24) % 6 < 2).astype(np.float32)
    image = np.ascontiguousarray(np.tile(rows[:, None], (1, 24))[..., None])
    return {v: image for v in ("front", "right", "top")}


def _one_level(engine: KCoherenceLevels, seed: int):
    """The single level of a one-level run as the level loop starts it: the pass, its state and
    the generator after the initial sources (what :func:`npmrf3d.model.pyramid.run_pyramid` draws)."""
    rng = np.random.default_rng(seed)
    engine.frame = whole_frame((SIDE,) * 3)
    engine.prepare(0, engine.frame.shape)
    state = engine.initial(engine.frame.shape, rng)
    return LevelPass(engine, 0, state), state, rng


def test_a_whole_level_runs_its_fixed_iterations_over_every_voxel():
    per_view = _views()
    config = make_chen_wang_config(size=SIDE, window=4, levels=1, iterations=3, seed=3)
    step, state, rng = _one_level(KCoherenceLevels("chen-wang", config, per_view), config.seed)
    assert not step.local and step.icm is None and step.replay is None and step.n_iter == 3
    lo, hi, decide_lo, decide_hi = step.boxes(0)
    assert lo.tolist() == decide_lo.tolist() == [0, 0, 0] and hi.tolist() == decide_hi.tolist() == [SIDE] * 3
    for it in range(3):
        step.iterate(rng, it)
        assert len(step.history) == it + 1 and step.decided == (it + 1) * SIDE ** 3
    assert step.global_counts == [0, 0, 0] and step.stats(3)["iterations"] == 3
    whole = METHODS["chen-wang"].run(per_view, config, np.random.default_rng(config.seed))
    np.testing.assert_array_equal(state.volume, whole.volume)
    assert whole.history[0] == step.history


def test_icm_redecides_warm_voxels_until_its_stop_rule():
    per_view = _views()
    config = make_coherent_config(size=SIDE, window=4, levels=1, icm=True, max_sweeps=6, seed=5)
    step, state, rng = _one_level(coherent_levels(config, per_view), config.seed)
    assert step.icm is not None and step.n_iter == 6
    first = step.icm.history[0]
    calls = []
    history, stats = step.run(rng, lambda *a: calls.append(a))
    assert all(len(a) == 3 for a in calls) and [a[0] for a in calls] == list(range(1, len(calls) + 1))
    assert 1 <= stats["iterations"] <= 6 and len(stats["temperature"]) == stats["iterations"] + 1
    assert stats["temperature"][-1] < first  # the level cooled
    assert stats["updates"] == stats["voxels_decided"] <= stats["iterations"] * SIDE ** 3  # warm voxels only
    assert not step.icm.warm(stats["iterations"])  # stopped by its rule
    whole = METHODS["coherent"].run(per_view, config, np.random.default_rng(config.seed))
    np.testing.assert_array_equal(state.volume, whole.volume)
    assert whole.history[0] == history


def test_global_matches_rematch_some_worst_sites_each_pass():
    per_view = _views()
    config = make_chen_wang_config(size=SIDE, window=4, levels=1, iterations=2, global_share=0.2, seed=9)
    step, state, rng = _one_level(KCoherenceLevels("chen-wang", config, per_view), config.seed)
    step.iterate(rng, 0)
    step.iterate(rng, 1)
    assert len(step.global_counts) == 2 and all(0 < n <= 0.2 * step.sites for n in step.global_counts)
    whole = METHODS["chen-wang"].run(per_view, config, np.random.default_rng(config.seed))
    np.testing.assert_array_equal(state.volume, whole.volume)
    assert whole.stats["levels"]["level_0"]["global_matches"] == step.global_counts
    # one view's global search alone: it changes at most the sites it counts
    before = step.assign[0].copy()
    count, _ = step.global_matches(0, phi=1.0)
    assert 0 < count and int((step.assign[0] != before).sum()) <= count


def test_the_phase_control_moves_the_value_target_after_each_step():
    per_view = _phases()
    config = make_coherent_config(size=SIDE, window=3, levels=1, iterations=3, phase_weight=16.0, seed=2)
    engine = coherent_levels(config, per_view)
    step, state, rng = _one_level(engine, config.seed)
    assert engine.control is not None
    np.testing.assert_array_equal(step.value_target(0), step.values.target)  # no error measured yet
    step.iterate(rng, 0)
    want = bin_phase_error(step.values.hist, step.values.target, engine.phases)
    assert [c.last_error.tolist() for c in engine.control] == [np.asarray(e).tolist() for e in want]
    moved = step.value_target(1)
    assert moved.shape == step.values.target.shape and not np.array_equal(moved, step.values.target)
    step.iterate(rng, 1)
    step.iterate(rng, 2)
    whole = METHODS["coherent"].run(per_view, config, np.random.default_rng(config.seed))
    np.testing.assert_array_equal(state.volume, whole.volume)
    assert whole.stats["levels"]["level_0"]["phase_gain"] == [c.gain for c in engine.control]


@pytest.mark.parametrize("name", ["chen-wang", "coherent"])
def test_a_block_reads_its_pilots_histograms_batch_by_batch(tmp_path, monkeypatch, name):
    method = METHODS[name]
    per_view = _views()
    config = method.make_config(size=SIDE, window=3, levels=2, iterations=1, blockwise=True, pilot=8,
                                whole_voxels=1, seed=4)
    whole = method.run(per_view, config, np.random.default_rng(config.seed)).volume
    passes = []

    class Recorded(LevelPass):
        def __init__(self, *args):
            super().__init__(*args)
            passes.append(self)

    monkeypatch.setattr(kcoherence_engine, "LevelPass", Recorded)
    plan = plan_region(config.size, config.levels, method.aprons(config, per_view), (8, 0, 0), (8, 8, 8),
                       start=tmp_path / "start.npz")
    block = method.run(per_view, config, np.random.default_rng(config.seed), region=plan)
    np.testing.assert_array_equal(block.volume, whole[8:16, :8, :8])
    step = passes[-1]  # the block's finest level
    assert step.local and step.replay is not None and step.record is None and step.shrinking
    assert step.engine.frame.shape != step.engine.frame.extent
    _, _, lo, hi = active_box(step.engine.frame, 3, 1)
    assert step.decided == int(np.prod(hi - lo)) < int(np.prod(step.engine.frame.shape))
    for b in range(step.batches):  # before each batch the pilot's histograms, in the block's units
        step.batch_histograms(0, b)
        np.testing.assert_array_equal(step.histograms.positions, step.replay.positions[0, b] * step.grid_voxels)
        np.testing.assert_array_equal(step.histograms.values, step.replay.values[0, b])
    np.testing.assert_array_equal(step.value_target(0), step.replay.targets[0])
