"""Volumes made in blocks: each block from its dependency cone equals, bit for bit, the same
part of the volume made at once (default sampler, coherent sampler and Chen–Wang; grey and
colour; 1 and 2 threads), and the Zarr writer resumes a cut-off run to the same volume."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

import npmrf3d

from npmrf3d import ParameterError
from npmrf3d._kernels import kcoherence as _k
from npmrf3d._kernels._jit import use_threads
from npmrf3d.cli.main import main
from npmrf3d.io.zarr_blocks import DONE, block_indices
from npmrf3d.methods import METHODS
from npmrf3d.methods.blocks import block_plan, make_block, synthesize_blocks, write_zarr
from npmrf3d.model.regions import plan_region
from npmrf3d.resources import ResourceError
from npmrf3d.studies.catalog import load_exemplar

from .cli_checks import refused_naming
from .naive import naive_global_flat, naive_group_by_batch, naive_sort_within_batches, naive_voxel_batches

#: A cone that is a true part of its level at the two finer levels: window 3 (reach 2), one
#: iteration per level, blocks of 16 in a 48 x 32 x 32 volume; a pilot smaller than the volume
#: (its cone is a true part of the finer levels too) and the phase control on.
SMALL = dict(size=(48, 32, 32), window=3, levels=3, iterations=1, blockwise=True, pilot=16, phase_weight=16.0,
             whole_voxels=1, seed=11)


def _exemplar(name: str) -> np.ndarray:
    """A 32 x 32 crop of a bundled exemplar: ``gravel64`` is grey, ``ihc64`` colour."""
    return np.ascontiguousarray(load_exemplar(name)[:32, :32], dtype=np.float32)


def _views(image):
    return {v: image for v in ("front", "right", "top")}


def _whole(method, per_view, config, threads):
    use_threads(threads)
    return method.run(per_view, config, np.random.default_rng(config.seed)).volume


@pytest.mark.parametrize("name", ["coherent", "chen-wang"])
@pytest.mark.parametrize("exemplar", ["gravel64", "ihc64"])
@pytest.mark.parametrize("threads", [1, 2])
def test_blocks_equal_the_volume_made_at_once(tmp_path, name, exemplar, threads):
    method = METHODS[name]
    per_view = _views(_exemplar(exemplar))
    config = method.make_config(**SMALL)
    whole = _whole(method, per_view, config, 3 - threads)
    plan = plan_region(config.size, config.levels, method.aprons(config, per_view), (16, 16, 0), (16, 16, 16))
    assert plan.frames[0].shape != plan.frames[0].extent and plan.frames[1].shape != plan.frames[1].extent
    use_threads(threads)
    blocks = synthesize_blocks(method, per_view, config, block=16, start=tmp_path / "start.npz")
    np.testing.assert_array_equal(blocks, whole)


@pytest.mark.parametrize("name", ["coherent", "chen-wang"])
def test_blocks_with_sparse_sites_equal_the_volume_made_at_once(tmp_path, name):
    """Sites every 4 voxels: a block whose region starts off the sites' lattice (at grid
    position 2 of a level) searches the whole grid's sites there."""
    method = METHODS[name]
    per_view = _views(_exemplar("gravel64"))
    config = method.make_config(**{**SMALL, "grid": 4, "window": 5})
    whole = _whole(method, per_view, config, 2)
    plan = plan_region(config.size, config.levels, method.aprons(config, per_view), (16, 16, 0), (16, 16, 16))
    assert any(o % 4 for frame in plan.frames if frame is not None for o in frame.origin)
    blocks = synthesize_blocks(method, per_view, config, block=16, start=tmp_path / "start.npz")
    np.testing.assert_array_equal(blocks, whole)


def test_first_site_is_the_whole_grids():
    """Along an axis, a region's search sites are the whole grid's positions that are
    multiples of the grid spacing."""
    for grid in (1, 2, 3):
        extent = np.array([12, 12, 12], dtype=np.int64)
        for o in range(12):
            origin = np.array([o, 0, 0], dtype=np.int64)
            first = _k.first_site(origin, extent, 0, grid)
            sites = list(range(first, 7, grid))
            assert sites == [i for i in range(7) if (o + i) % 12 % grid == 0]
        assert _k.first_site(origin, np.zeros(3, dtype=np.int64), 0, grid) == 0


