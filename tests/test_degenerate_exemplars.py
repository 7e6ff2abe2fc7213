"""Degenerate and oversized exemplars: identical patches keep the nearest-neighbour search
bounded, long searches give way to Ctrl-C and SIGTERM, and an exemplar too large for the
machine is refused before any work."""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from scipy.spatial import cKDTree

import npmrf3d
from npmrf3d import cli, resources
from npmrf3d.methods import estimate, get_method
from npmrf3d.model import kcoherence as coh
from npmrf3d.model.nearest import PatchIndex, first_valid, repeats


def _constant(side: int, value: float = 0.5) -> np.ndarray:
    return np.full((side, side, 1), value, dtype=np.float32)


def test_constant_exemplar_makes_a_constant_volume_from_one_distinct_patch():
    ex = _constant(200)
    model = coh.build_level_model(ex, 3)
    # 39 204 identical patches: the tree holds one vector, not a leaf of all of them
    assert model.tree.deduplicated and model.tree.distinct == 1 and len(model.tree) == 198 * 198
    assert model.tree.repeat_work == (198 * 198) ** 2 - 198 * 198
    assert (model.kcoh[model.valid] >= 0).all()
    assert (model.kcoh[model.valid] != model.valid[:, None]).all()  # never a centre's own set
    result = npmrf3d.synthesize(ex, size=8, levels=1, window=3, rng=0)
    assert result.volume.shape == (8, 8, 8, 1)
    assert np.all(result.volume == np.float32(0.5))


def test_exemplars_with_few_repeats_keep_the_plain_tree():
    points = np.random.default_rng(0).normal(size=(500, 4))
    index = PatchIndex(points)
    assert not index.deduplicated and index.distinct == 500 and index.repeat_work == 0
    d, i = index.query(points[:40], 3)
    d_ref, i_ref = cKDTree(points).query(points[:40], k=3)
    assert np.array_equal(i, i_ref) and np.array_equal(d, d_ref)
    # a few identical rows: still within the budget, still the plain tree
    doubled = np.concatenate([points, points[:10]])
    assert not PatchIndex(doubled).deduplicated


