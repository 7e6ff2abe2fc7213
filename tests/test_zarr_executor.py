"""The one executor of Zarr volumes made in blocks (``npmrf3d.io.zarr_blocks.write_volume``): the
blocks in the caller's order, the blocks made in this process with their own arguments, the first
block made here while a local cluster starts, and what each task returned for the caller to sum."""

from __future__ import annotations

import os
import sys

import numpy as np
import zarr

from npmrf3d.io.zarr_blocks import DONE, block_box, finished_blocks, write_block, write_volume

SIZE = (24, 20, 16)
BLOCK = 16
ATTRS = {"npmrf3d_run": "executor test"}


def _task(out: str, index, where: str) -> tuple:
    """Block ``index`` filled with its indices' sum plus 1; where it was made and by which process."""
    shape = block_box(index, BLOCK, SIZE)[1]
    write_block(out, index, BLOCK, np.full((*shape, 1), sum(index) + 1.0, dtype=np.float32))
    return tuple(index), where, os.getpid()


def _expected() -> np.ndarray:
    values = np.empty((*SIZE, 1), dtype=np.float32)
    for i, j, k in np.ndindex(*SIZE):
        values[i, j, k] = i // BLOCK + j // BLOCK + k // BLOCK + 1.0
    return values


def _largest_first(index) -> int:
    return -int(np.prod(block_box(index, BLOCK, SIZE)[1]))


def _write(out, **options) -> dict:
    return write_volume(out, size=SIZE, channels=1, block=BLOCK, attrs=ATTRS, task=_task, args=("worker",),
                        **options)


def test_blocks_made_here_take_their_own_arguments_in_the_callers_order_and_resume(tmp_path):
    out = tmp_path / "v.zarr"
    seen = []
    summary = _write(out, here_args=("here",), order=_largest_first, progress=lambda d, t: seen.append((d, t)))
    # the largest first: 16x16, 8x16, 16x4, 8x4 (x16), not the indices' order
    assert [r[0] for r in summary["results"]] == [(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)]
    assert {r[1] for r in summary["results"]} == {"here"} and {r[2] for r in summary["results"]} == {os.getpid()}
    assert seen == [(n, 4) for n in range(5)]
    assert (summary["blocks"], summary["skipped"], summary["written"], summary["rest_blocks"]) == (4, 0, 4, 3)
    assert summary["rest_seconds"] >= 0
    np.testing.assert_array_equal(zarr.open_array(out, mode="r")[...], _expected())
    # a block whose marker is gone is made again, alone; without here_args a block gets args
    (out / DONE / "0.1.0").unlink()
    summary = _write(out)
    assert summary["results"] == [((0, 1, 0), "worker", os.getpid())]
    assert (summary["skipped"], summary["written"], summary["rest_blocks"]) == (3, 1, 0)
    np.testing.assert_array_equal(zarr.open_array(out, mode="r")[...], _expected())


def test_the_first_block_is_made_here_while_the_cluster_makes_the_others(tmp_path):
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers cannot import a test module
    try:
        out = tmp_path / "v.zarr"
        asked = []
        summary = _write(out, here_args=("here",), workers=2, order=_largest_first,
                         first_here=lambda place: asked.append(place) or True)
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    assert [str(p) for p in asked] == [str(out)]
    first, *rest = summary["results"]
    assert first == ((0, 0, 0), "here", os.getpid())
    assert sorted(r[:2] for r in rest) == [((0, 1, 0), "worker"), ((1, 0, 0), "worker"), ((1, 1, 0), "worker")]
    assert os.getpid() not in {r[2] for r in rest}
    assert (summary["written"], summary["rest_blocks"]) == (4, 3)
    assert finished_blocks(out) == {(0, 0, 0), (0, 1, 0), (1, 0, 0), (1, 1, 0)}
    np.testing.assert_array_equal(zarr.open_array(out, mode="r")[...], _expected())
