"""A hostile round on every command and the Python API: odd option values, option combinations a
run would not read, odd inputs, odd outputs, runs racing for one output, interruptions, the API's
keywords and the other commands.

A refusal is one line ``npmrf3d...: error: ...`` on stderr, exit code 2, no traceback and
nothing new on disk (:func:`tests.cli_checks.one_line_error`); the cases are data, one list per
category, each row an argv (or a call) and what the line must say.
"""

from __future__ import annotations

import os
import pathlib
import signal
import socket
import subprocess
import sys
import time

import imageio.v3 as iio
import numpy as np
import pytest
import tifffile

import npmrf3d
from npmrf3d import ParameterError, cli
from npmrf3d.cli.main import build_parser
from tests.cli_checks import one_line_error, refused_naming

TINY = ["--size", "8", "--levels", "1", "--window", "3"]
KTINY = ["--size", "8", "--levels", "1", "--window", "4", "--iterations", "1"]
VTINY = ["--size", "8", "--levels", "1"]
DRY = ["--dry-run"]


@pytest.fixture
def place(tmp_path, monkeypatch) -> pathlib.Path:
    """A working folder holding the odd files the cases name."""
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(0)
    iio.imwrite(tmp_path / "good.png", rng.integers(0, 256, (16, 16, 3), dtype=np.uint8))
    iio.imwrite(tmp_path / "grey.png", rng.integers(0, 256, (16, 16), dtype=np.uint8))
    iio.imwrite(tmp_path / "one.png", np.zeros((1, 1), np.uint8))
    iio.imwrite(tmp_path / "two.png", np.array([[0, 255], [255, 0]], np.uint8))
    iio.imwrite(tmp_path / "row.png", rng.integers(0, 256, (1, 40), dtype=np.uint8))
    iio.imwrite(tmp_path / "col.png", rng.integers(0, 256, (40, 1), dtype=np.uint8))
    iio.imwrite(tmp_path / "aspect.png", rng.integers(0, 256, (4, 400), dtype=np.uint8))
    iio.imwrite(tmp_path / "g16.png", rng.integers(0, 65536, (16, 16), dtype=np.uint16))
    iio.imwrite(tmp_path / "rgba.png", rng.integers(0, 256, (16, 16, 4), dtype=np.uint8))
    iio.imwrite(tmp_path / "la.png", rng.integers(0, 256, (16, 16, 2), dtype=np.uint8))
    for name, bad in (("nan.tif", np.nan), ("inf.tif", np.inf)):
        image = rng.random((16, 16)).astype(np.float32)
        image[3, 3] = bad
        tifffile.imwrite(tmp_path / name, image)
    tifffile.imwrite(tmp_path / "flt.tif", rng.random((16, 16)).astype(np.float32))
    (tmp_path / "empty.png").write_bytes(b"")
    good = (tmp_path / "good.png").read_bytes()
    (tmp_path / "trunc.png").write_bytes(good[:len(good) // 2])
    (tmp_path / "text.png").write_text("not an image\n")
    (tmp_path / "adir").mkdir()
    (tmp_path / "adir.png").mkdir()
    os.symlink("loop2.png", tmp_path / "loop1.png")
    os.symlink("loop1.png", tmp_path / "loop2.png")
    os.symlink("nowhere", tmp_path / "dangling")
    os.symlink("good.png", tmp_path / "link.png")
    np.save(tmp_path / "obj.npy", np.array([1, None], dtype=object), allow_pickle=True)
    np.save(tmp_path / "a4.npy", rng.random((4, 4, 4, 4)).astype(np.float32)[..., None].repeat(5, -1))
    np.save(tmp_path / "a5.npy", rng.random((4, 4, 4, 4, 2)).astype(np.float32))
    np.save(tmp_path / "b2.npy", rng.random((16, 16)) > 0.5)
    np.save(tmp_path / "b3.npy", rng.random((16, 16, 16)) > 0.5)
    np.save(tmp_path / "c2.npy", (rng.random((16, 16)) + 1j).astype(np.complex64))
    np.save(tmp_path / "c3.npy", (rng.random((16, 16, 16)) + 1j).astype(np.complex64))
    np.save(tmp_path / "img2d.npy", rng.random((16, 16)).astype(np.float32))
    np.save(tmp_path / "nan2d.npy", np.full((16, 16), np.nan, np.float32))
    np.save(tmp_path / "const2d.npy", np.zeros((16, 16), np.float32))
    np.save(tmp_path / "v.npy", rng.random((16, 16, 16)).astype(np.float32))
    np.save(tmp_path / "v2.npy", rng.random((16, 16, 16, 2)).astype(np.float32))
    np.save(tmp_path / "v3.npy", rng.random((16, 16, 16, 3)).astype(np.float32))
    np.save(tmp_path / "vnan.npy", np.where(rng.random((16, 16, 16)) > 0.9, np.nan, 0.5).astype(np.float32))
    np.save(tmp_path / "small.npy", rng.random((2, 2, 2)).astype(np.float32))
    np.save(tmp_path / "flat.npy", rng.random((16, 16, 1)).astype(np.float32))
    np.save(tmp_path / "scalar.npy", np.float32(3))
    np.save(tmp_path / "e0.npy", np.zeros((0, 16), np.float32))
    np.save(tmp_path / "str.npy", np.array(["a", "b"]))
    np.save(tmp_path / "rec.npy", np.zeros((16, 16), dtype=[("a", "f4"), ("b", "f4")]))
    np.save(tmp_path / "dt.npy", np.zeros((16, 16), dtype="datetime64[s]"))
    (tmp_path / "afile").write_text("x")
    (tmp_path / "bad.npz").write_bytes(b"garbage")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    return tmp_path


# =========================================================================== 1. option values

#: Options whose value is a path or an address (odd paths are category 2 and 3).
_PATHS = {"out", "checkpoint", "exemplar_front", "exemplar_right", "exemplar_top", "scheduler",
          "constraint", "constraint_weight", "vector_field", "threshold", "slices"}
#: Each command's tiny dry run, to which one odd option value is added.
_BASES = {
    "synth": ["good.png", *TINY, *DRY], "coherent": ["good.png", *TINY, *DRY],
    "chen-wang": ["good.png", *TINY, *DRY], "kopf": ["good.png", *KTINY, *DRY],
    "volume": ["v.npy", *VTINY, *DRY], "volume-npmrf": ["v.npy", *VTINY, *DRY],
    "materials": ["grey.png", *TINY, *DRY],
}
#: Values no option takes: empty, not a number, unicode, NaN, -inf, past a float's range.
_ODD = ["", "x", "\u00e9", "nan", "-inf", "1e400"]


def _value_options(command: str) -> list[str]:
    """The option strings of ``command`` that take a value, paths left out."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices[command]
    return sorted(max(a.option_strings, key=len) for a in sub._actions
                  if a.option_strings and a.nargs != 0 and a.dest not in _PATHS and a.dest != "help")


ODD_VALUES = [[command, *_BASES[command], option, _ODD[i % len(_ODD)]]
              for command in _BASES for i, option in enumerate(_value_options(command))]


@pytest.mark.parametrize("argv", ODD_VALUES, ids=[" ".join([a[0], *a[-2:]]) for a in ODD_VALUES])
def test_an_odd_value_of_any_option_is_refused_in_one_line_naming_it(argv, place, capsys):
    line = one_line_error(argv, place, capsys)
    option, value = argv[-2:]
    assert option in line or f"'{value}'" in line, line


#: Options the chosen combination would not read: (argv, words the line holds).
UNREAD = [
    (["synth", "good.png", *TINY, "--support", "full", "--phase-weight", "3"], ["--phase-weight"]),
    (["synth", "good.png", "--size", "8", "--levels", "1", "--support", "full", "--grid", "2"], ["--grid 2"]),
    (["synth", "good.png", *TINY, "--support", "full", "--segmented", "yes"], ["--segmented"]),
    (["synth", "good.png", *TINY, "--support", "full", "--t0", "2"], ["--t0"]),
    (["synth", "good.png", *TINY, "--support", "full", "--proposal", "labels"], ["--proposal"]),
    (["synth", "good.png", *TINY, "--support", "full", "--relaxation", "anneal", "--xi", "-2"], ["--xi"]),
    (["synth", "good.png", *TINY, "--support", "full", "--relaxation", "anneal", "--max-sweeps", "2"],
     ["--max-sweeps"]),
    (["synth", "good.png", *TINY, "--bandwidth", "2"], ["--bandwidth"]),
    (["synth", "good.png", *TINY, "--adaptive", "5"], ["--adaptive"]),
    (["synth", "good.png", *TINY, "--decision", "sample"], ["--decision"]),
    (["synth", "good.png", *TINY, "--tau", "0.5"], ["--tau"]),
    (["synth", "good.png", *TINY, "--histogram-weight", "0.5"], ["--histogram-weight"]),
    (["synth", "good.png", *TINY, "--preset", "paper"], ["--preset"]),
    (["synth", "good.png", *TINY, "--toroidal-exemplar"], ["--toroidal-exemplar"]),
    (["synth", "good.png", *TINY, "--xi", "-2"], ["--xi", "--temperatures"]),
    (["synth", "good.png", *TINY, "--stop", "0.5"], ["--stop"]),
    (["synth", "good.png", *TINY, "--inherit", "fixed"], ["--inherit"]),
    (["synth", "good.png", *TINY, "--upsample", "1/8"], ["--upsample"]),
    (["synth", "good.png", *TINY, "--sampler", "heat-bath"], ["--sampler"]),
    (["synth", "good.png", *TINY, "--schedule", "linear"], ["--schedule"]),
    (["synth", "good.png", *TINY, "--proposals", "2"], ["--proposals"]),
    (["synth", "good.png", *TINY, "--relaxation", "anneal", "--stop", "0.5"], ["--stop"]),
    (["synth", "good.png", *TINY, "--whole-voxels", "64"], ["--whole-voxels", "--blockwise"]),
    (["synth", "good.png", *TINY, "--block", "8"], ["--block"]),
    (["synth", "good.png", *TINY, "--workers", "2"], ["--workers"]),
    (["coherent", "good.png", *TINY, "--xi", "-2"], ["--xi", "--icm"]),
    (["coherent", "good.png", *TINY, "--icm", "--sampler", "metropolis"], ["--sampler"]),
    (["chen-wang", "good.png", *TINY, "--block", "8"], ["--block"]),
    (["chen-wang", "good.png", *TINY, "--pilot", "8"], ["--pilot"]),
    (["kopf", "good.png", *KTINY, "--histogram-weight", "0", "--histogram-bins", "4"],
     ["--histogram-bins", "--histogram-weight"]),
    (["volume", "v.npy", *VTINY, "--angle", "90"], ["--angle"]),
    (["volume", "v.npy", *VTINY, "--vector-field", "radial", "--angle", "90"], ["--angle"]),
    (["study", "heuristics", "--quick", "--scheduler", "serial", "--workers", "2"], ["--workers", "serial"]),
    (["study", "heuristics", "--quick", "--scheduler", "serial", "--volume", "v.npy"], ["--volume"]),
    (["study", "heuristics", "--quick", "--scheduler", "serial", "--slice-axis", "0"], ["--slice-axis"]),
    (["study", "heuristics", "--quick", "--scheduler", "serial", "--slice-index", "2"], ["--slice-index"]),
    (["study", "heuristics", "--quick", "--scheduler", "serial", "--slices", "1"], ["--slices"]),
    (["study", "groundtruth", "--quick", "--scheduler", "serial", "--volume", "v.npy", "--slices", "3",
      "--slice-axis", "0"], ["--slice-axis", "--slices 3"]),
    (["study", "groundtruth", "--quick", "--scheduler", "serial", "--volume", "v.npy", "--slices", "3",
      "--slice-index", "2"], ["--slice-index"]),
]


@pytest.mark.parametrize("argv, words", UNREAD, ids=[" ".join(a) for a, _ in UNREAD])
def test_an_option_the_run_would_not_read_is_refused(argv, words, place, capsys):
    extra = ["--out", "st"] if argv[0] == "study" else DRY
    refused_naming([*argv, *extra], place, capsys, words)


def test_the_study_helpers_refuse_the_volume_options_of_a_study_without_a_volume():
    from npmrf3d.studies.catalog import get_study

    study = get_study("heuristics")
    for options, word in ((dict(slice_axis=1), "--slice-axis"), (dict(slices=3), "--slices"),
                          (dict(reference="v.npy"), "--volume"), (dict(slice_index=0), "--slice-index")):
        with pytest.raises(ParameterError, match=word):
            study.runs("quick", **options)
    with pytest.raises(ParameterError, match="--slice-axis"):
        get_study("groundtruth").runs("quick", reference="v.npy", slices=3, slice_axis=2)


# =========================================================================== 2. inputs

#: (argv, words the line holds)
INPUTS = [
    (["synth", "one.png", *TINY], ["1x1", "too small"]),
    (["synth", "two.png", *TINY], ["2x2", "too small"]),
    (["synth", "row.png", *TINY], ["too small"]),
    (["synth", "col.png", *TINY], ["too small"]),
    (["kopf", "one.png", *KTINY], ["too small"]),
    (["volume", "one.png", *VTINY], ["'one.png'"]),
    (["synth", "rgba.png", *TINY], ["alpha"]),
    (["synth", "la.png", *TINY], ["alpha"]),
    (["materials", "rgba.png", *TINY], ["alpha"]),
    (["synth", "nan.tif", *TINY], ["NaN or Inf"]),
    (["synth", "inf.tif", *TINY], ["NaN or Inf"]),
    (["kopf", "nan2d.npy", *KTINY], ["NaN or Inf"]),
    (["synth", "empty.png", *TINY], ["'empty.png'", "cannot be read"]),
    (["synth", "trunc.png", *TINY], ["'trunc.png'", "cannot be read"]),
    (["synth", "text.png", *TINY], ["'text.png'", "cannot be read"]),
    (["synth", "adir", *TINY], ["'adir'", "not a file"]),
    (["synth", "adir.png", *TINY], ["'adir.png'", "not a file"]),
    (["synth", "loop1.png", *TINY], ["'loop1.png'", "loop"]),
    (["synth", "dangling", *TINY], ["'dangling'", "'nowhere'", "does not exist"]),
    (["volume", "loop1.png", *VTINY], ["loop"]),
    (["synth", "good.png", "--exemplar-top", "loop1.png", *TINY], ["'loop1.png'", "loop"]),
    (["synth", "obj.npy", *TINY], ["'obj.npy'", "cannot be read"]),
    (["volume", "obj.npy", *VTINY], ["'obj.npy'", "cannot be read"]),
    (["synth", "a4.npy", *TINY], ["(4, 4, 4, 4, 5)"]),
    (["synth", "a5.npy", *TINY], ["(4, 4, 4, 4, 2)"]),
    (["volume", "a5.npy", *VTINY], ["(4, 4, 4, 4, 2)"]),
    (["synth", "b3.npy", *TINY], ["is a volume"]),
    (["synth", "c2.npy", *TINY], ["real-valued"]),
    (["volume", "c3.npy", *VTINY], ["real"]),
    (["synth", "scalar.npy", *TINY], ["shape ()"]),
    (["synth", "e0.npy", *TINY], ["empty"]),
    (["synth", "str.npy", *TINY], ["must hold numbers"]),
    (["synth", "rec.npy", *TINY], ["must hold numbers"]),
    (["synth", "dt.npy", *TINY], ["must hold numbers"]),
    (["synth", "v.npy", *TINY], ["is a volume", "npmrf3d volume"]),
    (["kopf", "v3.npy", *KTINY], ["is a volume"]),
    (["synth", "bundled:fibres48", *TINY], ["is a volume"]),
    (["volume", "img2d.npy", *VTINY], ["(16, 16)"]),
    (["volume", "good.png", *VTINY], ["2D image"]),
    (["volume", "vnan.npy", *VTINY], ["NaN or Inf"]),
    (["synth", "bundled:nope", *TINY], ["got 'nope'"]),
    (["synth", "bundled:", *TINY], ["got ''"]),
    (["synth", "bundled:../etc/passwd", *TINY], ["'../etc/passwd'"]),
    (["kopf", "bundled:nope", *KTINY], ["got 'nope'"]),
    (["synth", "good.png", "--exemplar-top", "grey.png", *TINY], ["same number of channels"]),
    (["materials", "const2d.npy", *TINY], ["one phase"]),
]


@pytest.mark.parametrize("argv, words", INPUTS, ids=[" ".join(a[:4]) for a, _ in INPUTS])
def test_an_odd_input_is_refused_in_one_line(argv, words, place, capsys):
    refused_naming([*argv, *DRY], place, capsys, words)


#: Odd but readable inputs: a dry run works.
READABLE = [["synth", name, *TINY] for name in ("aspect.png", "g16.png", "flt.tif", "link.png",
                                                 "b2.npy", "const2d.npy", "bundled:gravel64")] + [
    ["kopf", "g16.png", *KTINY], ["volume", "b3.npy", *VTINY], ["volume", "bundled:fibres48", *VTINY],
    ["materials", "b2.npy", *TINY]]


@pytest.mark.parametrize("argv", READABLE, ids=[" ".join(a[:2]) for a in READABLE])
def test_an_odd_but_readable_input_works(argv, place, capsys):
    assert cli.main([*argv, *DRY]) == 0, capsys.readouterr().err


# =========================================================================== 3. outputs

def _previous_run(place: pathlib.Path, name: str) -> None:
    assert cli.main(["synth", "good.png", *TINY, "--quiet", "--out", name]) == 0


def _folder_with(place: pathlib.Path, name: str) -> None:
    (place / name).mkdir()
    (place / name / "mine.txt").write_text("keep")


#: (argv, set-up before the run, words the line holds)
OUTPUTS = [
    (["--out", "afile"], None, ["'afile'", "not a folder"]),
    (["--out", "afile/sub"], None, ["'afile/sub'", "not a folder"]),
    (["--out", "dangling"], None, ["'dangling'", "'nowhere'"]),
    (["--out", "dangling", "--overwrite"], None, ["'dangling'", "'nowhere'"]),
    (["--out", "loop1.png"], None, ["'loop1.png'", "loop"]),
    (["--out", "dangling.zarr"], lambda p: os.symlink("gone", p / "dangling.zarr"), ["'gone'"]),
    (["--out", ""], None, ["--out", "empty"]),
    (["--out", "prev"], lambda p: _previous_run(p, "prev"), ["already holds a run", "--overwrite"]),
    (["--out", "prev.zarr"], lambda p: _previous_run(p, "prev.zarr"), ["already holds", "--overwrite"]),
    (["--out", "mine.zarr", "--overwrite"], lambda p: _folder_with(p, "mine.zarr"), ["not a Zarr volume"]),
    (["--out", "f.zarr"], lambda p: (p / "f.zarr").write_text("x"), ["not a folder"]),
    (["--out", "f.zarr", "--overwrite"], lambda p: (p / "f.zarr").write_text("x"), ["not a folder"]),
    (["--out", "lnk", "--overwrite"], lambda p: os.symlink("good.png", p / "lnk"), ["not a folder"]),
    (["--out", "o", "--checkpoint", "adir"], None, ["'adir'", "not a file"]),
    (["--out", "o", "--checkpoint", "bad.npz"], None, ["not a checkpoint file"]),
    (["--out", "o", "--checkpoint", "other.npz"], None, ["not a checkpoint file"]),
    (["--out", "o", "--checkpoint", "good.png"], None, ["not a checkpoint file"]),
    (["--out", "o", "--checkpoint", "afile/c.npz"], None, ["does not exist"]),
    (["--out", "o", "--checkpoint", "o"], None, ["the output"]),
    (["--out", "o", "--checkpoint", "o/volume.npy"], lambda p: (p / "o").mkdir(), ["run file volume.npy"]),
    (["--out", "x.zarr", "--checkpoint", "x.zarr"], None, ["the output"]),
]


@pytest.mark.parametrize("extra, setup, words", OUTPUTS, ids=[" ".join(e) for e, _, _ in OUTPUTS])
def test_an_odd_output_is_refused_before_any_work(extra, setup, words, place, capsys):
    if setup is not None:
        setup(place)
        capsys.readouterr()
    refused_naming(["synth", "good.png", *TINY, "--quiet", *extra], place, capsys, words)


#: Every command that writes a run folder refuses a checkpoint that is not one of npmrf3d's.
CORRUPT_CHECKPOINT = [["synth", "good.png", *TINY], ["coherent", "good.png", *TINY],
                      ["chen-wang", "good.png", *TINY], ["kopf", "good.png", *KTINY],
                      ["volume", "v.npy", *VTINY], ["volume-npmrf", "v.npy", *VTINY],
                      ["materials", "grey.png", *TINY]]


@pytest.mark.parametrize("argv", CORRUPT_CHECKPOINT, ids=[a[0] for a in CORRUPT_CHECKPOINT])
def test_a_corrupt_checkpoint_is_refused_by_every_command(argv, place, capsys):
    refused_naming([*argv, "--out", "o", "--checkpoint", "bad.npz"], place, capsys,
                   ["'bad.npz'", "not a checkpoint file"])


@pytest.mark.parametrize("out", ["x.ZARR", "x.zarr/", "x.Zarr"])
def test_a_zarr_name_in_any_case_or_with_a_slash_makes_a_zarr_volume(out, place, capsys):
    assert cli.main(["synth", "good.png", *TINY, "--quiet", "--out", out]) == 0, capsys.readouterr().err
    folder = place / out.rstrip("/")
    assert (folder / ".zarray").is_file() and not (folder / "volume.npy").exists()
    assert not [p for p in place.iterdir() if p.name.startswith(".") and p.name != ".zarr"]


def test_an_overwrite_keeps_the_users_files_and_leaves_nothing_beside(place, capsys):
    _folder_with(place, "o")
    assert cli.main(["synth", "good.png", *TINY, "--quiet", "--out", "o"]) == 0
    assert cli.main(["synth", "good.png", *TINY, "--quiet", "--out", "o", "--overwrite", "--seed", "1"]) == 0
    assert (place / "o" / "mine.txt").read_text() == "keep"
    assert sorted(p.name for p in place.iterdir() if p.name.startswith(".")) == []


@pytest.mark.parametrize("argv", [["materials", "grey.png", *TINY, "--out", "x.zarr"],
                                  ["metrics", "good.png", "v3.npy", "--out", "afile"],
                                  ["metrics", "good.png", "v3.npy", "--out", "dangling"],
                                  ["metrics", "good.png", "v3.npy", "--out", ""]])
def test_other_commands_refuse_an_odd_output(argv, place, capsys):
    one_line_error(argv, place, capsys)


# =========================================================================== 4. races, signals

def _held_by_a_live_process(place: pathlib.Path, name: str):
    """A lock on output ``name`` held by a live process of this host (a child that sleeps)."""
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    (place / f".{name}.lock").write_text(f"{child.pid} {socket.gethostname()}\n")
    return child


@pytest.mark.parametrize("argv, name", [
    (["synth", "good.png", *TINY, "--out", "o"], "o"),
    (["synth", "good.png", *TINY, "--out", "o.zarr"], "o.zarr"),
    (["volume", "v.npy", *VTINY, "--out", "o"], "o"),
    (["kopf", "good.png", *KTINY, "--out", "o.zarr"], "o.zarr"),
])
def test_a_second_run_into_an_output_another_run_holds_is_refused(argv, name, place, capsys):
    child = _held_by_a_live_process(place, name)
    try:
        line = refused_naming(argv, place, capsys, ["in use by another run", f"PID {child.pid}"])
        assert line.count("error") == 1
    finally:
        child.kill()
        child.wait()


@pytest.mark.parametrize("name", ["o", "o.zarr"])
def test_a_dead_runs_lock_and_staging_folder_are_cleared_by_the_next_run(name, place, capsys):
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    (place / f".{name}.lock").write_text(f"{child.pid} {socket.gethostname()}\n")
    (place / f".{name}.partial-{child.pid}-abc").mkdir()
    assert cli.main(["synth", "good.png", *TINY, "--quiet", "--out", name]) == 0, capsys.readouterr().err
    assert not [p.name for p in place.iterdir() if p.name.startswith(f".{name}")]


def _command(place: pathlib.Path, *argv: str) -> subprocess.Popen:
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "npmrf3d", *argv], cwd=place, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_sigterm_in_a_level_then_a_rerun_resumes_and_leaves_nothing_behind(place):
    run = ["synth", "good.png", "--size", "32", "--levels", "2", "--window", "5", "--grid", "1",
           "--quiet", "--out", "o", "--checkpoint", "c.npz"]
    first = _command(place, *run)
    start = time.monotonic()
    while not (place / "c.npz").exists():  # the coarse level is done: the fine one runs
        assert first.poll() is None, first.communicate()
        assert time.monotonic() - start < 120
        time.sleep(0.05)
    first.send_signal(signal.SIGTERM)
    _, err = first.communicate(timeout=120)
    assert first.returncode == 130 and len(err.strip().splitlines()) == 1, err
    assert "resume" in err and not (place / "o").exists()
    again = _command(place, *run)
    _, err = again.communicate(timeout=300)
    assert again.returncode == 0 and err == "", err
    assert sorted(p.name for p in (place / "o").iterdir()) == sorted(
        ["volume.npy", "volume.tif", "preview.png", "run.json"])
    assert not [p.name for p in place.iterdir() if p.name.startswith(".")]


@pytest.mark.parametrize("shell, code, words", [
    ("{exe} -m npmrf3d synth good.png --size 8 --levels 1 --window 3 --dry-run >&-", 1, "standard output"),
    ("{exe} -m npmrf3d info > /dev/full", 1, "No space left"),
    ("{exe} -m npmrf3d synth nothere.png --size 8 2>&-", 2, ""),
])
def test_a_closed_or_full_stream_ends_a_command_in_at_most_one_line(shell, code, words, place):
    done = subprocess.run(shell.format(exe=sys.executable), shell=True, cwd=place,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == code, done.stderr
    assert "Traceback" not in done.stderr and len(done.stderr.strip().splitlines()) <= 1
    assert words in done.stderr


# =========================================================================== 5. the Python API

EX = np.random.default_rng(0).integers(0, 256, (16, 16, 3), dtype=np.uint8)
VOL = np.random.default_rng(0).random((16, 16, 16)).astype(np.float32)
API_2D = dict(size=8, levels=1, window=3)

#: (keywords of synthesize(EX, ...), words of the ParameterError)
API_REFUSALS = [
    (dict(colour=3), ["no option 'colour'"]),
    (dict(levles=1), ["no option 'levles'"]),
    (dict(method="npmrff"), ["method must be one of"]),
    (dict(method=None), ["method must be one of"]),
    (dict(method=3), ["method must be one of"]),
    (dict(size="8"), ["size"]),
    (dict(size=8.5), ["size"]),
    (dict(size=(8, 8)), ["size"]),
    (dict(size=(8, 8, 8, 8)), ["size"]),
    (dict(size=True), ["size"]),
    (dict(size=None), ["size"]),
    (dict(size=np.array(8)), ["size"]),
    (dict(levels=1.0), ["levels must be an integer"]),
    (dict(levels="1"), ["levels must be an integer"]),
    (dict(window=np.float64(3)), ["window must be an integer"]),
    (dict(xi="-1"), ["xi must be a number"]),
    (dict(temperatures=True, xi=float("nan")), ["xi", "nan"]),
    (dict(phase_weight=1j), ["phase_weight must be a number"]),
    (dict(phase_weight=[1]), ["phase_weight must be a number"]),
    (dict(heuristic=2), ["heuristic must be one of"]),
    (dict(temperatures="yes"), ["temperatures must be True or False"]),
    (dict(views=3), ["views must be view names", "got 3"]),
    (dict(views=None), ["views must be view names"]),
    (dict(views=[1]), ["view must be one of"]),
    (dict(views=["front", "side"]), ["got 'side'"]),
    (dict(views=[]), ["empty"]),
    (dict(rng=1.5), ["rng must be"]),
    (dict(rng="1"), ["rng must be"]),
    (dict(rng=-1), ["seed must be"]),
    (dict(rng=True), ["rng must be"]),
    (dict(rng=[1, 2]), ["rng must be"]),
    (dict(rng=np.random.SeedSequence(1)), ["rng must be", "SeedSequence"]),
    (dict(rng=np.random.RandomState(0)), ["rng must be"]),
    (dict(exemplars={"side": EX}), ["not constrained: side"]),
    (dict(exemplars={"top": "nofile.png"}), ["'nofile.png' does not exist"]),
    (dict(exemplars=[EX]), ["must be a dict"]),
    (dict(exemplars={0: EX}), ["keyed by view names", "got the key 0"]),
    (dict(exemplars={None: EX}), ["keyed by view names", "None"]),
    (dict(exemplars={"top": EX[..., 0]}), ["same number of channels"]),
    (dict(views=("front", "right"), exemplars={"top": EX}), ["not constrained: top"]),
    (dict(xi=np.ones((6, 6))), ["xi must be a number"]),
]


@pytest.mark.parametrize("keywords, words", API_REFUSALS, ids=[str(sorted(k))[:40] for k, _ in API_REFUSALS])
def test_the_api_refuses_a_bad_keyword_in_one_line(keywords, words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ParameterError) as caught:
        npmrf3d.synthesize(EX, **{**API_2D, **keywords})
    message = str(caught.value)
    assert "\n" not in message, message
    for word in words:
        assert word in message, (word, message)
    assert not list(tmp_path.iterdir())


#: (exemplar, keywords) that a run of each method accepts (numpy scalars, lists, a bool image)
API_ACCEPTS = [
    (EX, dict(size=np.int64(8), levels=np.int32(1), window=3)),
    (EX, dict(size=[8, 8, 8], levels=1, window=3)),
    (EX, dict(size=np.array([8, 8, 8]), levels=1, window=3)),
    (EX, dict(**API_2D, rng=np.int64(3))),
    (EX, dict(**API_2D, rng=2 ** 200)),
    (EX, dict(**API_2D, temperatures=np.bool_(True), xi=np.float32(-2))),
    (EX, dict(**API_2D, views="front, top")),
    (EX, dict(**API_2D, heuristic="ml_h2a")),
    (EX[::-1, ::-1], dict(API_2D)),
    (np.random.default_rng(1).random((16, 16)) > 0.5, dict(API_2D)),
]


@pytest.mark.parametrize("exemplar, keywords", API_ACCEPTS, ids=[str(sorted(k)) for _, k in API_ACCEPTS])
def test_the_api_takes_numpy_scalars_lists_and_odd_arrays(exemplar, keywords):
    volume = npmrf3d.synthesize(exemplar, **keywords).volume
    assert volume.shape[:3] == (8, 8, 8) and np.isfinite(volume).all()


class _Boom(Exception):
    pass


def _boom(*_):
    raise _Boom("from the callback")


#: Each method's tiny call: (exemplar, method, keywords).
METHOD_CALLS = [
    (EX, "npmrf", API_2D), (EX, "npmrf", dict(API_2D, support="full")), (EX, "coherent", API_2D),
    (EX, "chen-wang", API_2D), (EX, "kopf", dict(size=8, levels=1, window=4, iterations=1)),
    (VOL, "volume-lh", dict(size=8, levels=1)), (VOL, "npmrf-3d", dict(size=8, levels=1)),
]


@pytest.mark.parametrize("exemplar, method, keywords", METHOD_CALLS,
                         ids=[f"{m}-{sorted(k)}" for _, m, k in METHOD_CALLS])
def test_an_exception_of_the_progress_callback_propagates_as_it_was(exemplar, method, keywords):
    with pytest.raises(_Boom, match="from the callback") as caught:
        npmrf3d.synthesize(exemplar, method=method, progress=_boom, **keywords)
    assert caught.value.__cause__ is None


@pytest.mark.parametrize("extra, word", [(dict(progress=3), "progress"), (dict(checkpoint=3), "checkpoint"),
                                         (dict(checkpoint=b"c.npz"), "checkpoint")])
@pytest.mark.parametrize("exemplar, method, keywords", METHOD_CALLS,
                         ids=[f"{m}-{sorted(k)}" for _, m, k in METHOD_CALLS])
def test_a_bad_progress_or_checkpoint_is_refused_before_the_run(exemplar, method, keywords, extra, word,
                                                                tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ParameterError, match=word):
        npmrf3d.synthesize(exemplar, method=method, **keywords, **extra)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("exemplar, method, keywords", METHOD_CALLS,
                         ids=[f"{m}-{sorted(k)}" for _, m, k in METHOD_CALLS])
def test_a_wrong_exemplar_kind_for_the_method_is_refused(exemplar, method, keywords):
    other = VOL if exemplar is EX else EX
    with pytest.raises(ParameterError) as caught:
        npmrf3d.synthesize(other, method=method, **keywords)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("call", [
    lambda: npmrf3d.kopf_synthesize(EX, size=8, levels=1, window=4, iterations=1, foo=1),
    lambda: npmrf3d.chen_wang_synthesize(EX, **API_2D, foo=1),
    lambda: npmrf3d.coherent_synthesize(EX, **API_2D, foo=1),
    lambda: npmrf3d.npmrf_synthesize(EX, **API_2D, foo=1),
    lambda: npmrf3d.volume_synthesize(VOL, size=8, levels=1, foo=1),
    lambda: npmrf3d.npmrf_volume_synthesize(VOL, size=8, levels=1, foo=1),
    lambda: npmrf3d.synthesize(EX, method="kopf", size=8, levels=1, window=4, iterations=1,
                               histogram_weight=0, histogram_bins=4),
    lambda: npmrf3d.synthesize(EX, method="coherent", **API_2D, xi=-2),
    lambda: npmrf3d.synthesize(VOL, method="volume-lh", size=8, levels=1, vector_field="spiral"),
    lambda: npmrf3d.synthesize(VOL, method="volume-lh", size=8, levels=1, spacing=-1),
    lambda: npmrf3d.synthesize(VOL, method="npmrf-3d", size=8, levels=1, adaptive=float("nan")),
    lambda: npmrf3d.synthesize(None, method="volume-lh", size=8, levels=1),
    lambda: npmrf3d.synthesize(VOL, method="volume-lh", size=8, levels=1, exemplars={"top": EX}),
    lambda: npmrf3d.get_method("x"),
    lambda: npmrf3d.load_exemplar("/"),
], ids=["kopf-foo", "cw-foo", "coherent-foo", "npmrf-foo", "vlh-foo", "v3-foo", "kopf-bins",
        "coherent-xi", "vlh-field", "vlh-spacing", "v3-adaptive", "vlh-none", "vlh-exemplars",
        "get_method", "load_exemplar-dir"])
def test_each_methods_function_refuses_in_one_line(call):
    with pytest.raises(ParameterError) as caught:
        call()
    assert "\n" not in str(caught.value)


# =========================================================================== 6. other commands

def _zarr_without_marker(place: pathlib.Path) -> None:
    import shutil
    assert cli.main(["synth", "good.png", *TINY, "--quiet", "--out", "z.zarr"]) == 0
    shutil.rmtree(place / "z.zarr" / ".npmrf3d-done")


#: (argv, set-up, words the line holds)
OTHERS = [
    (["metrics", "good.png", "z.zarr", "--out", "m"], _zarr_without_marker, ["not complete"]),
    (["metrics", "good.png", "adir", "--out", "m"], None, ["not a Zarr volume"]),
    (["metrics", "grey.png", "v2.npy", "--out", "m"], None, ["the volume has 2"]),
    (["metrics", "good.png", "v.npy", "--out", "m"], None, ["the volume has 1"]),
    (["metrics", "grey.png", "small.npy", "--out", "m"], None, ["too small"]),
    (["metrics", "grey.png", "flat.npy", "--out", "m"], None, ["too small"]),
    (["metrics", "one.png", "v.npy", "--out", "m"], None, ["too small"]),
    (["metrics", "row.png", "v.npy", "--out", "m"], None, ["too small"]),
    (["metrics", "grey.png", "vnan.npy", "--out", "m"], None, ["NaN or Inf"]),
    (["metrics", "grey.png", "v.npy", "--out", "m", "--views", ""], None, ["--views", "empty"]),
    (["metrics", "grey.png", "v.npy", "--out", "m", "--views", "front,front"], None, ["repeat"]),
    (["metrics", "grey.png", "v.npy", "--out", "m", "--views", "side"], None, ["'side'"]),
    (["metrics", "grey.png", "v.npy", "--out", "m", "--views", "front", "--exemplar-top", "grey.png"],
     None, ["--exemplar-top"]),
    (["metrics", "grey.png", "v.npy", "--out", "m", "--exemplar-top", ""], None, ["empty"]),
    (["metrics", "grey.png", "v.npy", "--out", "m", "--quiet"], None, ["--quiet"]),
    (["metrics", "good.png", "run.json", "--out", "m"], lambda p: (p / "run.json").write_text("{}"),
     ["'.json'"]),
    (["metrics", "bundled:nope", "v3.npy", "--out", "m"], None, ["'nope'"]),
    (["metrics", "grey.png", "dangling", "--out", "m"], None, ["'dangling'"]),
    (["study", "nope", "--quick", "--out", "st"], None, ["'nope'"]),
    (["study", "", "--quick", "--out", "st"], None, ["got ''"]),
    (["study", "heuristics", "--quick", "--out", "afile", "--scheduler", "serial"], None, ["afile"]),
    (["study", "heuristics", "--quick", "--out", "", "--scheduler", "serial"], None, ["--out"]),
    (["study", "heuristics", "--quick", "--out", "st", "--scheduler", "bogus"], None, ["--scheduler"]),
    (["study", "heuristics", "--quick", "--out", "st", "--workers", "0"], None, ["--workers"]),
    (["study", "heuristics", "--quick", "--out", "st", "--threads", "-1"], None, ["--threads"]),
    (["study", "heuristics", "--quick", "--out", "st", "--seeds", "x"], None, ["--seeds"]),
    (["study", "heuristics", "--quick", "--out", "st", "--size", "0"], None, ["--size"]),
    (["study", "groundtruth", "--quick", "--out", "st", "--scheduler", "serial"], None, ["--volume"]),
    (["study", "groundtruth", "--quick", "--out", "st", "--scheduler", "serial", "--volume", "img2d.npy"],
     None, ["(16, 16)"]),
    (["study", "groundtruth", "--quick", "--out", "st", "--scheduler", "serial", "--volume", "v.npy",
      "--slice-index", "16"], None, ["--slice-index 16"]),
    (["report", "nothere"], None, ["'nothere'"]),
    (["report", ""], None, ["RESULTS_DIR", "empty"]),
    (["report", "adir"], None, ["no study results"]),
    (["info", "x"], None, ["x"]),
    (["info", "--json"], None, ["--json"]),
]


@pytest.mark.parametrize("argv, setup, words", OTHERS, ids=[" ".join(a[:5]) for a, _, _ in OTHERS])
def test_the_other_commands_refuse_in_one_line(argv, setup, words, place, capsys):
    if setup is not None:
        setup(place)
        capsys.readouterr()
    refused_naming(argv, place, capsys, words)


@pytest.mark.parametrize("command", [["neural", "train", "grey.png", "--out", "m.pt"],
                                     ["neural", "generate", "afile", "--out", "x.npy"]])
def test_a_neural_command_without_torch_says_so_in_one_line(command, place, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)
    refused_naming(command, place, capsys, ["torch"])


#: The neural commands' argument checks, run where torch is installed (tests_neural).
NEURAL_CASES = 17


def test_the_round_counts_at_least_three_hundred_cases():
    cases = (len(ODD_VALUES) + len(UNREAD) + len(INPUTS) + len(READABLE) + len(OUTPUTS)
             + len(CORRUPT_CHECKPOINT) + 3 + 1 + 4 + 4 + 2 + 1 + 3 + len(API_REFUSALS)
             + len(API_ACCEPTS) + 5 * len(METHOD_CALLS) + 15 + len(OTHERS) + 2 + NEURAL_CASES)
    assert cases >= 300, cases
