"""Defaults that surprise and options that would change nothing, on the command line.

Every sub-command's default ``--out`` names the sub-command; an image's alpha channel is no
data channel; a vector field or an ``--angle`` that turns nothing, a ``--coherence-bias``
without global matches, ``--histogram-bins`` without histogram matching, a ``--pca-dims`` the
neighbourhoods cannot hold, ``--passes 0`` and a ``NUMBA_NUM_THREADS`` of 0 are refused in one
line that names the options as the command line spells them; an explicit ``--window`` that the
segmented preset replaces is refused (``--segmented yes``) or warned about (``auto``).

``ERRORS`` lists the refusals: (argv, words the line must hold, words it must not hold).
"""

from __future__ import annotations

import os
import pathlib
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from npmrf3d import cli
from npmrf3d.cli.main import build_parser
from npmrf3d.errors import InputNote
from npmrf3d.model.exemplar import load_exemplar
from tests.cli_checks import one_line_error, refused_naming

VTINY = ["--size", "8", "--levels", "1", "--dry-run"]
TINY = ["--size", "8", "--levels", "1", "--dry-run"]
KTINY = ["--size", "8", "--levels", "1", "--window", "4", "--iterations", "1", "--dry-run"]

#: (argv, words the error line holds, words it must not hold)
ERRORS = [
    # an all-zero or non-finite vector field, an --angle that turns nothing
    (["volume", "v.npy", *VTINY, "--vector-field", "zero_dirs.npy"],
     ["--vector-field", "zero_dirs.npy", "zero everywhere"], ["vector_field"]),
    (["volume", "v.npy", *VTINY, "--vector-field", "zero_frames.npy"],
     ["--vector-field", "zero everywhere"], ["vector_field"]),
    (["volume", "v.npy", *VTINY, "--vector-field", "nan_dirs.npy"],
     ["--vector-field", "NaN or Inf"], ["vector_field"]),
    (["volume", "v.npy", *VTINY, "--angle", "30"], ["--angle", "--vector-field none"], []),
    (["volume", "v.npy", *VTINY, "--angle", "180"], ["--angle", "--vector-field none"], []),
    (["volume", "v.npy", *VTINY, "--angle", "30", "--vector-field", "radial"],
     ["--angle", "--vector-field radial"], []),
    (["volume", "v.npy", *VTINY, "--angle", "30", "--vector-field", "dirs.npy"],
     ["--angle", "--vector-field a field file"], []),
    (["volume-npmrf", "v.npy", *VTINY, "--angle", "30"], ["--angle"], []),
    # what a 4x4x4 array is, and only options that exist
    (["volume", "c4.npy", *VTINY], ["(4, 4, 4)", "4 channels", "--exemplar-kind volume"],
     ["--exemplar-kind image", "exemplar_kind"]),
    (["volume-npmrf", "c4.npy", *VTINY], ["(4, 4, 4)", "--exemplar-kind volume"],
     ["--exemplar-kind image", "exemplar_kind"]),
    (["volume", "amb.npy", *VTINY], ["ambiguous", "--exemplar-kind volume"],
     ["--exemplar-kind image", "exemplar_kind"]),
    (["synth", "amb.npy", *TINY], ["ambiguous", "--exemplar-kind image"],
     ["--exemplar-kind volume", "exemplar_kind"]),
    (["synth", "cube.npy", *TINY], ["--exemplar-kind image"], ["exemplar_kind"]),
    # an alpha channel with transparent pixels
    (["synth", "alpha.png", *TINY], ["alpha", "flatten"], []),
    (["coherent", "alpha.png", *TINY], ["alpha", "flatten"], []),
    # every option of volume and volume-npmrf speaks its own name
    (["volume", "v.npy", *VTINY, "--levels", "0"], ["--levels must"], []),
    (["volume", "v.npy", *VTINY, "--window", "4"], ["--window must"], []),
    (["volume", "v.npy", *VTINY, "--window", "9"], ["--window must"], []),
    (["volume", "v.npy", *VTINY, "--pca-dims", "0"], ["--pca-dims must"], ["pca_dims"]),
    (["volume", "v.npy", *VTINY, "--k", "0"], ["--k must"], []),
    (["volume", "v.npy", *VTINY, "--exclude", "-1"], ["--exclude must"], []),
    (["volume", "v.npy", *VTINY, "--passes", "-1"], ["--passes must"], []),
    (["volume", "v.npy", *VTINY, "--neighbourhood", "all"], ["--neighbourhood must"], []),
    (["volume", "v.npy", *VTINY, "--jitter", "-1"], ["--jitter must"], []),
    (["volume", "v.npy", *VTINY, "--fine-jitter", "nan"], ["--fine-jitter must"], ["fine_jitter"]),
    (["volume", "v.npy", *VTINY, "--usage", "-1"], ["--usage must"], []),
    (["volume", "v.npy", *VTINY, "--balance", "1000"], ["--balance must"], []),
    (["volume", "v.npy", *VTINY, "--start", "middle"], ["--start must"], []),
    (["volume", "v.npy", *VTINY, "--vector-field", "twist", "--angle", "1e9"], ["--angle must"], []),
    (["volume", "v.npy", *VTINY, "--vector-field", "spiral"], ["--vector-field must"],
     ["vector_field"]),
    (["volume", "v.npy", *VTINY, "--seed", "-1"], ["--seed must"], []),
    (["volume", "v.npy", "--size", "0", "--levels", "1", "--dry-run"], ["--size must"], []),
    (["volume", "v.npy", *VTINY, "--spacing", "-1"], ["--spacing must"], []),
    (["volume", "v.npy", *VTINY, "--spacing", "1,2,3"], ["--spacing", "anisotropic"], []),
    (["volume-npmrf", "v.npy", *VTINY, "--adaptive", "0"], ["--adaptive must"], []),
    (["volume-npmrf", "v.npy", *VTINY, "--centre-bandwidth", "0"], ["--centre-bandwidth must"],
     ["centre_bandwidth"]),
    (["volume-npmrf", "v.npy", *VTINY, "--seed", "-1"], ["--seed must"], []),
    (["volume-npmrf", "v.npy", *VTINY, "--levels", "7"], ["--levels must"], []),
    # the levels' message names no window the run does not use
    (["volume", "v.npy", "--size", "8", "--levels", "4", "--dry-run"],
     ["--size 8 is too small for 4 levels"], ["window"]),
    (["volume", "v.npy", "--size", "16", "--levels", "5", "--dry-run"],
     ["--size 16 is too small for 5 levels"], ["window 3"]),
    (["volume", "v.npy", *VTINY, "--passes", "0"], ["--passes must", "got 0"], []),
    (["volume-npmrf", "v.npy", *VTINY, "--passes", "0"], ["--passes must", "got 0"], []),
    # other commands: library names become their options
    (["kopf", *KTINY, "--r", "3"], ["--r must"], []),
    (["chen-wang", *TINY, "--r", "3"], ["--r must"], []),
    (["kopf", *KTINY, "--seed", "-1"], ["--seed must"], []),
    (["synth", *TINY, "--seed", "-1"], ["--seed must"], []),
    (["kopf", *KTINY, "--constraint-weight", "2"], ["--constraint-weight needs --constraint"],
     ["constraint_weight"]),
    (["kopf", *KTINY, "--constraint", "c4.npy"], ["--constraint must have shape"], []),
    (["synth", "seg.png", *TINY, "--histogram-weight", "2"], ["option --histogram-weight"],
     ["histogram_weight"]),
    # options the configuration leaves without effect
    (["synth", "seg.png", *TINY, "--window", "3", "--segmented", "yes"],
     ["--window 3", "--segmented yes", "window 5"], []),
    (["coherent", "seg.png", *TINY, "--coherence-bias", "3"], ["--coherence-bias", "--global-share is above 0"], []),
    (["coherent", "seg.png", *TINY, "--coherence-bias", "3", "--global-share", "0"],
     ["--coherence-bias", "--global-share is above 0"], []),
    (["chen-wang", "seg.png", *TINY, "--coherence-bias", "0.5"], ["--coherence-bias", "--global-share is above 0"], []),
    # every option an annealing, ICM or block-local run alone reads, refused without it
    *[([command, "seg.png", *TINY, *option], [option[0], needs], [])
      for command in ("coherent",)
      for option, needs in ((["--sampler", "metropolis"], "--t0 is above 0"), (["--t-end", "0.5"], "--t0 is above 0"),
                            (["--schedule", "linear"], "--t0 is above 0"), (["--xi", "-2"], "--icm is set"),
                            (["--stop", "0.5"], "--icm is set"), (["--max-sweeps", "3"], "--icm is set"),
                            (["--inherit", "fixed"], "--icm is set"), (["--upsample", "1/8"], "--icm is set"),
                            (["--iterations", "2", "--icm"], "--icm is not set"))],
    # written at their default value, they are still written: refused all the same
    (["coherent", "seg.png", *TINY, "--xi", "-1"], ["--xi", "--icm is set"], []),
    (["coherent", "seg.png", *TINY, "--icm", "--sampler", "heat-bath"], ["--sampler", "--t0 is above 0"], []),
    (["synth", "seg.png", *TINY, "--stop", "0.95"], ["--stop", "--temperatures is set"], []),
    (["kopf", "seg.png", *KTINY, "--histogram-weight", "0", "--histogram-bins", "16"],
     ["--histogram-bins", "--histogram-weight is above 0"], []),
    *[([command, "seg.png", *TINY, *option], [option[0], needs], [])
      for command in ("coherent", "chen-wang")
      for option, needs in ((["--pilot", "32"], "--blockwise is set"),
                            (["--whole-voxels", "4096"], "--blockwise"),
                            (["--phase-weight", "4", "--value-prior", "0"], "--value-prior is above 0"))],
    (["kopf", "seg.png", *KTINY, "--histogram-bins", "7", "--histogram-weight", "0"],
     ["--histogram-bins", "--histogram-weight is above 0"], []),
    (["baseline", "kopf", "seg.png", *KTINY, "--histogram-bins", "7", "--histogram-weight", "0"],
     ["--histogram-bins", "--histogram-weight is above 0"], []),
    (["chen-wang", "seg.png", *TINY, "--pca-dims", "1000"], ["--pca-dims 1000", "at most 16"], []),
    (["chen-wang", "rgb.png", *TINY, "--pca-dims", "49"], ["--pca-dims 49", "at most 48"], []),
]


