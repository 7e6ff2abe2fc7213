"""3D exemplars: recognising a volume, loading .npy and TIFF stacks, refusals."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import tifffile

from npmrf3d.errors import ParameterError
from npmrf3d.model.exemplar import load_exemplar
from npmrf3d.model.exemplar3d import check_spacing, interpret, load_volume_exemplar, volume_fits


@pytest.mark.parametrize(("shape", "kind"), [
    ((20, 30), "image"), ((64, 64, 3), "image"), ((64, 64, 4), "image"), ((4, 4, 7), "image"),
    ((48, 48, 48), "volume"), ((32, 40, 60), "volume"), ((16, 16, 16, 3), "volume"),
])
def test_arrays_without_axes_are_recognised(shape, kind):
    got, array = interpret(np.zeros(shape, dtype=np.uint8))
    assert got == kind
    assert array.ndim == (3 if kind == "image" else 4)


def test_an_ambiguous_array_is_refused_naming_the_option():
    with pytest.raises(ParameterError, match=r"shape \(64, 64, 16\) is ambiguous: an image with 16 "
                                             r"channels or a volume of 64 slices; .*--exemplar-kind"):
        interpret(np.zeros((64, 64, 16)))
    assert interpret(np.zeros((64, 64, 16)), kind="image")[1].shape == (64, 64, 16)
    assert interpret(np.zeros((64, 64, 16)), kind="volume")[1].shape == (64, 64, 16, 1)
    with pytest.raises(ParameterError, match="exemplar_kind must be one of auto, image, volume; got 'cube'"):
        interpret(np.zeros((8, 8)), kind="cube")


def test_a_2d_method_refuses_a_volume_and_a_3d_method_an_image():
    with pytest.raises(ParameterError, match=r"shape \(48, 48, 48\) is a volume .*npmrf3d volume .*"
                                             r"--exemplar-kind image"):
        load_exemplar(np.zeros((48, 48, 48), dtype=np.float32))
    assert load_exemplar(np.zeros((48, 48, 48)), exemplar_kind="image").shape == (48, 48, 48)
    with pytest.raises(ParameterError, match=r"is a 2D image, and this method needs a volume"):
        load_volume_exemplar(np.zeros((64, 64, 3), dtype=np.uint8))
    with pytest.raises(ParameterError, match=r"shape \(8, 8\) is a 2D image; a volume needs three axes"):
        load_volume_exemplar(np.zeros((8, 8)), exemplar_kind="volume")


@pytest.mark.parametrize(("dtype", "scale"), [(np.uint8, 255.0), (np.uint16, 65535.0), (np.float64, 1.0)])
def test_volume_dtypes_are_scaled_as_images_are(rng, dtype, scale):
    raw = (rng.random((16, 17, 18)) * (scale if scale > 1 else 7.0)).astype(dtype)
    out = load_volume_exemplar(raw)
    assert out.dtype == np.float32 and out.shape == (16, 17, 18, 1)
    np.testing.assert_allclose(out[..., 0], raw / scale, rtol=1e-6)


def test_volume_with_nan_or_strings_is_refused():
    bad = np.zeros((16, 16, 16), dtype=np.float32)
    bad[1, 2, 3] = np.nan
    with pytest.raises(ParameterError, match="contains 1 NaN or Inf values"):
        load_volume_exemplar(bad)
    with pytest.raises(ParameterError, match="must hold numbers"):
        load_volume_exemplar(np.full((16, 16, 16), "a"))


def test_npy_and_tiff_stacks_load_as_volumes(tmp_path, rng):
    grey = (rng.random((18, 20, 22)) * 255).astype(np.uint8)
    colour = (rng.random((18, 20, 22, 3)) * 65535).astype(np.uint16)
    np.save(tmp_path / "crop.npy", grey)
    tifffile.imwrite(tmp_path / "fiji.tif", grey, imagej=True, metadata={"axes": "ZYX"})
    tifffile.imwrite(tmp_path / "pages.tif", grey)  # plain multi-page TIFF: one page per slice
    tifffile.imwrite(tmp_path / "hyper.tif", np.ascontiguousarray(colour.transpose(0, 3, 1, 2)),
                     imagej=True, metadata={"axes": "ZCYX"})
    tifffile.imwrite(tmp_path / "rgbpages.tif", colour, photometric="rgb")
    for name in ("crop.npy", "fiji.tif", "pages.tif"):
        out = load_volume_exemplar(tmp_path / name)
        np.testing.assert_allclose(out[..., 0], grey / 255.0, rtol=1e-6, err_msg=name)
    for name in ("hyper.tif", "rgbpages.tif"):
        out = load_volume_exemplar(tmp_path / name)
        np.testing.assert_allclose(out, colour / 65535.0, rtol=1e-6, err_msg=name)
    # the same stacks given to a 2D method are refused, not read as 18 channels
    with pytest.raises(ParameterError, match="is a volume"):
        load_exemplar(tmp_path / "pages.tif")


def test_imagej_channels_are_channels_unless_a_volume_is_asked_for(tmp_path, rng):
    data = (rng.random((6, 20, 22)) * 255).astype(np.uint8)
    tifffile.imwrite(tmp_path / "channels.tif", data, imagej=True)  # tifffile: axes CYX
    assert load_exemplar(tmp_path / "channels.tif").shape == (20, 22, 6)
    assert load_volume_exemplar(tmp_path / "channels.tif", exemplar_kind="volume").shape == (6, 20, 22, 1)


def test_anisotropic_spacing_is_refused_with_the_resampling(tmp_path, rng):
    assert check_spacing((0.5, 0.5, 0.502)) == (0.5, 0.5, 0.502)
    with pytest.raises(ParameterError, match=r"spacing \(2.0, 1.0, 1.0\) \(z, y, x\) is anisotropic.*"
                                             r"zoom\(volume, \(2.0, 1.0, 1.0\)"):
        check_spacing((2, 1, 1))
    with pytest.raises(ParameterError, match="spacing must be a finite number"):
        check_spacing((1, 0, 1))
    data = (rng.random((16, 16, 16)) * 255).astype(np.uint8)
    tifffile.imwrite(tmp_path / "aniso.tif", data, imagej=True, resolution=(1.0, 1.0),
                     metadata={"axes": "ZYX", "spacing": 3.0})
    with pytest.raises(ParameterError, match="voxel spacing recorded in exemplar .* is anisotropic"):
        load_volume_exemplar(tmp_path / "aniso.tif")
    assert load_volume_exemplar(tmp_path / "aniso.tif", spacing=1.0).shape == (16, 16, 16, 1)


def test_a_volume_smaller_than_the_window_is_refused():
    with pytest.raises(ParameterError, match="exemplar of size 8x12x12 is too small for window 5"):
        volume_fits(np.zeros((8, 12, 12, 1)), window=5)


def test_the_issue_command_fails_fast_with_one_line(tmp_path):
    np.save(tmp_path / "crop.npy", np.zeros((48, 48, 48), dtype=np.float32))
    proc = subprocess.run([sys.executable, "-m", "npmrf3d", "synth", str(tmp_path / "crop.npy"),
                           "--size", "64", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "is a volume" in proc.stderr
    assert not (tmp_path / "out").exists()