def _brute(points, queries):
    return ((queries[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)


def test_deduplicated_query_finds_the_nearest_points_identical_ones_by_index(rng):
    labels = (rng.random((30, 30, 1)) < 0.2).astype(np.float32)
    points = coh.pca_project(coh.centre_patches(labels, 3), 4)[2]
    index = PatchIndex(points, budget=0)
    assert index.deduplicated and index.distinct < len(points)
    d, i = index.query(points, 7)
    sq = _brute(points, points)
    assert np.allclose(d ** 2, np.sort(sq, axis=1)[:, :7])
    assert np.allclose(np.take_along_axis(sq, i, axis=1), d ** 2)
    # identical points come in index order, and each point's own vector comes first
    same = np.all(points[i[:, :-1]] == points[i[:, 1:]], axis=2)
    assert (np.diff(i, axis=1)[same] > 0).all()
    assert np.all(points[i[:, 0]] == points)


@pytest.mark.parametrize("exclude", [0.0, 1.0, 2.5])
def test_deduplicated_k_coherence_sets_match_brute_force_distances(rng, exclude):
    labels = (rng.random((24, 24, 1)) < 0.3).astype(np.float32)
    points = coh.pca_project(coh.centre_patches(labels, 3), 5)[2]
    side = 22
    coords = np.stack(np.divmod(np.arange(len(points)), side), axis=1)
    index = PatchIndex(points, budget=0)
    sets = coh.k_coherence_sets(points, 4, exclude=exclude, coords=coords, tree=index)
    sq = _brute(points, points)
    cheb = np.abs(coords[:, None, :] - coords[None, :, :]).max(axis=2)
    eligible = (cheb > exclude) & ~np.eye(len(points), dtype=bool)
    want = np.sort(np.where(eligible, sq, np.inf), axis=1)[:, :4]
    assert np.allclose(np.take_along_axis(sq, sets, axis=1), want)
    assert np.take_along_axis(eligible, sets, axis=1).all()


def test_repeats_groups_identical_rows_and_ignores_the_sign_of_zero():
    points = np.array([[0.0, 1.0], [-0.0, 1.0], [2.0, 3.0], [0.0, 1.0]])
    first, group, counts = repeats(points)
    assert first.tolist() == [0, 2] and group.tolist() == [0, 0, 1, 0] and counts.tolist() == [3, 1]


def test_first_valid_pads_short_rows_with_their_last_valid_entry():
    values = np.array([[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12]])
    valid = np.array([[True, False, True, True], [False, False, True, False], [False] * 4])
    assert first_valid(values, valid, 2).tolist() == [[1, 3], [7, 7], [9, 9]]


class _SignallingTree:
    """A k-d tree stand-in whose second query sends SIGINT to this process."""

    def __init__(self, tree):
        self.tree, self.n, self.data, self.calls = tree, tree.n, tree.data, 0

    def query(self, vectors, k, **options):
        self.calls += 1
        if self.calls == 2:
            os.kill(os.getpid(), signal.SIGINT)
        return self.tree.query(vectors, k=k, **options)


def test_a_signal_ends_a_search_between_chunks():
    points = np.random.default_rng(1).normal(size=(64, 3))
    index = PatchIndex(points, chunk=8)
    index.tree = _SignallingTree(index.tree)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            index.query(points, 2)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert index.tree.calls == 2  # 8 chunks; the interrupt acted after the second


def test_oversized_exemplar_is_refused_up_front_with_the_figure(tmp_path, monkeypatch, capsys):
    big, small = tmp_path / "big.npy", tmp_path / "small.npy"
    np.save(big, np.full((1000, 1000), 128, dtype=np.uint8))
    np.save(small, np.full((60, 60), 128, dtype=np.uint8))
    method = get_method("npmrf")
    config = method.make_config(size=8, levels=1, window=3)
    array = np.full((1000, 1000, 1), 128, dtype=np.float32)  # constant: the segmented preset
    need_big = estimate(method, config, {v: array for v in config.views})
    limit = need_big.bytes - 64 * 2**20  # well above the small run, below the big one
    monkeypatch.setattr(resources, "available_memory", lambda: limit)
    out = tmp_path / "out"
    code = cli.main(["synth", str(big), "--size", "8", "--levels", "1", "--window", "3",
                     "--quiet", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert f"needs about {resources.format_bytes(need_big.bytes)}" in lines[0]
    assert "exemplar patch tables" in lines[0]
    code = cli.main(["synth", str(small), "--size", "8", "--levels", "1", "--window", "3",
                     "--quiet", "--out", str(out)])
    assert code == 0 and (out / "volume.npy").exists()


def test_a_signal_during_a_long_search_leaves_no_lock_and_no_output(tmp_path):
    # 160 000 patches of noise: the level model's search runs for many seconds
    np.save(tmp_path / "noise.npy", np.random.default_rng(0).integers(0, 256, (402, 402), dtype=np.uint8))
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "npmrf3d", "synth", "noise.npy", "--size", "8",
                             "--levels", "1", "--window", "3", "--quiet", "--out", "run"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    lock = tmp_path / ".run.lock"
    start = time.monotonic()
    while not lock.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - start < 300
        time.sleep(0.02)
    time.sleep(2.0)  # past the patch matrix and the PCA, into the search
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert not lock.exists() and not (tmp_path / "run").exists()
    assert sorted(p.name for p in pathlib.Path(tmp_path).iterdir()) == ["noise.npy"]



def test_kopf_on_a_constant_exemplar_searches_one_distinct_neighbourhood():
    from npmrf3d.model.kopf_search import NeighbourhoodIndex as KopfIndex
    from npmrf3d.methods.kopf import kopf_synthesize

    ex = _constant(120)
    index = KopfIndex(ex, 4)
    assert index.tree.deduplicated and index.tree.distinct == 1
    found, distance = index.query(index.patches[:5])
    assert found.tolist() == [0] * 5 and np.all(distance == 0.0)
    result = kopf_synthesize(ex, size=8, window=4, levels=1, iterations=1, rng=0)
    assert np.all(result.volume == np.float32(0.5))