@pytest.fixture
def place(tmp_path, monkeypatch) -> pathlib.Path:
    """A working folder with the files that ``ERRORS`` names."""
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(0)
    np.save(tmp_path / "v.npy", rng.random((16, 16, 16)).astype(np.float32))
    np.save(tmp_path / "c4.npy", rng.random((4, 4, 4)).astype(np.float32))
    np.save(tmp_path / "amb.npy", np.zeros((64, 64, 16), dtype=np.float32))
    np.save(tmp_path / "cube.npy", np.zeros((16, 16, 16), dtype=np.float32) + 0.5)
    np.save(tmp_path / "zero_dirs.npy", np.zeros((8, 8, 8, 3), dtype=np.float32))
    np.save(tmp_path / "zero_frames.npy", np.zeros((8, 8, 8, 3, 3), dtype=np.float32))
    nan = np.ones((8, 8, 8, 3), dtype=np.float32)
    nan[1, 2, 3, 0] = np.nan
    np.save(tmp_path / "nan_dirs.npy", nan)
    np.save(tmp_path / "dirs.npy", rng.normal(size=(8, 8, 8, 3)).astype(np.float32))
    rgba = rng.integers(0, 256, (24, 24, 4), dtype=np.uint8)
    rgba[..., 3] = 255
    iio.imwrite(tmp_path / "opaque.png", rgba)
    rgba[3, 4, 3] = 128
    iio.imwrite(tmp_path / "alpha.png", rgba)
    iio.imwrite(tmp_path / "rgb.png", rgba[..., :3])
    iio.imwrite(tmp_path / "seg.png", ((rng.random((32, 32)) > 0.5) * 255).astype(np.uint8))
    return tmp_path




