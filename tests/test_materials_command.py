"""``npmrf3d materials``: labels in, the same labels out, and a report whose numbers are right."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import ndimage

from npmrf3d.analysis import materials
from npmrf3d.analysis.materials_compare import materials_report, reference_along_axes
from npmrf3d.cli import main
from npmrf3d.cli.materials import MATERIALS_FILES
from npmrf3d.io.runs import RUN_FILES
from npmrf3d.model.otsu import otsu_threshold

QUICK = ["--size", "16", "--levels", "2", "--quiet"]


def _blobs(shape, seed=0, sigma=1.5):
    rng = np.random.default_rng(seed)
    return ndimage.gaussian_filter(rng.random(shape), sigma, mode="wrap")


def test_a_grey_slice_is_split_at_otsu_and_the_report_holds_its_numbers(tmp_path):
    grey = (_blobs((32, 32)) * 255).astype(np.float32)
    np.save(tmp_path / "slice.npy", grey)
    out = tmp_path / "run"
    assert main(["materials", str(tmp_path / "slice.npy"), *QUICK, "--out", str(out)]) == 0
    for name in RUN_FILES + MATERIALS_FILES:
        assert (out / name).is_file(), name
    volume = np.load(out / "volume.npy")
    assert volume.dtype == np.uint8 and volume.shape == (16, 16, 16, 1)
    assert set(np.unique(volume)) == {0, 1}
    report = json.loads((out / "materials.json").read_text())
    assert report["input"]["values"] == [0, 1] and "Otsu" in report["input"]["phases"]
    assert report["input"]["split"] == "before" and "at least 0.3" in report["input"]["split_why"]
    assert report["method"] == "npmrf"
    phase1 = report["phases"][1]
    assert phase1["volume"]["fraction"] == pytest.approx(float((volume == 1).mean()))
    assert phase1["volume"]["percolates"] == materials.percolates(volume[..., 0] == 1)
    assert phase1["input"]["fraction"] == pytest.approx(float((grey > otsu_threshold(grey)).mean()))
    assert phase1["compare"]["fraction"]["words"].startswith("fraction ")
    page = (out / "materials.html").read_text()
    assert "materials_two_point.png" in page and "before synthesis: minority phase" in page


def test_a_three_phase_label_image_keeps_its_three_values_and_dtype(tmp_path):
    field = _blobs((32, 32), seed=1)
    labels = np.digitize(field, np.quantile(field, [0.3, 0.65])).astype(np.uint16) * 3 + 2   # 2, 5, 8
    np.save(tmp_path / "labels.npy", labels)
    out = tmp_path / "run"
    assert main(["materials", str(tmp_path / "labels.npy"), *QUICK, "--out", str(out)]) == 0
    volume = np.load(out / "volume.npy")
    assert volume.dtype == np.uint16
    assert set(np.unique(volume)) == {2, 5, 8}
    report = json.loads((out / "materials.json").read_text())
    assert [p["value"] for p in report["phases"]] == [2, 5, 8]
    assert report["input"]["phases"].startswith("labels kept")
    assert sum(p["volume"]["fraction"] for p in report["phases"]) == pytest.approx(1.0)


def test_three_slices_and_a_crop(tmp_path):
    crop = (_blobs((24, 24, 24), seed=2) > 0.5).astype(np.uint8) * 255
    np.save(tmp_path / "crop.npy", crop)
    for view, image in (("f", crop[:, :, 12]), ("r", crop[12]), ("t", crop[:, 12])):
        np.save(tmp_path / f"{view}.npy", image)
    out = tmp_path / "slices"
    slices = ",".join(str(tmp_path / f"{v}.npy") for v in "frt")
    assert main(["materials", "--slices", slices, *QUICK, "--out", str(out)]) == 0
    report = json.loads((out / "materials.json").read_text())
    assert report["input"]["kind"] == "slices" and set(np.unique(np.load(out / "volume.npy"))) == {0, 255}
    out = tmp_path / "crop"
    assert main(["materials", str(tmp_path / "crop.npy"), *QUICK, "--out", str(out)]) == 0
    report = json.loads((out / "materials.json").read_text())
    assert report["method"] == "volume-lh" and report["input"]["kind"] == "crop"
    assert report["phases"][1]["input"]["diffusivity"] == pytest.approx(
        [materials.relative_diffusivity(crop == 255, axis=a) for a in range(3)])


def test_the_slices_are_compared_along_the_axes_their_views_hold():
    rows = {"front": {"mean_chord": [1.0, 2.0], "fraction": 0.5}, "right": {"mean_chord": [3.0, 4.0], "fraction": 0.3}}
    for stats in rows.values():
        for key in ("interface_density", "surface_stereology", "two_point", "two_point_shape",
                    "chord_distribution", "percolates"):
            stats[key] = [False, True] if key == "percolates" else [0.0, 0.0]
    ref = reference_along_axes(rows)
    # front: rows along axis 0, columns along 1; right: rows along 1, columns along 2
    assert ref["mean_chord"] == [1.0, 2.5, 4.0]
    assert ref["percolates"] == [False, True, True]
    assert ref["fraction"] == pytest.approx(0.4)


def test_percolation_on_planted_channels_is_found_per_axis():
    volume = np.zeros((20, 18, 16), dtype=np.uint8)
    volume[:, 3, 4] = 1            # a straight channel along axis 0
    volume[5, :, 10] = 1           # and one along axis 1 (touching no face along axis 2)
    assert materials.percolates(volume == 1) == [True, True, False]
    volume[7, 9, :] = 1            # now along axis 2 too
    assert materials.percolates(volume == 1) == [True, True, True]
    assert materials.percolates(volume == 0) == [True, True, True]
    report = materials_report(volume, [0, 1], inputs={"volume": volume}, diffusivity="finite-volume")
    assert report["phases"][1]["volume"]["percolates"] == [True, True, True]
    diagonal = np.zeros((16, 16, 16), dtype=bool)
    diagonal[np.arange(16), np.arange(16), 0] = True      # edge neighbours only: not face-connected
    assert materials.percolates(diagonal) == [False, False, False]


def test_diffusivity_of_empty_full_channel_and_series_volumes():
    shape = (16, 20, 18)
    assert materials.relative_diffusivity(np.zeros(shape, dtype=bool), axis=0) == 0.0
    for axis in range(3):
        assert materials.relative_diffusivity(np.ones(shape, dtype=bool), axis=axis) == pytest.approx(1.0, abs=1e-6)
    channels = np.zeros(shape, dtype=bool)
    channels[:, 2, 3] = channels[:, 10, 11] = channels[:, 15, 4:7] = True
    assert materials.relative_diffusivity(channels, axis=0) == pytest.approx(channels.mean(), rel=1e-6)
    assert materials.relative_diffusivity(channels, axis=1) == 0.0
    # a path of 17 voxels in series over a length of 16: D = 16 / (17 * cross-section)
    step = np.zeros(shape, dtype=bool)
    step[:8, 5, 5] = True
    step[7:, 5, 6] = True
    assert materials.relative_diffusivity(step, axis=0) == pytest.approx(16 / (17 * 20 * 18), rel=1e-6)


@pytest.mark.parametrize("args, message", [
    (["--threshold", "300"], "outside the input's values"),
    (["--threshold", "many"], "--threshold must be auto or a number"),
    (["--out", "x.zarr"], "must not end in .zarr"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, args, message):
    grey = (_blobs((32, 32)) * 255).astype(np.uint8)
    np.save(tmp_path / "slice.npy", grey)
    out = tmp_path / "run"
    argv = ["materials", str(tmp_path / "slice.npy"), *QUICK, *(args if "--out" in args else [*args, "--out", str(out)])]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and err[0].startswith("npmrf3d: error:")
    assert not out.exists() and not (tmp_path / "x.zarr").exists()


def test_colour_one_phase_and_tiny_crops_are_refused(tmp_path, capsys):
    rng = np.random.default_rng(3)
    cases = {"colour.npy": (rng.random((32, 32, 3)) * 255).astype(np.uint8),
             "flat.npy": np.full((32, 32), 7, dtype=np.uint8),
             "tiny.npy": (rng.random((12, 12, 12)) > 0.5).astype(np.uint8)}
    expected = {"colour.npy": "is a colour image", "flat.npy": "one phase only", "tiny.npy": "too small"}
    for name, array in cases.items():
        np.save(tmp_path / name, array)
        out = tmp_path / f"run-{name}"
        assert main(["materials", str(tmp_path / name), *QUICK, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and expected[name] in err[0], err
        assert not out.exists()


def _minority_slice(seed=4, share=0.15):
    """A grey uint8 slice whose bright phase (Otsu's) holds about ``share`` of the pixels."""
    field = _blobs((32, 32), seed=seed)
    noise = np.random.default_rng(seed).random((32, 32))
    bright = field > np.quantile(field, 1 - share)
    return np.where(bright, 170 + 60 * noise, 40 + 60 * noise).astype(np.uint8)


def test_a_small_minority_phase_is_split_after_synthesis_as_synth_makes_it(tmp_path, capsys):
    grey = _minority_slice()
    np.save(tmp_path / "slice.npy", grey)
    out = tmp_path / "run"
    assert main(["materials", str(tmp_path / "slice.npy"), *QUICK[:-1], "--seed", "3", "--out", str(out)]) == 0
    assert ", 2 labels, " in capsys.readouterr().out  # the phases, not the grey levels synthesised
    report = json.loads((out / "materials.json").read_text())
    assert report["input"]["split"] == "after" and "under 0.3" in report["input"]["split_why"]
    assert json.loads((out / "run.json").read_text())["split"]["order"] == "after"
    volume = np.load(out / "volume.npy")
    assert volume.dtype == np.uint8 and set(np.unique(volume)) <= {0, 1}
    # the grey volume synth makes from the same slice and seed, split at the input's threshold
    assert main(["synth", str(tmp_path / "slice.npy"), *QUICK, "--seed", "3", "--out", str(tmp_path / "synth")]) == 0
    cut = otsu_threshold(grey)
    below = grey[grey <= cut].max() / 255.0
    synth = np.load(tmp_path / "synth" / "volume.npy")
    np.testing.assert_array_equal(volume, (synth > np.float32(below)).astype(np.uint8))
    forced = tmp_path / "before"
    assert main(["materials", str(tmp_path / "slice.npy"), *QUICK, "--seed", "3", "--split", "before",
                 "--out", str(forced)]) == 0
    report = json.loads((forced / "materials.json").read_text())
    assert report["input"]["split"] == "before" and report["input"]["split_why"].startswith("--split before")
    assert set(np.unique(np.load(forced / "volume.npy"))) <= {0, 1}


def test_split_order_follows_the_minority_share():
    from npmrf3d.cli.materials import SPLIT_AFTER_BELOW, split_order
    small = [np.zeros((10, 10), np.uint8)]
    small[0][:2] = 1                                   # 0.2 of the pixels
    assert SPLIT_AFTER_BELOW == 0.3 and split_order(small, True)[0] == "after"
    half = [np.tile(np.array([0, 1], np.uint8), (10, 5))]
    assert split_order(half, True)[0] == "before"
    assert split_order([1 - small[0]], True)[0] == split_order(small, True)[0]   # either phase the minority
    assert split_order(small, True, "before")[0] == "before" and split_order(half, True, "after")[0] == "after"
    assert split_order(small, True, crop=True)[0] == "before" and split_order(small, False)[0] == "before"


@pytest.mark.parametrize("name, message", [("labels.npy", "applies to a grey input"),
                                           ("crop.npy", "a 3D crop is split before")])
def test_split_after_is_refused_where_nothing_grey_is_split(tmp_path, capsys, name, message):
    inputs = {"labels.npy": (_blobs((32, 32)) > 0.5).astype(np.uint8) * 3,
              "crop.npy": (_blobs((20, 20, 20)) * 255).astype(np.uint8)}
    np.save(tmp_path / name, inputs[name])
    out = tmp_path / "run"
    assert main(["materials", str(tmp_path / name), *QUICK, "--split", "after", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not out.exists()
