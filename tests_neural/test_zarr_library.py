"""``neural.write_zarr`` called from Python: the same executor as the command line's Zarr runs
(``npmrf3d.io.zarr_blocks.write_volume``), so a volume replaced with ``overwrite=True`` stays
until the new one is complete, and an interrupted or failed run leaves nothing it cannot resume."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from npmrf3d.methods import neural
from npmrf3d.methods.neural import zarr_volume
from tests_neural.helpers import random_model


@pytest.fixture
def model_file(tmp_path):
    path = tmp_path / "m.pt"
    neural.save_model(random_model(16, scales=3, channel_step=2, noise_channels=2), path)
    return path


def _old_volume(model_file, out):
    """A finished 16^3 volume at ``out``; its values."""
    summary = neural.write_zarr(model_file, out, size=16, block=16, workers=1)
    assert summary == {"blocks": 1, "skipped": 0, "written": 1}
    return np.asarray(zarr.open_array(out, mode="r")[...])


def _keeps(out, values):
    array = zarr.open_array(out, mode="r")
    assert array.shape == values.shape and list(array.attrs["npmrf3d_size"]) == [16, 16, 16]
    np.testing.assert_array_equal(array[...], values)


def test_an_interrupted_overwrite_keeps_the_old_volume_and_the_same_call_resumes(tmp_path, model_file):
    out = tmp_path / "v.zarr"
    old = _old_volume(model_file, out)

    def interrupt(done, total):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        neural.write_zarr(model_file, out, size=(32, 32, 16), block=16, workers=1, overwrite=True,
                          progress=interrupt)
    _keeps(out, old)
    summary = neural.write_zarr(model_file, out, size=(32, 32, 16), block=16, workers=1, overwrite=True)
    assert summary == {"blocks": 4, "skipped": 2, "written": 2}
    expected = neural.generate(neural.load_model(model_file), (0, 0, 0), (32, 32, 16))
    np.testing.assert_array_equal(zarr.open_array(out, mode="r")[...], expected)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.pt", "v.zarr"]


def test_a_failed_overwrite_keeps_the_old_volume_and_leaves_nothing_beside_it(tmp_path, model_file, monkeypatch):
    out = tmp_path / "v.zarr"
    old = _old_volume(model_file, out)

    def broken(model, origin, shape):
        raise RuntimeError("out of memory")

    monkeypatch.setattr(zarr_volume, "generate_block", broken)
    with pytest.raises(RuntimeError, match="out of memory"):
        neural.write_zarr(model_file, out, size=(32, 32, 16), block=16, workers=1, overwrite=True)
    _keeps(out, old)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.pt", "v.zarr"]