@pytest.mark.parametrize("name", ["coherent", "chen-wang"])
def test_a_block_decides_at_each_pass_only_what_the_next_needs(tmp_path, name):
    """Two passes per level: a block's first pass decides its region shrunk by one reach of a
    pass, its second by two (where the region does not wrap an axis whole), and the block still
    equals the same part of the volume made at once."""
    method = METHODS[name]
    per_view = _views(_exemplar("gravel64"))
    config = method.make_config(**{**SMALL, "iterations": 2})
    whole = _whole(method, per_view, config, 2)
    plan = plan_region(config.size, config.levels, method.aprons(config, per_view), (16, 16, 0), (16, 16, 16),
                       start=tmp_path / "s.npz")
    run = method.run(per_view, config, np.random.default_rng(config.seed), region=plan)
    np.testing.assert_array_equal(run.volume, whole[16:32, 16:32, :16])
    frame = plan.frames[0]
    finest = run.stats["levels"]["level_0"]
    assert finest["shape"] == list(frame.shape)
    reach = 2  # window 3
    shrunk = [[n if n == e else n - 2 * t * reach for n, e in zip(frame.shape, frame.extent)] for t in (1, 2)]
    assert finest["voxels_decided"] == sum(int(np.prod(s)) for s in shrunk) < 2 * int(np.prod(frame.shape))


def test_the_apron_is_needed_in_full(tmp_path):
    """One voxel less of apron at the finest level and a block differs from the whole volume:
    the test above could fail."""
    method = METHODS["coherent"]
    per_view = _views(_exemplar("gravel64"))
    config = method.make_config(**{**SMALL, "window": 5})
    whole = _whole(method, per_view, config, 2)
    aprons = method.aprons(config, per_view)
    short = (aprons[0] - 2, *aprons[1:])  # regions are rounded to even sides: two voxels less
    plan = plan_region(config.size, config.levels, short, (16, 0, 0), (16, 16, 16), start=tmp_path / "s.npz")
    block = method.run(per_view, config, np.random.default_rng(config.seed), region=plan).volume
    assert not np.array_equal(block, whole[16:32, :16, :16])
    exact = make_block(method, per_view, config, (16, 0, 0), (16, 16, 16), tmp_path / "s.npz")
    np.testing.assert_array_equal(exact, whole[16:32, :16, :16])


@pytest.mark.parametrize("exemplar", ["gravel64", "ihc64"])
def test_the_default_sampler_blockwise_in_blocks(tmp_path, exemplar):
    method = METHODS["npmrf"]
    per_view = _views(_exemplar(exemplar))
    config = method.make_config(size=(32, 32, 32), window=3, levels=2, blockwise=True, whole_voxels=1, seed=4)
    whole = _whole(method, per_view, config, 2)
    np.testing.assert_array_equal(synthesize_blocks(method, per_view, config, block=16, start=tmp_path / "s.npz"),
                                  whole)


def test_blockwise_keeps_the_exemplar_colours_and_differs_from_the_seedless_run(tmp_path):
    method = METHODS["coherent"]
    image = _exemplar("ihc64")
    config = method.make_config(**SMALL)
    volume = _whole(method, _views(image), config, 2)
    colours = {tuple(c) for c in image.reshape(-1, 3).tolist()}
    assert {tuple(c) for c in volume.reshape(-1, 3).tolist()} <= colours
    other = _whole(method, _views(image), method.make_config(**{**SMALL, "seed": 12}), 2)
    assert not np.array_equal(volume, other)


def test_global_flat_matches_its_twin():
    rng = np.random.default_rng(0)
    for _ in range(50):
        extent = rng.integers(1, 9, 3)
        shape = rng.integers(1, 9, 3)
        origin = rng.integers(0, 20, 3)
        p = [int(rng.integers(0, n)) for n in shape]
        for e in (extent, np.zeros(3, dtype=np.int64)):
            got = _k.global_flat(p[0], p[1], p[2], tuple(int(n) for n in shape), origin.astype(np.int64),
                                 e.astype(np.int64))
            assert got == naive_global_flat(p, shape, origin, e)


def test_grouping_by_batch_matches_its_twin():
    rng = np.random.default_rng(4)
    for batches in (1, 3, 8, 300):
        ids = rng.integers(-1, batches, size=int(rng.integers(0, 500))).astype(np.int16)
        order, bounds = np.empty(ids.size, dtype=np.int64), np.empty(batches + 1, dtype=np.int64)
        _k.group_by_batch(ids, batches, order, bounds)
        want_order, want_bounds = naive_group_by_batch(ids, batches)
        np.testing.assert_array_equal(bounds, want_bounds)
        np.testing.assert_array_equal(order[:bounds[-1]], want_order)


def test_sorting_within_batches_matches_its_twin():
    """Batches of a permutation of every index, and of a part of them (ICM's visits)."""
    rng = np.random.default_rng(5)
    for n, kept, batches in ((1000, 1000, 8), (500, 321, 3), (7, 7, 7), (10, 0, 1)):
        order = rng.permutation(n)[:kept].astype(np.int64)
        bounds = np.linspace(0, kept, batches + 1).astype(np.int64)
        want = naive_sort_within_batches(order, bounds)
        _k.sort_within_batches(order, bounds, n)
        np.testing.assert_array_equal(order, want)


