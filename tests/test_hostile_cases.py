"""Hostile inputs on every sub-command: odd files, odd numbers, odd folders, odd environments.

Each refusal is one line ``npmrf3d[ <command>]: error: ...`` on stderr, exit code 2, no
traceback, nothing new in the working folder. ``REFUSALS`` lists (argv, words the line holds,
words it must not hold); the neural cases need torch and a tiny trained model.
"""

from __future__ import annotations

import os
import pathlib
import stat
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from npmrf3d import cli
from tests.cli_checks import one_line_error, refused_naming

TINY = ["--size", "8", "--levels", "1", "--window", "3", "--dry-run"]
KTINY = ["--size", "8", "--levels", "1", "--window", "4", "--iterations", "1", "--dry-run"]
VTINY = ["--size", "8", "--levels", "1", "--dry-run"]


def _npy_claiming(path: pathlib.Path, shape: tuple[int, ...]) -> None:
    """A .npy file whose header claims ``shape`` (float32) over a few bytes of data."""
    header = repr({"descr": "<f4", "fortran_order": False, "shape": shape}).encode()
    header += b" " * (64 - (10 + len(header) + 1) % 64) + b"\n"
    path.write_bytes(b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + bytes(4096))


class _Unpickled:
    """Unpickling this would create the file 'UNPICKLED' in the working folder."""

    def __reduce__(self):
        return (pathlib.Path.touch, (pathlib.Path("UNPICKLED"),))


@pytest.fixture
def place(tmp_path, monkeypatch) -> pathlib.Path:
    """A working folder with the files the cases name."""
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(0)
    iio.imwrite(tmp_path / "good.png", rng.integers(0, 256, (24, 24, 3), dtype=np.uint8))
    iio.imwrite(tmp_path / "grey.png", rng.integers(0, 256, (24, 24), dtype=np.uint8))
    np.save(tmp_path / "v.npy", rng.random((16, 16, 16)).astype(np.float32))
    np.save(tmp_path / "v3.npy", rng.random((16, 16, 16, 3)).astype(np.float32))
    np.save(tmp_path / "img2d.npy", rng.random((24, 24)).astype(np.float32))
    np.save(tmp_path / "five.npy", rng.random((4, 4, 4, 4, 2)).astype(np.float32))
    np.save(tmp_path / "scalar.npy", np.float32(3.0))
    np.save(tmp_path / "obj.npy", np.array([{"a": 1}, None], dtype=object), allow_pickle=True)
    evil = np.empty(2, dtype=object)
    evil[0], evil[1] = _Unpickled(), 1
    np.save(tmp_path / "evil.npy", evil, allow_pickle=True)
    _npy_claiming(tmp_path / "huge.npy", (10_000, 10_000, 10_000))
    (tmp_path / "zero.png").write_bytes(b"")
    (tmp_path / "adir").mkdir()
    (tmp_path / "emptydir").mkdir()
    (tmp_path / "ro").mkdir()
    (tmp_path / "afile").write_text("x")
    if hasattr(os, "mkfifo"):
        os.mkfifo(tmp_path / "fifo")
    return tmp_path




