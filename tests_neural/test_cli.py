"""``npmrf3d neural train`` and ``npmrf3d neural generate`` (in memory and into Zarr on Dask)."""

from __future__ import annotations

import numpy as np
import pytest
import zarr

from npmrf3d.cli.main import main
from npmrf3d.methods import neural
from npmrf3d.methods.neural.zarr_volume import DONE

TRAIN = ["--iterations", "2", "--size", "16", "--scales", "3", "--channel-step", "2",
         "--noise-channels", "2", "--tile", "16", "--filters", "4", "--descriptor-scales", "2",
         "--filter-size", "3", "--threads", "1"]


@pytest.fixture
def model_file(tmp_path, exemplar):
    np.save(tmp_path / "ex.npy", exemplar)
    path = tmp_path / "m.pt"
    assert main(["neural", "train", str(tmp_path / "ex.npy"), "--out", str(path), "--quiet", *TRAIN]) == 0
    return path


def test_train_shows_the_loss_and_writes_a_model(tmp_path, exemplar, capsys):
    np.save(tmp_path / "ex.npy", exemplar)
    out = tmp_path / "m.pt"
    assert main(["neural", "train", str(tmp_path / "ex.npy"), "--out", str(out),
                 "--checkpoint", str(tmp_path / "c.ckpt"), *TRAIN]) == 0
    captured = capsys.readouterr()
    assert "loss=" in captured.err and "2/2" in captured.err
    assert f"wrote {out}" in captured.out and "s per step" in captured.out
    assert neural.load_model(out).config.iterations == 2
    assert main(["neural", "train", str(tmp_path / "ex.npy"), "--out", str(out), *TRAIN]) == 2
    assert "already exists; pass --overwrite" in capsys.readouterr().err
    # resuming a finished checkpoint trains nothing more and gives the same model
    assert main(["neural", "train", str(tmp_path / "ex.npy"), "--out", str(tmp_path / "again.pt"), "--quiet",
                 "--checkpoint", str(tmp_path / "c.ckpt"), *TRAIN]) == 0
    np.testing.assert_array_equal(neural.generate(neural.load_model(out), 0, 8),
                                  neural.generate(neural.load_model(tmp_path / "again.pt"), 0, 8))


@pytest.mark.parametrize("argv, message", [
    (["--iterations", "0"], "--iterations must be between 1 and"),
    (["--size", "3"], "--size must be between 8 and 1024; got 3"),
    (["--descriptor", "vgg19"], "--vgg19 must name a local VGG-19 weights file"),
])
def test_train_errors_are_one_line_and_write_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "m.pt"
    assert main(["neural", "train", "--out", str(out), *TRAIN, *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_generate_npy_and_tif(tmp_path, model_file, capsys):
    model = neural.load_model(model_file)
    out = tmp_path / "v.npy"
    assert main(["neural", "generate", str(model_file), "--size", "20,12,8", "--origin=-4,0,9",
                 "--out", str(out), "--threads", "1"]) == 0
    assert "voxels/s" in capsys.readouterr().out
    np.testing.assert_array_equal(np.load(out), neural.generate(model, (-4, 0, 9), (20, 12, 8)))
    assert main(["neural", "generate", str(model_file), "--size", "8", "--out", str(tmp_path / "v.tif"), "--quiet"]) == 0
    assert (tmp_path / "v.tif").stat().st_size > 8 ** 3 * 4


@pytest.mark.parametrize("argv, message", [
    (["--size", "0"], "--size must be >= 1; got 0"),
    (["--size", "8", "--out-suffix", ".png"], "--out must end in one of"),
    (["--size", "a"], "size must be an integer N or three comma-separated integers"),
])
def test_generate_errors_are_one_line(tmp_path, model_file, capsys, argv, message):
    suffix = ".npy"
    if "--out-suffix" in argv:
        suffix = argv[argv.index("--out-suffix") + 1]
        argv = argv[:argv.index("--out-suffix")]
    out = tmp_path / f"v{suffix}"
    assert main(["neural", "generate", str(model_file), "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_generate_zarr_on_a_local_cluster_resumes(tmp_path, model_file, capsys):
    out = tmp_path / "v.zarr"
    argv = ["neural", "generate", str(model_file), "--size", "32,32,16", "--block", "16",
            "--workers", "2", "--out", str(out)]
    assert main(argv) == 0
    assert "4 blocks written, 0 already done" in capsys.readouterr().out
    array = zarr.open_array(out, mode="r")
    assert array.shape == (32, 32, 16, 1) and array.chunks == (16, 16, 16, 1)
    expected = neural.generate(neural.load_model(model_file), (0, 0, 0), (32, 32, 16))
    np.testing.assert_array_equal(array[...], expected)
    # an interrupted run: one block lost its marker and its data; the rerun writes only that one
    (out / DONE / "1.0.0").unlink()
    zarr.open_array(out, mode="r+")[16:32, 0:16, 0:16] = 0
    assert main(argv) == 0
    assert "1 blocks written, 3 already done" in capsys.readouterr().out
    np.testing.assert_array_equal(zarr.open_array(out, mode="r")[...], expected)
    # another size into the same folder is refused
    assert main([*argv[:3], "--size", "16", "--block", "16", "--out", str(out)]) == 2
    assert "holds a volume of another size" in capsys.readouterr().err
