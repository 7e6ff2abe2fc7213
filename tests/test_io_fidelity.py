"""Outputs keep what came in, inputs are read as image libraries read them, and the Python API
refuses a wrong keyword argument up front with one line.

Label maps keep their values through ``synth`` and the API; a colour ``volume.tif`` is a
composite hyperstack with red, green and blue colour tables; a CMYK JPEG is read as RGB; an
output path that is not a regular file is never replaced, a symbolic link is written through; a
full disk names the file; the API's keyword arguments are checked before any work.
"""

from __future__ import annotations

import errno
import os
import pathlib
import shutil

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile
from PIL import Image

import npmrf3d
from npmrf3d import _validation as check
from npmrf3d import cli, io
from npmrf3d.errors import ParameterError
from npmrf3d.io.files import atomic_write, write_json
from npmrf3d.methods import get_method
from npmrf3d.methods._api import prepare
from npmrf3d.model.exemplar import load_exemplar
from tests.cli_checks import one_line_error

TINY = ["--size", "16", "--levels", "2", "--quiet"]


def labels(side: int = 24, block: int = 3, phases: int = 2) -> np.ndarray:
    """A uint8 label map ``0 .. phases-1`` of diagonal bands of ``block`` pixels."""
    r = np.arange(side) // block
    return ((r[:, None] + r[None, :]) % phases).astype(np.uint8)


# --------------------------------------------------------------------------- label maps


def test_a_label_map_keeps_its_values_and_a_photograph_is_scaled():
    assert np.unique(load_exemplar(labels(phases=3))).tolist() == [0.0, 1.0, 2.0]
    sixteen_bit = load_exemplar(labels(phases=4).astype(np.uint16))
    assert np.unique(sixteen_bit).tolist() == [0.0, 1.0, 2.0, 3.0]
    photo = np.random.default_rng(0).integers(0, 256, (16, 16)).astype(np.uint8)
    np.testing.assert_array_equal(load_exemplar(photo)[..., 0], photo.astype(np.float32) / 255)
    binary = labels() * 255  # a mask drawn black and white: [0, 1] as before
    assert np.unique(load_exemplar(binary)).tolist() == [0.0, 1.0]
    assert check.value_scale(np.array([0, 16], np.uint8)) == 255.0


