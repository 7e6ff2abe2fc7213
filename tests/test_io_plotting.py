"""Tests for npmrf3d.io, npmrf3d.plotting and the bundled exemplars."""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pytest
import tifffile

from npmrf3d import data, io, plotting
from npmrf3d.errors import ParameterError
from npmrf3d.io import runs

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def random_volume(rng: np.random.Generator, channels: int) -> np.ndarray:
    return rng.random((4, 5, 6, channels), dtype=np.float32)


def leftovers(folder: pathlib.Path) -> list[str]:
    """Names of staging folders or temporary files left in ``folder``."""
    return sorted(p.name for p in folder.iterdir() if ".partial-" in p.name or ".tmp-" in p.name)


# --------------------------------------------------------------------------- volumes


@pytest.mark.parametrize("channels", [1, 3])
def test_volume_tiff_round_trip(tmp_path, rng, channels):
    volume = random_volume(rng, channels)
    path = io.write_volume_tiff(tmp_path / "v.tif", volume)

    with tifffile.TiffFile(path) as tif:
        assert tif.is_imagej
        series = tif.series[0]
        stored = series.asarray()
        assert series.axes == ("ZCYX" if channels > 1 else "ZYX")
    assert stored.dtype == np.float32
    assert stored.shape == ((4, channels, 5, 6) if channels > 1 else (4, 5, 6))
    np.testing.assert_array_equal(stored.reshape(4, channels, 5, 6), volume.transpose(0, 3, 1, 2))

    back = io.read_volume(path)
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, volume)
    assert leftovers(tmp_path) == []


def test_npy_round_trip(tmp_path, rng):
    volume = random_volume(rng, 2)
    np.save(tmp_path / "v.npy", volume)
    np.testing.assert_array_equal(io.read_volume(tmp_path / "v.npy"), volume)

    np.save(tmp_path / "grey.npy", volume[..., 0].astype(np.float64))
    back = io.read_volume(tmp_path / "grey.npy")
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, volume[..., :1])


def test_plain_tiff_volumes(tmp_path, rng):
    volume = random_volume(rng, 2)
    tifffile.imwrite(tmp_path / "zyxc.tif", volume, photometric="minisblack")
    tifffile.imwrite(tmp_path / "zyx.tif", volume[..., 0], photometric="minisblack")
    np.testing.assert_array_equal(io.read_volume(tmp_path / "zyxc.tif"), volume)
    np.testing.assert_array_equal(io.read_volume(tmp_path / "zyx.tif"), volume[..., :1])


def test_read_volume_rejects_a_flat_image(tmp_path, rng):
    np.save(tmp_path / "flat.npy", rng.random((5, 6)))
    message = r"flat\.npy' must hold .*\(N1, N2, N3, C\); got shape \(5, 6\)"
    with pytest.raises(ParameterError, match=message):
        io.read_volume(tmp_path / "flat.npy")


# --------------------------------------------------------------------------- read_array


def test_read_array_images(tmp_path, rng):
    import imageio.v3 as iio

    grey = rng.integers(0, 256, (7, 9), dtype=np.uint8)
    iio.imwrite(tmp_path / "g.png", grey)
    np.save(tmp_path / "g.npy", grey)
    tifffile.imwrite(tmp_path / "g.tif", grey)
    for name in ("g.png", "g.npy", "g.tif"):
        np.testing.assert_array_equal(io.read_array(tmp_path / name), grey)


def test_read_array_missing_file(tmp_path):
    with pytest.raises(ParameterError, match=r"exemplar file '.*nope\.png' does not exist"):
        io.read_array(tmp_path / "nope.png", what="exemplar file")


def test_missing_file_named_like_a_bundled_exemplar_says_how_to_name_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ParameterError, match=r"'gravel64' does not exist \(the bundled exemplar of "
                                             r"that name is 'bundled:gravel64'\)"):
        io.read_array("gravel64", what="exemplar file")


def test_read_array_directory(tmp_path):
    folder = tmp_path / "dir.png"
    folder.mkdir()
    with pytest.raises(ParameterError, match=r"dir\.png' is not a file"):
        io.read_array(folder)


@pytest.mark.parametrize("name", ["bad.png", "bad.tif", "bad.npy"])
def test_read_array_corrupt_file(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"this is not an image" * 10)
    with pytest.raises(ParameterError, match=rf"'.*{name}' cannot be read: ") as info:
        io.read_array(path)
    assert "\n" not in str(info.value)


