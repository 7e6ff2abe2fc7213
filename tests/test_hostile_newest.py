"""Hostile round on the newest surfaces: ``npmrf3d materials`` (odd slices, crops, thresholds and
outputs), ``--out X.zarr`` on every command that makes a volume, the refusal of options a run
would not read (the command line's written options, the API's values away from the default),
and an argument no parser knows, named by its sub-command. Every refusal: exit code 2, one
line, nothing written."""

from __future__ import annotations

import os
import pathlib

import numpy as np
import pytest
from scipy import ndimage

import npmrf3d
from npmrf3d.cli import main
from npmrf3d.errors import ParameterError

from .cli_checks import COMMANDS, listing, refused_naming

QUICK = ["--size", "16", "--levels", "2", "--quiet"]
DRY = [*QUICK, "--dry-run"]


def _blobs(shape, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return ndimage.gaussian_filter(rng.random(shape), 1.5, mode="wrap")


def _labels(shape, seed=0) -> np.ndarray:
    return (_blobs(shape, seed) > 0.5).astype(np.uint8)


@pytest.fixture
def inputs(tmp_path, monkeypatch) -> pathlib.Path:
    """A working folder holding slices, crops and odd outputs (the refusals run in it)."""
    monkeypatch.chdir(tmp_path)
    np.save("grey.npy", (_blobs((32, 32), 5) * 255).astype(np.uint8))
    np.save("labels.npy", _labels((32, 32), 1))
    np.save("zero.npy", np.zeros((32, 32), np.uint8))
    np.save("one.npy", np.ones((32, 32), np.uint8))
    np.save("thin0.npy", _labels((1, 24, 24)))
    np.save("thin1.npy", _labels((24, 1, 24)))
    np.save("two.npy", _labels((2, 24, 24)))
    np.save("long.npy", _labels((16, 20, 60)))
    np.save("nan.npy", np.where(_blobs((32, 32)) > 0.5, np.nan, 1.0))
    np.save("complex.npy", _blobs((32, 32)).astype(np.complex64))
    np.save("empty.npy", np.zeros((0, 32)))
    np.save("five_axes.npy", np.zeros((4, 4, 4, 4, 4)))
    np.save("colour.npy", (np.random.default_rng(3).random((32, 32, 3)) * 255).astype(np.uint8))
    pathlib.Path("afile").write_text("x")
    pathlib.Path("afile.zarr").write_text("x")
    os.symlink("nowhere", "dangling")
    os.symlink("nowhere.zarr", "dangling.zarr")
    os.mkdir("foreign.zarr")
    pathlib.Path("foreign.zarr", "notes.txt").write_text("x")
    return tmp_path


# --- materials: odd inputs ---------------------------------------------------------------------

MATERIALS_REFUSALS = [
    (["--slices", "zero.npy,one.npy,zero.npy"], ["front slice 'zero.npy'", "one phase only", "together hold 2"]),
    (["--slices", "labels.npy,labels.npy,one.npy"], ["top slice 'one.npy'", "one phase only"]),
    (["--slices", "zero.npy,zero.npy,zero.npy"], ["one phase only (value 0)"]),
    (["zero.npy"], ["one phase only (value 0)"]),
    (["grey.npy", "--threshold", "nan"], ["--threshold", "must be auto or a number", "'nan'"]),
    (["grey.npy", "--threshold", "inf"], ["--threshold", "must be auto or a number", "'inf'"]),
    (["grey.npy", "--threshold", "1e400"], ["--threshold", "must be auto or a number"]),
    (["grey.npy", "--threshold", "0x10"], ["--threshold", "must be auto or a number"]),
    (["grey.npy", "--threshold", ""], ["--threshold", "must be auto or a number"]),
    (["grey.npy", "--threshold", "1000"], ["outside the input's values"]),
    (["thin0.npy"], ["(1, 24, 24)", "one voxel thick", "at least 16"]),
    (["thin1.npy"], ["(24, 1, 24)", "one voxel thick"]),
    (["thin0.npy", "--exemplar-kind", "volume"], ["one voxel thick"]),
    (["two.npy"], ["ambiguous", "--exemplar-kind volume"]),
    (["two.npy", "--exemplar-kind", "volume"], ["2x24x24", "too small", "at least 16"]),
    (["long.npy"], ["ambiguous", "--exemplar-kind volume"]),
    (["grey.npy", "--exemplar-kind", "volume"], ["is a 2D image", "a volume needs three axes"]),
    (["--slices", "labels.npy,labels.npy,labels.npy", "--exemplar-kind", "volume"],
     ["--exemplar-kind volume does not apply to --slices"]),
    (["--slices", "labels.npy,labels.npy"], ["--slices must name three slices"]),
    (["--slices", "labels.npy,,labels.npy"], ["--slices must name three slices"]),
    (["--slices", "labels.npy,labels.npy,labels.npy,labels.npy"], ["--slices must name three slices"]),
    (["--slices", "labels.npy,missing.npy,labels.npy"], ["'missing.npy' does not exist"]),
    (["--slices", "labels.npy,bundled:fibres48,labels.npy"], ["right slice", "is a volume"]),
    (["grey.npy", "--slices", "labels.npy,labels.npy,labels.npy"], ["INPUT or --slices, not both"]),
    (["--slices", "labels.npy,labels.npy,labels.npy", "--views", "front"], ["--views does not apply"]),
    (["nan.npy"], ["NaN or infinite"]),
    (["complex.npy"], ["must hold real numbers"]),
    (["empty.npy"], ["shape (0, 32)"]),
    (["five_axes.npy"], ["shape (4, 4, 4, 4, 4)"]),
    (["colour.npy"], ["is a colour image"]),
    (["bundled:fibres48", "--window", "5"], ["--window is an option of the 2D method", "volume-lh"]),
    (["grey.npy", "--block", "8"], ["--block"]),
    (["grey.npy", "--workers", "2"], ["--workers"]),
    (["grey.npy", "--exemplar-front", "grey.npy"], ["--exemplar-front is not used by materials"]),
    (["grey.npy", "--diffusivity", "exact"], ["--diffusivity", "invalid choice"]),
    # options a 2D run would not read are refused when written, at their defaults too
    (["grey.npy", "--stop", "0.95"], ["--stop", "--temperatures"]),
    (["grey.npy", "--max-sweeps", "30"], ["--max-sweeps", "--temperatures"]),
    (["grey.npy", "--preset", "tuned"], ["--preset", "--support is full"]),
    (["grey.npy", "--inherit", "resynth"], ["--inherit"]),
]


@pytest.mark.parametrize("args, words", MATERIALS_REFUSALS)
def test_materials_refuses_odd_inputs(inputs, capsys, args, words):
    refused_naming(["materials", *args, *QUICK, "--out", "run"], inputs, capsys, words=words,
                   not_words=("Traceback",))


@pytest.mark.parametrize("size, words", [
    ("100000", ["needs about", "PiB", "are available", "lower --size"]),
    ("4096", ["needs about", "TiB", "are available"]),
])
@pytest.mark.parametrize("source", ["grey.npy", "bundled:fibres48"])
def test_materials_refuses_a_huge_size_up_front_with_the_figure(inputs, capsys, size, words, source):
    refused_naming(["materials", source, "--size", size, "--levels", "2", "--quiet", "--out", "run"],
                   inputs, capsys, words=words)


@pytest.mark.parametrize("out, words", [
    ("afile", ["'afile' exists and is not a folder"]),
    ("afile/sub", ["cannot be created", "is not a folder"]),
    ("dangling", ["symbolic link to 'nowhere'", "does not exist"]),
    ("", ["--out must name a folder"]),
    ("/dev/null", ["exists and is not a folder"]),
    ("x.zarr", ["must not end in .zarr"]),
    ("x.ZARR", ["must not end in .zarr"]),
    ("x.zarr/", ["must not end in .zarr"]),
    ("foreign.zarr", ["must not end in .zarr"]),
])
def test_materials_refuses_odd_output_targets(inputs, capsys, out, words):
    refused_naming(["materials", "grey.npy", *QUICK, "--out", out], inputs, capsys, words=words)


def test_materials_refuses_a_checkpoint_that_is_its_output(inputs, capsys):
    refused_naming(["materials", "grey.npy", *QUICK, "--out", "cp", "--checkpoint", "cp"], inputs, capsys,
                   words=["--checkpoint 'cp' is the output"])


def _report(out: pathlib.Path) -> dict:
    import json

    return json.loads((out / "materials.json").read_text())


def test_materials_runs_slices_of_different_sizes_and_non_square(inputs, capsys):
    np.save("f.npy", _labels((16, 16), 1))
    np.save("r.npy", _labels((24, 20), 2))
    np.save("t.npy", _labels((20, 28), 3))
    assert main(["materials", "--slices", "f.npy,r.npy,t.npy", *QUICK, "--out", "slices"]) == 0
    assert _report(inputs / "slices")["input"]["kind"] == "slices"
    np.save("wide.npy", _labels((16, 40), 4))
    assert main(["materials", "wide.npy", *QUICK, "--out", "wide"]) == 0
    assert np.load(inputs / "wide" / "volume.npy").shape == (16, 16, 16, 1)


def test_materials_keeps_five_phases_and_their_values(inputs):
    five = (np.digitize(_blobs((32, 32), 4), [0.44, 0.48, 0.52, 0.56]) * 10).astype(np.int16)
    np.save("five.npy", five)
    assert main(["materials", "five.npy", *QUICK, "--out", "five"]) == 0
    volume = np.load(inputs / "five" / "volume.npy")
    assert volume.dtype == np.int16 and set(np.unique(volume)) <= {0, 10, 20, 30, 40}
    assert _report(inputs / "five")["input"]["values"] == [0, 10, 20, 30, 40]


def test_materials_thresholds_a_grey_slice_and_reads_an_elongated_crop_when_told(inputs):
    assert main(["materials", "grey.npy", "--threshold", "128", *QUICK, "--out", "grey"]) == 0
    assert _report(inputs / "grey")["input"]["values"] == [0, 1]
    assert main(["materials", "long.npy", "--exemplar-kind", "volume", *QUICK, "--out", "long"]) == 0
    assert _report(inputs / "long")["method"] == "volume-lh"


# --- --out X.zarr on every command that makes a volume -----------------------------------------

ODD_ZARR = [
    ("afile.zarr", ["'afile.zarr' exists and is not a folder"]),
    ("afile.zarr/v.zarr", ["cannot be created", "is not a folder"]),
    ("dangling.zarr", ["symbolic link to 'nowhere.zarr'"]),
    ("foreign.zarr", ["not a Zarr volume of npmrf3d", "left untouched"]),
]


@pytest.mark.parametrize("out, words", ODD_ZARR)
@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_refuses_odd_zarr_targets(inputs, capsys, name, out, words):
    refused_naming([*COMMANDS[name], *QUICK, "--out", out], inputs, capsys, words=words)
    assert (inputs / "foreign.zarr" / "notes.txt").read_text() == "x"


@pytest.mark.parametrize("name", ["volume", "volume-npmrf"])
def test_a_3d_commands_zarr_volume_is_judged_as_a_volume_not_a_run_folder(inputs, capsys, name):
    out = "v.zarr"
    assert main([*COMMANDS[name], *QUICK, "--out", out]) == 0
    refused_naming([*COMMANDS[name], *QUICK, "--out", out], inputs, capsys,
                   words=["already holds the volume of this run", "--overwrite"], not_words=["run (preview.png)"])
    refused_naming([*COMMANDS[name], *QUICK, "--out", out, "--seed", "5"], inputs, capsys,
                   words=["another seed (0, this run: 5)"])
    other = "volume-npmrf" if name == "volume" else "volume"
    refused_naming([*COMMANDS[other], *QUICK, "--out", out], inputs, capsys, words=["another method"])


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_a_zarr_dry_run_writes_nothing(inputs, capsys, name):
    before = listing(inputs)
    assert main([*COMMANDS[name], *DRY, "--out", "dry.zarr"]) == 0
    assert listing(inputs) == before


@pytest.mark.parametrize("name, option", [
    ("volume", ["--block", "8"]), ("volume-npmrf", ["--workers", "2"]), ("kopf", ["--scheduler", "local"]),
    ("synth", ["--bogus"]),
])
def test_an_unknown_argument_is_refused_by_its_command(inputs, capsys, name, option):
    refused_naming([*COMMANDS[name], *QUICK, "--out", "v.zarr", *option], inputs, capsys,
                   words=[f"npmrf3d {name}: error: unrecognized arguments: {option[0]}", f"'npmrf3d {name} --help'"])


@pytest.mark.parametrize("name, option, words", [
    ("chen-wang", ["--block", "8"], ["--block", "add --blockwise"]),
    ("coherent", ["--workers", "2"], ["--workers", "add --blockwise"]),
    ("coherent", ["--scheduler", "tcp://nowhere:1"], ["--scheduler", "add --blockwise"]),
    ("chen-wang", ["--block", "0"], ["--block", "positive integer"]),
])
def test_block_options_without_blocks_are_refused(inputs, capsys, name, option, words):
    refused_naming([*COMMANDS[name], *QUICK, "--out", "v.zarr", *option], inputs, capsys, words=words)


# --- options a run would not read ---------------------------------------------------------------

@pytest.mark.parametrize("argv, words", [
    (["synth", "--stop", "0.95"], ["--stop", "--temperatures"]),
    (["synth", "--t0", "1.0"], ["--t0", "--relaxation is anneal"]),
    (["coherent", "--xi", "-1"], ["--xi", "--icm is set"]),
    (["coherent", "--iterations", "4", "--icm"], ["--iterations", "--icm is not set"]),
    (["coherent", "--pilot", "64"], ["--pilot", "--blockwise"]),
    (["chen-wang", "--coherence-bias", "0"], ["--coherence-bias", "--global-share is above 0"]),
    (["kopf", "--histogram-bins", "16", "--histogram-weight", "0"], ["--histogram-bins", "--histogram-weight"]),
    (["baseline", "kopf", "--histogram-bins", "16", "--histogram-weight", "0"], ["--histogram-bins"]),
    (["volume", "bundled:fibres48", "--angle", "180"], ["--angle turns only"]),
])
def test_an_option_written_that_the_run_would_not_read_is_refused(inputs, capsys, argv, words):
    refused_naming([*argv, *DRY, "--out", "run"], inputs, capsys, words=words)


@pytest.mark.parametrize("function, options, words", [
    ("kopf_synthesize", {"histogram_weight": 0.0, "histogram_bins": 8}, ["histogram_bins", "histogram_weight"]),
    ("coherent_synthesize", {"xi": -2.0}, ["xi", "icm"]),
    ("chen_wang_synthesize", {"coherence_bias": 0.5}, ["coherence_bias", "global_share"]),
    ("npmrf_synthesize", {"stop": 0.5}, ["stop"]),
    ("volume_synthesize", {"angle": 90.0}, ["angle"]),
    ("npmrf_volume_synthesize", {"angle": 90.0}, ["angle"]),
])
def test_the_api_refuses_a_value_away_from_the_default_that_the_run_would_not_read(function, options, words):
    exemplar = _load_volume() if "volume" in function else npmrf3d.load_exemplar(npmrf3d.data.path("gravel64"))
    with pytest.raises(ParameterError) as caught:
        getattr(npmrf3d, function)(exemplar, size=16, levels=2, **options)
    message = str(caught.value)
    assert "\n" not in message and all(w in message for w in words), message


def _load_volume() -> np.ndarray:
    from npmrf3d.io import read_array

    return read_array(npmrf3d.data.path("fibres48"))


def test_the_api_accepts_an_inapplicable_option_at_its_default():
    config = npmrf3d.get_method("kopf").make_config(size=16, levels=2, histogram_weight=0.0, histogram_bins=16)
    assert config.histogram_weight == 0.0