def test_synth_writes_the_label_values_of_a_label_png(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    iio.imwrite("labels.png", labels())
    assert iio.imread("labels.png").max() == 1  # stored as 0/1, not 0/255
    assert cli.main(["synth", "labels.png", *TINY, "--out", "run"]) == 0
    volume = np.load("run/volume.npy")
    assert np.unique(volume).tolist() == [0.0, 1.0]
    assert 0.3 < (volume > 0.5).mean() < 0.7
    np.testing.assert_array_equal(io.read_volume("run/volume.tif"), volume)


def test_the_api_gives_a_uint8_label_map_the_volume_of_its_values():
    lab = labels(phases=3)
    as_uint8 = npmrf3d.synthesize(lab, size=16, levels=2, rng=1).volume
    as_float = npmrf3d.synthesize(lab.astype(np.float32), size=16, levels=2, rng=1).volume
    assert set(np.unique(as_uint8).tolist()) <= {0.0, 1.0, 2.0}
    np.testing.assert_array_equal(as_uint8, as_float)


# --------------------------------------------------------------------------- colour TIFF


def test_a_colour_volume_tiff_is_a_composite_with_rgb_colour_tables(tmp_path):
    volume = np.random.default_rng(0).random((4, 5, 6, 3), dtype=np.float32)
    path = io.write_volume_tiff(tmp_path / "colour.tif", volume)
    with tifffile.TiffFile(path) as tif:
        meta = tif.imagej_metadata
        assert tif.series[0].axes == "ZCYX"
    assert meta["mode"] == "composite" and meta["channels"] == 3
    brightest = [lut[:, 255].tolist() for lut in meta["LUTs"]]
    assert brightest == [[255, 0, 0], [0, 255, 0], [0, 0, 255]]
    assert tuple(meta["Ranges"]) == (0.0, 1.0) * 3
    np.testing.assert_array_equal(io.read_volume(path), volume)

    grey = io.write_volume_tiff(tmp_path / "grey.tif", volume[..., :1])
    with tifffile.TiffFile(grey) as tif:
        assert tif.imagej_metadata.get("mode", "grayscale") == "grayscale"
        assert "LUTs" not in tif.imagej_metadata


# --------------------------------------------------------------------------- CMYK JPEG


def test_a_cmyk_jpeg_is_read_as_rgb_as_pillow_converts_it(tmp_path):
    rgb = (np.random.default_rng(1).random((16, 16, 3)) * 255).astype(np.uint8)
    path = tmp_path / "cmyk.jpg"
    Image.fromarray(rgb).convert("CMYK").save(path)
    with Image.open(path) as image:
        assert image.mode == "CMYK"
        expected = np.asarray(image.convert("RGB"))
    np.testing.assert_array_equal(io.read_array(path), expected)
    exemplar = load_exemplar(path)
    assert exemplar.shape == (16, 16, 3)
    np.testing.assert_array_equal(exemplar, expected.astype(np.float32) / 255)


# --------------------------------------------------------------------------- output paths


def test_what_is_not_a_regular_file_is_never_replaced(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(ParameterError, match=r"'.*fifo' is a FIFO, not a regular file"):
        write_json(fifo, {"a": 1})
    assert fifo.is_fifo()
    device = tmp_path / "device"
    device.symlink_to(os.devnull)  # through a link: what it points to is checked
    with pytest.raises(ParameterError, match="is a character device, not a regular file"):
        atomic_write(device, lambda tmp: tmp.write_text("x"))
    assert device.is_symlink() and pathlib.Path(os.devnull).is_char_device()
    with pytest.raises(ParameterError, match="is a folder, not a regular file"):
        write_json(tmp_path, {"a": 1})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["device", "fifo"]


def test_a_symbolic_link_is_written_through(tmp_path):
    target = tmp_path / "data" / "target.json"
    target.parent.mkdir()
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    assert write_json(link, {"a": 1}) == link
    assert link.is_symlink() and link.resolve() == target.resolve()
    assert target.read_text() == '{\n  "a": 1\n}\n'
    assert sorted(p.name for p in target.parent.iterdir()) == ["target.json"]


def test_report_overwrite_refuses_a_fifo(tmp_path, capsys, monkeypatch):
    study = tmp_path / "res" / "demo"
    study.mkdir(parents=True)
    (study / "results.csv").write_text(
        "study,run_id,exemplar,method,algorithm,seed,size,levels,status,seconds,mean_histogram_kl\n"
        "demo,a,e,m,npmrf,0,8,1,done,1.5,0.25\n", encoding="utf-8")
    fifo = tmp_path / "page.html"
    os.mkfifo(fifo)
    monkeypatch.chdir(tmp_path)
    line = one_line_error(["report", str(study), "--out", str(fifo), "--overwrite"], tmp_path,
                          capsys)
    assert "is a FIFO, not a regular file" in line
    assert fifo.is_fifo()


# --------------------------------------------------------------------------- messages


def test_a_full_disk_names_the_file_and_says_to_free_space(tmp_path, capsys, monkeypatch):
    iio.imwrite(tmp_path / "labels.png", labels())
    monkeypatch.chdir(tmp_path)

    def short_write(file, array, **kwargs):  # what numpy's tofile says when the disk fills
        pathlib.Path(file).write_bytes(b"\x93NUMPY")
        raise OSError("32768 requested and 5088 written")

    monkeypatch.setattr("numpy.save", short_write)
    monkeypatch.setattr("npmrf3d.io.files.shutil.disk_usage",
                        lambda path: shutil._ntuple_diskusage(100, 100, 0))
    line = one_line_error(["synth", "labels.png", *TINY, "--out", "run"], tmp_path, capsys)
    assert "volume.npy'" in line and "No space left on device" in line
    assert "requested" not in line and "free some space" in line


def test_a_positional_exemplar_beside_one_per_view_is_refused(tmp_path, capsys, monkeypatch):
    iio.imwrite(tmp_path / "a.png", labels())
    monkeypatch.chdir(tmp_path)
    views = [arg for v in ("front", "right", "top") for arg in (f"--exemplar-{v}", "a.png")]
    line = one_line_error(["synth", "a.png", *views, *TINY], tmp_path, capsys)
    assert "exemplar 'a.png' is not used" in line and "front, right, top" in line
    with pytest.raises(ParameterError, match="is not used"):
        npmrf3d.synthesize(labels(), exemplars={"front": labels()}, views="front", size=8,
                           levels=1, window=3)


@pytest.mark.parametrize("command", [["synth"], ["neural", "train", "--out", "m.pt"]])
def test_the_default_exemplar_not_written_is_not_refused_as_unused(command, tmp_path, monkeypatch):
    from npmrf3d.cli._common import view_sources
    from npmrf3d.cli._options import given_options
    from npmrf3d.cli.main import build_parser

    iio.imwrite(tmp_path / "a.png", labels())
    monkeypatch.chdir(tmp_path)
    views = [arg for v in ("front", "right", "top") for arg in (f"--exemplar-{v}", "a.png")]
    argv = [*command, *views]
    args = build_parser().parse_args(argv)
    args.given = given_options(build_parser(), argv)
    exemplar, per_view, _ = view_sources(args)
    assert exemplar is None and sorted(per_view) == ["front", "right", "top"]
    if command == ["synth"]:
        assert cli.main([*argv, *TINY, "--dry-run"]) == 0


# --------------------------------------------------------------------------- the Python API


NPMRF = get_method("npmrf")


@pytest.mark.parametrize("value", [5, "bar"])
def test_progress_must_be_callable(value):
    with pytest.raises(ParameterError, match="^progress must be a callable or None; got"):
        prepare(NPMRF, labels(), None, size=8, rng=0, options={}, progress=value)


@pytest.mark.parametrize("value", [5, b"c.npz", ""])
def test_checkpoint_must_be_a_path(value):
    with pytest.raises(ParameterError, match="^checkpoint must"):
        prepare(NPMRF, labels(), None, size=8, rng=0, options={}, checkpoint=value)


def test_exemplars_must_be_a_dict_and_a_dict_is_not_the_exemplar():
    with pytest.raises(ParameterError, match=r"^exemplars must be a dict view -> array or path"):
        npmrf3d.synthesize(size=8, levels=1, window=3, exemplars=[labels()])
    with pytest.raises(ParameterError, match=r"^exemplar is a dict \(front\); .*exemplars="):
        npmrf3d.synthesize({"front": labels()}, size=8, levels=1, window=3)


@pytest.mark.parametrize("value", ["5", True, np.bool_(True), [1.0]])
def test_real_options_refuse_what_is_not_a_number(value):
    with pytest.raises(ParameterError, match=r"^phase_weight must be a number; got"):
        npmrf3d.synthesize(labels(), size=8, levels=1, window=3, phase_weight=value)
    assert check.real("x", np.float32(0.5)) == 0.5 and check.real("x", np.int64(2)) == 2.0


def test_a_masked_exemplar_is_refused_and_the_nan_message_does_not_advise_a_mask():
    image = np.ma.masked_less(np.linspace(0, 1, 64).reshape(8, 8), 0.1)
    with pytest.raises(ParameterError, match="is a masked array with 7 masked values"):
        load_exemplar(image)
    np.testing.assert_array_equal(load_exemplar(np.ma.masked_array(labels())), load_exemplar(labels()))
    holes = np.ones((8, 8))
    holes[0, 0] = np.nan
    with pytest.raises(ParameterError, match="1 NaN or Inf values") as info:
        load_exemplar(holes)
    assert "mask" not in str(info.value)