#: (argv, words the error line holds, words it must not hold)
REFUSALS = [
    # the shapes of a per-level list and a kopf mean-shift, as the command line spells them
    (["coherent", "good.png", *TINY, "--iterations", ""], ["argument --iterations", "integers"],
     ["_parse_tuple"]),
    (["coherent", "good.png", *TINY, "--window", "3,x"], ["argument --window", "'3,x'"],
     ["_parse_tuple"]),
    (["chen-wang", "good.png", *TINY, "--iterations", "1,y"], ["argument --iterations"],
     ["_parse_tuple"]),
    (["coherent", "good.png", *TINY, "--window", "3,5,7"], ["--window must be one integer (one level)"],
     ["1 integers"]),
    (["coherent", "good.png", *TINY, "--iterations", "1,2"], ["--iterations must be one integer"],
     ["1 integers"]),
    (["kopf", "good.png", *KTINY, "--mean-shift", ""], ["--mean-shift", "'none'"], []),
    # odd exemplar files
    (["synth", "adir", *TINY], ["'adir'", "not a file"], []),
    (["synth", "/dev/null", *TINY], ["'/dev/null'", "not a file"], []),
    (["synth", "zero.png", *TINY], ["'zero.png'", "cannot be read"], []),
    (["synth", "obj.npy", *TINY], ["'obj.npy'", "cannot be read"], []),
    (["synth", "good.png", "--exemplar-front", "evil.npy", *TINY], ["'evil.npy'"], []),
    (["synth", "huge.npy", *TINY], ["'huge.npy'", "cannot be read"], []),
    (["volume", "img2d.npy", *VTINY], ["2D image", "needs a volume"], []),
    (["volume", "five.npy", *VTINY], ["(4, 4, 4, 4, 2)"], []),
    (["volume", "v.npy", *VTINY, "--vector-field", "evil.npy"], ["'evil.npy'"], []),
    (["kopf", "good.png", *KTINY, "--constraint", "huge.npy"], ["'huge.npy'"], []),
    # odd --out folders
    (["synth", "good.png", *TINY, "--out", "afile/x/y"], ["is not a folder"], []),
    (["synth", "good.png", *TINY, "--out", "a" * 300], ["cannot read or write"], []),
    (["synth", "good.png", *TINY, "--out", "good.png"], ["exists and is not a folder"], []),
    (["metrics", "good.png", "v3.npy", "--out", "afile/m"], ["is not a folder"], []),
    # numbers at and past their bounds
    (["synth", "good.png", "--size", "1e400", "--levels", "1", "--dry-run"], ["--size must"], []),
    (["synth", "good.png", "--size", " ", "--levels", "1", "--dry-run"], ["--size must"], []),
    (["synth", "good.png", "--size", "8,-8,8", "--levels", "1", "--dry-run"], ["--size must be positive"], []),
    (["synth", "good.png", *TINY, "--bandwidth", "1e400"], ["--bandwidth must", "got inf"], []),
    (["synth", "good.png", *TINY, "--stop", "nan"], ["--stop must", "got nan"], []),
    (["coherent", "good.png", *TINY, "--k", "1000000000"], ["--k must be between"], []),
    (["coherent", "good.png", *TINY, "--global-share", "2"], ["--global-share must"], []),
    (["kopf", "good.png", *KTINY, "--r", "nan"], ["--r must"], []),
    (["chen-wang", "good.png", *TINY, "--batches", "0"], ["--batches must"], []),
    (["chen-wang", "good.png", *TINY, "--views", "front,right,top,front"], ["--views must not repeat"], []),
    (["volume", "v.npy", *VTINY, "--spacing", "1,1"], ["--spacing must be one number or three"], []),
    (["volume", "v.npy", *VTINY, "--passes", "100000000000000000000"], ["--passes must"], []),
    # metrics on mismatched or mis-shaped volumes
    (["metrics", "good.png", "v.npy", "--out", "m"], ["3 channel(s)", "the volume has 1"], []),
    (["metrics", "good.png", "img2d.npy", "--out", "m"], ["(24, 24)"], []),
    (["metrics", "good.png", "five.npy", "--out", "m"], ["(4, 4, 4, 4, 2)"], []),
    (["metrics", "good.png", "scalar.npy", "--out", "m"], ["got shape ()"], []),
    # report, study and the command line itself
    (["report", "emptydir"], ["no study results"], []),
    (["report", "good.png"], ["not a folder"], []),
    (["study", "heuristics", "--quick", "--seeds", "1", "1", "--out", "st", "--scheduler", "serial"],
     ["not unique"], []),
    (["frobnicate"], ["invalid choice"], []),
    (["synth", "good.png", "grey.png", *TINY], ["unrecognized arguments: grey.png"], []),
]


@pytest.mark.parametrize("argv, words, not_words", REFUSALS,
                         ids=[" ".join(a) or "(none)" for a, _, _ in REFUSALS])
def test_refusal(argv, words, not_words, place, capsys):
    refused_naming(argv, place, capsys, words, not_words)
    assert not (place / "UNPICKLED").exists()


def test_the_refusals_are_distinct():
    assert len({tuple(argv) for argv, _, _ in REFUSALS}) == len(REFUSALS)


@pytest.mark.parametrize("argv", [["synth", "fifo", *TINY], ["kopf", "good.png", *KTINY, "--constraint", "fifo"]])
def test_a_fifo_is_refused_without_blocking(argv, place, capsys):
    assert "not a file" in one_line_error(argv, place, capsys)