def test_voxel_batches_match_their_twin():
    rng = np.random.default_rng(3)
    for _ in range(4):
        shape = tuple(int(n) for n in rng.integers(1, 7, 3))
        extent = np.array([n + int(rng.integers(0, 4)) for n in shape], dtype=np.int64)
        origin = rng.integers(0, extent).astype(np.int64)
        salt, batches = int(rng.integers(0, 2**31)), int(rng.choice([1, 3, 8, 1024]))
        lo = np.array([int(rng.integers(0, n)) for n in shape], dtype=np.int64)
        hi = np.array([int(rng.integers(a, n + 1)) for a, n in zip(lo, shape)], dtype=np.int64)
        for o, e in ((origin, extent), (np.zeros(3, np.int64), np.zeros(3, np.int64))):
            got = np.empty(shape, dtype=np.int16)
            _k.voxel_batches(np.array(shape, dtype=np.int64), o, e, salt, batches, lo, hi, got)
            np.testing.assert_array_equal(got, naive_voxel_batches(shape, o, e, salt, batches, lo, hi))


def test_a_region_draws_the_batches_of_the_whole_grid():
    """The batches of a region (toroidal, across the grid's edge) are the whole grid's there,
    and every batch holds about its share."""
    extent = np.array([12, 10, 8], dtype=np.int64)
    whole = np.empty(tuple(extent), dtype=np.int16)
    _k.voxel_batches(extent, np.zeros(3, np.int64), extent, 77, 8, np.zeros(3, np.int64), extent, whole)
    origin, shape = np.array([9, 3, 5], dtype=np.int64), np.array([6, 4, 7], dtype=np.int64)
    part = np.empty(tuple(shape), dtype=np.int16)
    _k.voxel_batches(shape, origin, extent, 77, 8, np.zeros(3, np.int64), shape, part)
    index = np.ix_(*[(o + np.arange(n)) % e for o, n, e in zip(origin, shape, extent)])
    np.testing.assert_array_equal(part, whole[index])
    assert np.all(np.abs(np.bincount(whole.ravel(), minlength=8) - whole.size / 8) < 0.3 * whole.size / 8)


def test_levels_that_fit_run_whole_once_and_the_blocks_still_equal(tmp_path):
    """With ``whole_voxels`` the middle level's size, the two coarsest levels run whole (in the
    shared checkpoint) and the finest in blocks: still the volume made at once."""
    method = METHODS["coherent"]
    per_view = _views(_exemplar("gravel64"))
    config = method.make_config(**{**SMALL, "whole_voxels": 24 * 16 * 16})
    assert method.aprons(config, per_view)[1:] == (None, None)
    whole = _whole(method, per_view, config, 2)
    blocks = synthesize_blocks(method, per_view, config, block=16, start=tmp_path / "start.npz")
    np.testing.assert_array_equal(blocks, whole)


def test_a_blockwise_volume_whose_levels_all_fit_is_the_default_volume():
    """At most ``whole_voxels`` voxels at the finest level: every level runs whole, as the
    default does, and ``--blockwise`` changes nothing."""
    image = _exemplar("gravel64")
    kw = dict(size=32, levels=2, window=5, rng=3)
    np.testing.assert_array_equal(npmrf3d.synthesize(image, blockwise=True, **kw).volume,
                                  npmrf3d.synthesize(image, **kw).volume)


def test_blocks_read_the_pilot(tmp_path):
    """A pilot of another size gives another volume: the blocks follow its histograms."""
    method = METHODS["coherent"]
    per_view = _views(_exemplar("gravel64"))
    volumes = [_whole(method, per_view, method.make_config(**{**SMALL, "pilot": p}), 2) for p in (16, 32)]
    assert not np.array_equal(*volumes)


def test_methods_that_cannot_run_in_blocks_say_so():
    per_view = _views(_exemplar("gravel64"))
    with pytest.raises(ParameterError, match="cannot be made in blocks"):
        block_plan(METHODS["coherent"], per_view, METHODS["coherent"].make_config(size=32, window=3), block=16)
    with pytest.raises(ParameterError, match="per-voxel temperatures"):
        METHODS["npmrf"].make_config(size=32, blockwise=True, temperatures=True)
    with pytest.raises(ParameterError, match="support 'coherent'"):
        METHODS["npmrf"].make_config(size=32, blockwise=True, support="full")