def test_read_array_unknown_extension(tmp_path):
    path = tmp_path / "image.xyz"
    path.write_bytes(b"0")
    with pytest.raises(ParameterError, match=r"image\.xyz' has unsupported extension '\.xyz'"):
        io.read_array(path)


# --------------------------------------------------------------------------- write_run


def make_run(out_dir, rng, *, channels=1, record=None, overwrite=False):
    volume = random_volume(rng, channels)
    exemplar = volume[:, :, 0]
    return runs.write_run(
        out_dir,
        volume=volume,
        exemplars={"front": exemplar, "right": exemplar, "top": exemplar},
        record={"seed": np.int64(0), "shape": volume.shape} if record is None else record,
        overwrite=overwrite,
        title="test",
    )


def test_write_run_writes_all_files(tmp_path, rng):
    out = make_run(tmp_path / "nested" / "run", rng)
    assert sorted(p.name for p in out.iterdir()) == sorted(runs.RUN_FILES)
    assert json.loads((out / "run.json").read_text()) == {"seed": 0, "shape": [4, 5, 6, 1]}
    assert (out / "preview.png").read_bytes().startswith(PNG_SIGNATURE)
    np.testing.assert_array_equal(io.read_volume(out / "volume.tif"), np.load(out / "volume.npy"))
    assert leftovers(out.parent) == []
    assert leftovers(out) == []


def test_write_run_refuses_an_existing_run(tmp_path, rng):
    out = make_run(tmp_path / "run", rng, record={"attempt": 1})
    before = {name: (out / name).read_bytes() for name in runs.RUN_FILES}

    with pytest.raises(ParameterError, match=r"already holds a run \(volume\.npy, .*run\.json\)"):
        make_run(out, rng, record={"attempt": 2})
    assert {name: (out / name).read_bytes() for name in runs.RUN_FILES} == before

    make_run(out, rng, record={"attempt": 3}, overwrite=True)
    assert json.loads((out / "run.json").read_text()) == {"attempt": 3}
    assert leftovers(tmp_path) == []


def test_write_run_refuses_a_file(tmp_path, rng):
    target = tmp_path / "run"
    target.write_text("x")
    with pytest.raises(ParameterError, match=r"'.*run' exists and is not a folder"):
        make_run(target, rng)


def test_write_run_failure_leaves_nothing(tmp_path, rng):
    out = tmp_path / "run"
    with pytest.raises(TypeError, match="object"):
        make_run(out, rng, record={"bad": object()})
    assert list(tmp_path.iterdir()) == []


def test_write_run_failure_while_writing_leaves_nothing(tmp_path, rng, monkeypatch):
    def broken_save(fig, path):
        raise OSError("disk full")

    monkeypatch.setattr(runs.plotting, "save_figure", broken_save)
    with pytest.raises(OSError, match="disk full"):
        make_run(tmp_path / "run", rng)
    assert list(tmp_path.iterdir()) == []
    # a nested output folder: no parent folder is created either
    with pytest.raises(OSError, match="disk full"):
        make_run(tmp_path / "a" / "b" / "run", rng)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- small helpers


def test_atomic_write_cleans_up_on_error(tmp_path):
    def writer(tmp):
        tmp.write_text("partial")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError, match="boom"):
        io.atomic_write(tmp_path / "f.txt", writer)
    assert list(tmp_path.iterdir()) == []


def test_write_json_converts_numpy_and_dataclasses(tmp_path):
    from dataclasses import dataclass

    @dataclass
    class Point:
        x: float
        y: tuple[int, int]

    path = io.write_json(
        tmp_path / "a.json",
        {"p": Point(np.float32(0.5), (1, 2)), "a": np.arange(3), np.int64(7): np.bool_(True)},
    )
    assert json.loads(path.read_text()) == {"p": {"x": 0.5, "y": [1, 2]}, "a": [0, 1, 2], "7": True}