@pytest.mark.parametrize("argv, words, not_words", ERRORS, ids=[" ".join(a) for a, _, _ in ERRORS])
def test_refusal_is_one_line_naming_the_options(argv, words, not_words, place, capsys):
    refused_naming(argv, place, capsys, words, not_words)


def test_the_refusals_are_distinct():
    assert len({tuple(argv) for argv, _, _ in ERRORS}) == len(ERRORS)


# --------------------------------------------------------------------------- default --out

#: (argv before the options, the command its default --out names)
COMMANDS = [
    (["synth"], "synth"), (["npmrf"], "synth"), (["coherent"], "coherent"), (["kopf"], "kopf"),
    (["baseline", "kopf"], "kopf"), (["chen-wang"], "chen-wang"),
    (["baseline", "chen-wang"], "chen-wang"), (["volume", "v.npy"], "volume"),
    (["volume-lh", "v.npy"], "volume"), (["volume-npmrf", "v.npy"], "volume-npmrf"),
    (["npmrf-3d", "v.npy"], "volume-npmrf"),
]


@pytest.mark.parametrize("argv, command", COMMANDS, ids=[" ".join(a) for a, _ in COMMANDS])
def test_default_out_names_the_command(argv, command):
    assert build_parser().parse_args(argv).out == f"npmrf3d-{command}-out"