def test_a_block_that_cannot_fit_a_worker_is_refused_before_anything_is_written(tmp_path):
    method = METHODS["coherent"]
    per_view = _views(_exemplar("gravel64"))
    config = method.make_config(**SMALL)
    with pytest.raises(ResourceError, match="needs about"):
        write_zarr(method, per_view, config, tmp_path / "v.zarr", block=16, record={}, memory_per_worker=10**6)
    assert not (tmp_path / "v.zarr").exists()


SYNTH = ["synth", "bundled:gravel64", "--size", "32", "--window", "3", "--levels", "2", "--seed", "3"]


def test_synth_into_zarr_equals_the_blockwise_run_and_resumes(tmp_path, capsys):
    out = tmp_path / "v.zarr"
    argv = [*SYNTH, "--out", str(out), "--blockwise", "--whole-voxels", "1", "--block", "16", "--workers", "1"]
    assert main(argv) == 0
    said = capsys.readouterr().out
    assert "8 blocks written, 0 already done; a worker's peak memory" in said
    assert 0 < zarr.open_array(out, mode="r").attrs["npmrf3d_worker_peak_bytes"] < 4 * 2**30
    assert main([*SYNTH, "--blockwise", "--whole-voxels", "1", "--out", str(tmp_path / "whole"), "--quiet"]) == 0
    expected = np.load(tmp_path / "whole" / "volume.npy")
    array = zarr.open_array(out, mode="r")
    assert array.shape == (32, 32, 32, 1) and array.chunks == (16, 16, 16, 1)
    assert "npmrf3d_record" in array.attrs and (out / "preview.png").is_file()
    np.testing.assert_array_equal(array[...], expected)
    # a run cut off after some blocks: their markers are there, the others not
    for index in block_indices((32, 32, 32), 16)[3:]:
        (out / DONE / ".".join(map(str, index))).unlink()
    zarr.open_array(out, mode="r+")[16:, :, :] = 0.0
    # resumed on a local cluster of two workers (one worker makes every block in its own process)
    assert main([*argv[:-1], "2"]) == 0
    assert "5 blocks written, 3 already done" in capsys.readouterr().out
    np.testing.assert_array_equal(zarr.open_array(out, mode="r")[...], expected)


def test_synth_zarr_refusals(tmp_path, capsys):
    refused_naming([*SYNTH, "--scheduler", "tcp://127.0.0.1:1", "--out", str(tmp_path / "d")], tmp_path, capsys,
                   words=("--scheduler", ".zarr"))
    refused_naming([*SYNTH, "--out", str(tmp_path / "v.zarr"), "--blockwise", "--checkpoint", str(tmp_path / "c.npz")],
                   tmp_path, capsys, words=("--checkpoint",))
    refused_naming([*SYNTH, "--out", str(tmp_path / "v.zarr"), "--whole-voxels", "8"], tmp_path, capsys,
                   words=("--whole-voxels", "--blockwise"))
    refused_naming([*SYNTH, "--out", str(tmp_path / "v.zarr"), "--blockwise", "--temperatures"], tmp_path, capsys,
                   words=("temperatures",))
    refused_naming([*SYNTH, "--out", str(tmp_path / "v.zarr"), "--workers", "2"], tmp_path, capsys,
                   words=("--workers", "--blockwise"))
    (tmp_path / "v.zarr").mkdir()
    (tmp_path / "v.zarr" / "notes.txt").write_text("mine")
    refused_naming([*SYNTH, "--out", str(tmp_path / "v.zarr")], tmp_path, capsys, words=("not a Zarr volume",))


def test_dry_run_prints_the_block_plan(tmp_path, capsys):
    assert main([*SYNTH, "--size", "1024", "--out", str(tmp_path / "big.zarr"), "--blockwise", "--block", "256",
                 "--dry-run"]) == 0
    text = capsys.readouterr().out
    assert "64 blocks" in text and "coarsest level made once, whole" in text and "needs about" in text
    assert not (tmp_path / "big.zarr").exists()


def test_synth_into_zarr_at_once_is_the_default_volume(tmp_path, capsys):
    """Without --blockwise a Zarr --out holds the default sampler's volume, made at once."""
    assert main([*SYNTH, "--out", str(tmp_path / "v.zarr"), "--quiet"]) == 0
    assert main([*SYNTH, "--out", str(tmp_path / "run"), "--quiet"]) == 0
    np.testing.assert_array_equal(zarr.open_array(tmp_path / "v.zarr", mode="r")[...],
                                  np.load(tmp_path / "run" / "volume.npy"))
    refused_naming([*SYNTH, "--size", "4096", "--out", str(tmp_path / "huge.zarr")], tmp_path, capsys,
                   words=("needs about", "--blockwise"))