def test_checkpoint_round_trip(tmp_path, rng):
    volume = random_volume(rng, 1)
    path = io.save_checkpoint(tmp_path / "ck.npz", volume=volume, iteration=3, name="front")
    loaded = io.load_checkpoint(path)
    np.testing.assert_array_equal(loaded["volume"], volume)
    assert loaded["iteration"] == 3 and loaded["name"] == "front"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ck.npz"]
    with pytest.raises(TypeError, match="checkpoint value 'state' .* got NoneType"):
        io.save_checkpoint(tmp_path / "none.npz", state=None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ck.npz"]


def test_load_checkpoint_errors(tmp_path):
    with pytest.raises(ParameterError, match="checkpoint file .* does not exist"):
        io.load_checkpoint(tmp_path / "missing.npz")
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    with pytest.raises(ParameterError, match=r"checkpoint file '.*bad\.npz' is not a checkpoint file of npmrf3d"):
        io.load_checkpoint(tmp_path / "bad.npz")
    good = io.save_checkpoint(tmp_path / "good.npz", level=1)
    (tmp_path / "cut.npz").write_bytes(good.read_bytes()[:-40])  # one of ours, damaged
    with pytest.raises(ParameterError, match=r"checkpoint file '.*cut\.npz' cannot be read .*delete it"):
        io.load_checkpoint(tmp_path / "cut.npz")


def test_package_versions():
    versions = io.package_versions()
    for key in ("python", "numpy", "numba", "scipy", "matplotlib", "tifffile", "imageio"):
        assert isinstance(versions[key], str) and versions[key]
    assert versions["numpy"] == np.__version__
    assert {"tqdm", "npmrf3d", "platform", "cpu_count"} <= versions.keys()


# --------------------------------------------------------------------------- plotting


@pytest.mark.parametrize("channels", [1, 3, 2])
def test_preview_figure_and_save(tmp_path, rng, channels):
    volume = random_volume(rng, channels)
    exemplars = {"front": volume[:, :, 0], "right": volume[0], "top": volume[0].copy()}
    fig = plotting.preview_figure(volume, exemplars, title=f"C={channels}")
    # two distinct exemplars, three slices, the cube (+ a colour bar when C is not 1 or 3)
    assert len(fig.axes) == 6 + (channels not in (1, 3))
    assert fig.axes[1].get_title() == "exemplar (right, top)"
    path = plotting.save_figure(fig, tmp_path / "preview.png")
    assert path.read_bytes().startswith(PNG_SIGNATURE)
    assert leftovers(tmp_path) == []


def test_to_display():
    image = np.linspace(0.0, 2.0, 2 * 3 * 3, dtype=np.float32).reshape(2, 3, 3)
    rgb = plotting.to_display(image, vmin=0.0, vmax=1.0)
    assert rgb.shape == (2, 3, 3) and rgb.min() >= 0.0 and rgb.max() == 1.0
    assert plotting.to_display(image[..., :1]).shape == (2, 3)
    np.testing.assert_array_equal(plotting.to_display(np.dstack([image] * 2)), image[..., 0])


def test_plot_slices_and_cube_standalone(rng):
    volume = random_volume(rng, 1)
    slices = plotting.plot_slices(volume)
    assert [im.axes.get_title() for im in slices] == ["front  k=3", "right  i=2", "top  j=2"]
    np.testing.assert_array_equal(slices[1].get_array(), volume[2, :, :, 0])
    assert len(plotting.plot_cube(volume)) == 3


# --------------------------------------------------------------------------- bundled data

BUNDLED_SHAPES = {
    "brick": (128, 128),
    "grass": (128, 128),
    "gravel": (128, 128),
    "gravel64": (64, 64),
    "ihc": (128, 128, 3),
    "ihc64": (64, 64, 3),
}


def test_bundled_exemplars():
    assert set(BUNDLED_SHAPES) <= set(data.available())
    sources = (pathlib.Path(data.__file__).parent / "SOURCES.md").read_text()
    for name in data.available():  # every bundled file has its origin and licence written down
        assert f"`{name}.png`" in sources
    assert data.DEFAULT_EXEMPLAR in data.available()
    for name, shape in BUNDLED_SHAPES.items():
        image = io.read_array(data.path(name))
        assert image.shape == shape and image.dtype == np.uint8
    gravel = io.read_array(data.path("gravel"))
    np.testing.assert_array_equal(io.read_array(data.path("gravel64")), gravel[:64, :64])
    # the scan slices cross the 48^3 crop of the same scan at its voxel 24 (the scan's 64)
    crop = io.read_array(data.path("fibres48"))
    for view, cut in {"front": crop[:, :, 24], "right": crop[24], "top": crop[:, 24]}.items():
        np.testing.assert_array_equal(io.read_array(data.path(f"polymer_{view}"))[40:88, 40:88], cut)


def test_unknown_bundled_name():
    with pytest.raises(ParameterError, match=r"brick, grass, gravel, gravel64, .*; got .marble."):
        data.path("marble")