@pytest.mark.parametrize("argv", [["volume", "v.npy", "--size", "8", "--levels", "1"],
                                  ["volume-npmrf", "v.npy", "--size", "8", "--levels", "1"]])
def test_volume_help_shows_its_own_out(argv, capsys):
    assert cli.main([argv[0], "--help"]) == 0
    assert f"(default: npmrf3d-{argv[0]}-out)" in capsys.readouterr().out


# --------------------------------------------------------------------------- alpha


def test_opaque_alpha_is_dropped_with_one_note(place, capsys):
    code = cli.main(["synth", "opaque.png", *TINY])
    captured = capsys.readouterr()
    notes = [line for line in captured.err.splitlines() if line.strip()]
    assert code == 0, captured.err
    assert notes == ["npmrf3d: note: exemplar 'opaque.png': its alpha channel is fully opaque and "
                     "was dropped"]
    assert cli.main(["synth", "opaque.png", *TINY, "--quiet"]) == 0
    assert capsys.readouterr().err == ""


def test_opaque_alpha_leaves_the_colour_channels(place):
    with pytest.warns(InputNote, match="fully opaque"):
        image = load_exemplar("opaque.png")
    assert image.shape == (24, 24, 3)
    np.testing.assert_array_equal(image, load_exemplar("rgb.png"))


# --------------------------------------------------------------------------- run-time warnings


def test_window_replaced_by_the_segmented_preset_is_warned_about(place, capsys):
    code = cli.main(["synth", "seg.png", *TINY, "--window", "3"])
    err = capsys.readouterr().err
    assert code == 0, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("npmrf3d: warning: ")
    assert "--window 3 is not used" in lines[0] and "--segmented no" in lines[0]
    for argv in (["seg.png", *TINY], ["seg.png", *TINY, "--window", "5"],
                 ["seg.png", *TINY, "--window", "3", "--segmented", "no"]):
        assert cli.main(["synth", *argv]) == 0
        assert "warning" not in capsys.readouterr().err, argv


def test_options_that_apply_are_still_accepted(place, capsys):
    for argv in (["volume", "v.npy", *VTINY, "--vector-field", "twist", "--angle", "30"],
                 ["volume", "v.npy", *VTINY, "--vector-field", "dirs.npy"],
                 ["coherent", "seg.png", *TINY, "--coherence-bias", "3", "--global-share", "0.2"],
                 ["kopf", "seg.png", *KTINY, "--histogram-bins", "7"],
                 ["chen-wang", "seg.png", *TINY, "--pca-dims", "16"],
                 ["chen-wang", "seg.png", *TINY, "--global-share", "0"]):
        code = cli.main(argv)
        assert code == 0, (argv, capsys.readouterr().err)
        capsys.readouterr()


def test_progress_shows_no_nan_before_the_first_value(capsys):
    from npmrf3d.cli._progress import LevelProgress

    progress = LevelProgress((8, 8, 8), enabled=True, unit="pass", symbol="E")
    progress(0, 0, 2, float("nan"))
    assert not progress.bar.postfix
    progress(0, 1, 2, 1.5)
    assert progress.bar.postfix == "E=1.5"
    progress.close()
    assert "nan" not in capsys.readouterr().err


# --------------------------------------------------------------------------- the environment


@pytest.mark.parametrize("threads", ["0", "-2", "many"])
def test_numba_threads_of_zero_is_one_line(threads, place, capsys, monkeypatch):
    monkeypatch.setenv("NUMBA_NUM_THREADS", threads)
    line = one_line_error(["info"], place, capsys)
    assert "NUMBA_NUM_THREADS" in line and repr(threads) in line


def test_numba_threads_of_zero_in_a_fresh_process(tmp_path):
    env = {**os.environ, "NUMBA_NUM_THREADS": "0"}
    done = subprocess.run([sys.executable, "-m", "npmrf3d", "info"], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=300)
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and "NUMBA_NUM_THREADS" in done.stderr
    assert "Traceback" not in done.stderr and done.stdout == ""