@pytest.mark.parametrize("argv", [
    ["synth", "good.png", "--size", "\uff18", "--levels", "1", "--window", "3", "--dry-run"],  # fullwidth 8
    ["kopf", "good.png", *KTINY, "--mean-shift", "none"],
    ["synth", "good.png", "--size", "32", "--size", "8", "--levels", "1", "--window", "3", "--dry-run"],
])
def test_odd_but_good_input_works(argv, place, capsys):
    assert cli.main(argv) == 0, capsys.readouterr().err


# --------------------------------------------------------------------------- unwritable folders

def _unwritable(monkeypatch, name: str = "ro") -> None:
    """Make the folder ``name`` read as unwritable (the tests may run as root, whom permission
    bits do not stop)."""
    real = os.access

    def access(path, mode, *args, **kwargs):
        if pathlib.Path(path).name == name and mode & os.W_OK:
            return False
        return real(path, mode, *args, **kwargs)

    monkeypatch.setattr(os, "access", access)


@pytest.mark.parametrize("argv", [
    ["synth", "good.png", *TINY, "--out", "o", "--checkpoint", "ro/c.npz"],
    ["synth", "good.png", *TINY[:-1], "--out", "o", "--checkpoint", "ro/c.npz"],
    ["volume", "v.npy", *VTINY[:-1], "--out", "o", "--checkpoint", "ro/c.npz"],
    ["chen-wang", "good.png", *TINY[:-1], "--out", "o", "--checkpoint", "ro/c.npz"],
])
def test_unwritable_checkpoint_folder_is_refused_before_the_work(argv, place, capsys, monkeypatch):
    _unwritable(monkeypatch)
    line = one_line_error(argv, place, capsys)
    assert "folder of checkpoint 'ro/c.npz' is not writable" in line


# --------------------------------------------------------------------------- cache folders

def test_cache_folder_falls_back_to_a_private_temporary_folder(tmp_path, monkeypatch):
    from npmrf3d import _cache_folders
    from npmrf3d._kernels import _jit

    (tmp_path / "afile").write_text("x")
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "afile" / "numba"))
    chosen = pathlib.Path(_jit._cache_dir())
    assert chosen.name == _jit.SOURCES_FOLDER
    private = chosen.parent
    assert private.parent == tmp_path and private.name.startswith("npmrf3d-numba-")
    assert stat.S_IMODE(private.stat().st_mode) & 0o077 == 0
    # a shared folder another user could write is never used
    private.chmod(0o777)
    assert _cache_folders.private_temp_folder("numba") is None
    assert _jit._cache_dir() is None


def test_cache_folder_is_keyed_by_the_kernels_sources(tmp_path, monkeypatch):
    from npmrf3d._kernels import _jit

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    chosen = pathlib.Path(_jit._cache_dir())
    assert chosen == tmp_path / "numba" / _jit.SOURCES_FOLDER and chosen.is_dir()
    # a worker process inherits the subfolder and keeps it (no folder inside the folder)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(chosen))
    assert pathlib.Path(_jit._cache_dir()) == chosen
    # one byte of any kernel module changed (a helper other kernels inline): another folder
    copy = tmp_path / "kernels"
    copy.mkdir()
    for path in pathlib.Path(_jit.__file__).parent.glob("*.py"):
        (copy / path.name).write_bytes(path.read_bytes())
    assert f"kernels-{_jit.kernel_sources_digest(copy)}" == _jit.SOURCES_FOLDER
    helper = copy / "vecmath.py"
    helper.write_bytes(helper.read_bytes() + b"\n")
    assert f"kernels-{_jit.kernel_sources_digest(copy)}" != _jit.SOURCES_FOLDER


def test_info_works_when_the_home_folder_cannot_be_written(tmp_path):
    (tmp_path / "afile").write_text("x")
    temp = tmp_path / "temp"
    temp.mkdir()
    env = {key: value for key, value in os.environ.items()
           if key not in ("NUMBA_CACHE_DIR", "MPLCONFIGDIR", "XDG_CACHE_HOME", "XDG_CONFIG_HOME")}
    env.update(HOME=str(tmp_path / "afile"), TMPDIR=str(temp), NUMBA_NUM_THREADS="1",
               PYTHONPATH=str(pathlib.Path(__file__).resolve().parents[1]))
    done = subprocess.run([sys.executable, "-m", "npmrf3d", "info"], env=env, capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == ""
    assert {p.name.rsplit("-", 1)[0] for p in temp.iterdir()} >= {"npmrf3d-numba", "npmrf3d-matplotlib"}
