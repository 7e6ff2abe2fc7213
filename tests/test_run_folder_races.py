"""Run folders shared between commands: a reader against a run replacing the folder, a
checkpoint that clashes with ``--out``, an overwrite of the folder the shell stands in, and the
mode of the folders a run makes.

Every refusal is one line, exit code 2, no traceback, and leaves the files as they were.
"""

from __future__ import annotations

import json
import os
import pathlib
import stat
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from npmrf3d.cli import main
from npmrf3d.errors import ParameterError
from npmrf3d.io.runs import RUN_FILES, write_run

REPO = pathlib.Path(__file__).resolve().parents[1]
TINY = ["--size", "8", "--levels", "1", "--window", "3", "--quiet"]


def _write(out, seed=0, **kwargs):
    volume = np.random.default_rng(seed).random((8, 8, 8, 1), dtype=np.float32)
    ex = {"front": np.zeros((8, 8, 1), dtype=np.float32)}
    return write_run(out, volume=volume, exemplars=ex, record={"seed": seed}, **kwargs)


def _listing(root: pathlib.Path) -> dict[str, bytes | None]:
    """Every path under ``root`` with its bytes (None for folders)."""
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_bytes())
            for p in sorted(root.rglob("*"))}


def _refused(capsys, argv) -> str:
    code = main(argv)
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert code == 2, captured.err
    assert len(lines) == 1, captured.err
    assert lines[0].startswith("npmrf3d: error: ")
    assert "Traceback" not in captured.err and captured.out == ""
    return lines[0]


@pytest.fixture
def exemplar(tmp_path) -> pathlib.Path:
    """A 16x16 random 8-bit grey PNG."""
    path = tmp_path / "exemplar.png"
    iio.imwrite(path, np.random.default_rng(0).integers(0, 256, (16, 16), dtype=np.uint8))
    return path


@pytest.fixture
def no_work(monkeypatch):
    """Synthesis must not start: every command's method run fails the test."""
    def never(*args, **kwargs):
        raise AssertionError("the run started although its arguments clash")

    for module in ("synth", "_blocks"):
        monkeypatch.setattr(f"npmrf3d.cli.{module}.run_method", never)


# --------------------------------------------------------------------------- a reader and a run


def test_metrics_refuses_a_run_folder_that_a_run_holds(tmp_path, exemplar, capsys):
    run = tmp_path / "run"
    _write(run)
    lock = tmp_path / ".run.lock"
    lock.write_text(f"{os.getppid()}\n")  # a live process other than this one: a run replacing it
    before = _listing(tmp_path)
    line = _refused(capsys, ["metrics", str(exemplar), str(run / "volume.npy")])
    assert f"run folder '{run}' is in use by another run" in line
    assert "run npmrf3d metrics again" in line
    assert _listing(tmp_path) == before  # no metrics.json, no histograms.png
    lock.unlink()
    assert main(["metrics", str(exemplar), str(run / "volume.npy")]) == 0
    assert (run / "metrics.json").is_file()


def test_metrics_refuses_when_its_volume_folder_is_held_even_with_another_out(tmp_path, exemplar, capsys):
    run, elsewhere = tmp_path / "run", tmp_path / "elsewhere"
    _write(run)
    (tmp_path / ".run.lock").write_text(f"{os.getppid()}\n")
    line = _refused(capsys, ["metrics", str(exemplar), str(run / "volume.npy"), "--out", str(elsewhere)])
    assert "is in use by another run" in line
    assert not elsewhere.exists()


def test_an_overwrite_cannot_swap_the_folder_while_metrics_read_it(tmp_path, exemplar, capsys, monkeypatch):
    """Between reading the volume and writing metrics.json, a run in another process tries to
    replace the folder: it is refused, and the metrics land beside the volume they describe."""
    import npmrf3d.cli.metrics as command

    run = tmp_path / "run"
    _write(run, seed=1)
    volume_before = (run / "volume.npy").read_bytes()
    evaluate = command.metrics.evaluate
    attempts = []

    def evaluate_while_a_run_overwrites(*args, **kwargs):
        script = ("import numpy as np, sys\n"
                  "from npmrf3d.io.runs import write_run\n"
                  "from npmrf3d.errors import ParameterError\n"
                  "try:\n"
                  "    write_run(sys.argv[1], volume=np.zeros((8, 8, 8, 1), np.float32),\n"
                  "              exemplars={'front': np.zeros((8, 8, 1), np.float32)},\n"
                  "              record={'seed': 2}, overwrite=True)\n"
                  "except ParameterError as exc:\n"
                  "    print(exc)\n"
                  "    sys.exit(3)\n")
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        attempts.append(subprocess.run([sys.executable, "-c", script, str(run)], capture_output=True,
                                       text=True, env=env, timeout=300))
        return evaluate(*args, **kwargs)

    monkeypatch.setattr(command.metrics, "evaluate", evaluate_while_a_run_overwrites)
    assert main(["metrics", str(exemplar), str(run / "volume.npy")]) == 0
    capsys.readouterr()
    (attempt,) = attempts
    assert attempt.returncode == 3, attempt.stderr
    assert "in use by another run" in attempt.stdout
    assert (run / "volume.npy").read_bytes() == volume_before
    assert json.loads((run / "run.json").read_text())["seed"] == 1
    assert (run / "metrics.json").is_file() and (run / "histograms.png").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exemplar.png", "run"]  # lock released


def test_metrics_of_a_plain_folder_takes_no_lock(tmp_path, exemplar, capsys):
    """A volume in a folder that is not a run folder: nothing to lock, nothing left beside it."""
    data = tmp_path / "data"
    data.mkdir()
    np.save(data / "mine.npy", np.random.default_rng(1).random((8, 8, 8), dtype=np.float32))
    assert main(["metrics", str(exemplar), str(data / "mine.npy")]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data", "exemplar.png"]


# --------------------------------------------------------------------------- checkpoint and --out


@pytest.mark.parametrize("command", [["synth"], ["baseline", "chen-wang"], ["baseline", "kopf"]])
def test_checkpoint_that_is_the_out_folder_is_refused_before_any_work(command, tmp_path, exemplar,
                                                                      capsys, no_work):
    same = tmp_path / "x"
    extra = ["--window", "4", "--iterations", "1"] if command[0] == "baseline" else ["--window", "3"]
    line = _refused(capsys, [*command, str(exemplar), "--size", "8", "--levels", "1", *extra, "--quiet",
                             "--checkpoint", str(same), "--out", str(same)])
    assert f"checkpoint '{same}' is the output" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exemplar.png"]


def test_checkpoint_is_checked_against_out_by_the_volume_command(tmp_path, capsys, no_work):
    same = tmp_path / "x"
    line = _refused(capsys, ["volume", str(tmp_path / "missing.npy"), "--size", "8", "--levels", "1",
                             "--checkpoint", str(same), "--out", str(same)])
    assert "is the output" in line
    assert list(tmp_path.iterdir()) == []


def test_checkpoint_above_the_out_folder_is_refused(tmp_path, exemplar, capsys, no_work):
    line = _refused(capsys, ["synth", str(exemplar), *TINY, "--checkpoint", str(tmp_path / "ck"),
                             "--out", str(tmp_path / "ck" / "run")])
    assert "folder holding the output folder" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["exemplar.png"]


@pytest.mark.parametrize("name", [*RUN_FILES, "metrics.json", "histograms.png"])
@pytest.mark.parametrize("overwrite", [False, True])
def test_checkpoint_named_as_a_run_file_of_out_is_refused(name, overwrite, tmp_path, exemplar, capsys, no_work):
    out = tmp_path / "run"
    out.mkdir()
    if overwrite:
        _write(out)
    before = _listing(tmp_path)
    line = _refused(capsys, ["synth", str(exemplar), *TINY, "--checkpoint", str(out / name),
                             "--out", str(out), *(["--overwrite"] if overwrite else [])])
    assert f"is the run file {name} of the output folder" in line
    assert _listing(tmp_path) == before


@pytest.mark.parametrize("kind", ["their volume.npy", "a text file", "a zip archive", "an empty file",
                                  "an npz without a checksum"])
def test_file_that_is_not_a_checkpoint_is_refused_untouched(kind, tmp_path, exemplar, capsys, no_work):
    theirs = tmp_path / "mine" / ("volume.npy" if kind == "their volume.npy" else "ck.npz")
    theirs.parent.mkdir()
    if kind == "their volume.npy":
        np.save(theirs, np.ones((8, 8, 8), dtype=np.float32))
    elif kind == "a text file":
        theirs.write_text("my notes")
    elif kind == "a zip archive":
        import zipfile

        with zipfile.ZipFile(theirs, "w") as archive:
            archive.writestr("notes.txt", "mine")
    elif kind == "an empty file":
        theirs.write_bytes(b"")
    else:
        np.savez(theirs, a=np.arange(3))
    before = _listing(tmp_path)
    line = _refused(capsys, ["synth", str(exemplar), *TINY, "--checkpoint", str(theirs),
                             "--out", str(tmp_path / "run")])
    assert "is not a checkpoint file of npmrf3d" in line
    assert "delete" not in line
    assert _listing(tmp_path) == before


def test_library_refuses_a_file_that_is_not_a_checkpoint_without_advising_to_delete_it(tmp_path):
    from npmrf3d.io.checkpoints import load_checkpoint

    theirs = tmp_path / "volume.npy"
    np.save(theirs, np.ones(3))
    with pytest.raises(ParameterError, match="is not a checkpoint file of npmrf3d") as caught:
        load_checkpoint(theirs)
    assert "delete" not in str(caught.value)


def test_checkpoint_inside_out_with_its_own_name_survives_an_overwrite(tmp_path, exemplar, capsys):
    out = tmp_path / "run"
    out.mkdir()
    checkpoint = out / "ck.npz"
    argv = ["synth", str(exemplar), *TINY, "--checkpoint", str(checkpoint), "--out", str(out)]
    assert main(argv) == 0
    first = np.load(out / "volume.npy")
    assert main([*argv, "--overwrite"]) == 0  # resumes the finished run, carried along by the swap
    capsys.readouterr()
    assert checkpoint.is_file()
    np.testing.assert_array_equal(np.load(out / "volume.npy"), first)


# --------------------------------------------------------------------------- the folder of the shell


@pytest.mark.parametrize("where, words", [(".", "the current working folder"),
                                          ("..", "a parent of the current working folder"),
                                          ("HOME", "the home folder")])
def test_overwrite_of_the_working_folder_its_parents_or_home_is_refused(where, words, tmp_path, exemplar,
                                                                       capsys, monkeypatch, no_work):
    home = tmp_path / "home"
    home.mkdir()
    work = tmp_path / "w" / "work"
    work.mkdir(parents=True)
    _write(work)
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    out = str(home) if where == "HOME" else where
    before = _listing(tmp_path)
    line = _refused(capsys, ["synth", str(exemplar), *TINY, "--out", out, "--overwrite"])
    assert words in line and "--overwrite replaces the whole folder" in line
    assert _listing(tmp_path) == before
    assert pathlib.Path.cwd() == work and work.is_dir()


def test_library_overwrite_of_the_working_folder_is_refused(tmp_path, monkeypatch):
    work = tmp_path / "work"
    _write(work, seed=1)
    monkeypatch.chdir(work)
    before = _listing(tmp_path)
    with pytest.raises(ParameterError, match="the current working folder"):
        _write(".", seed=2, overwrite=True)
    assert _listing(tmp_path) == before
    _write(work / "sub", seed=2, overwrite=True)  # a folder below the working folder is fine
    assert (work / "sub" / "run.json").is_file()


# --------------------------------------------------------------------------- folder modes


@pytest.fixture(params=[0o022, 0o077], ids=["umask022", "umask077"])
def umask(request):
    old = os.umask(request.param)
    try:
        yield request.param
    finally:
        os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_new_run_folder_follows_the_umask(umask, tmp_path):
    _write(tmp_path / "run")
    assert _mode(tmp_path / "run") == 0o777 & ~umask
    _write(tmp_path / "a" / "b" / "run")  # made below new folders
    assert _mode(tmp_path / "a" / "b" / "run") == 0o777 & ~umask
    assert all(_mode(tmp_path / "run" / name) == 0o666 & ~umask for name in RUN_FILES)


@pytest.mark.parametrize("mode", [0o755, 0o750, 0o700])
def test_overwrite_keeps_the_folders_mode(mode, umask, tmp_path):
    out = tmp_path / "run"
    _write(out, seed=1)
    os.chmod(out, mode)
    _write(out, seed=2, overwrite=True)
    assert json.loads((out / "run.json").read_text())["seed"] == 2
    assert _mode(out) == mode


def test_cli_run_folder_follows_the_umask(umask, tmp_path, exemplar, capsys):
    assert main(["synth", str(exemplar), *TINY, "--out", str(tmp_path / "run")]) == 0
    assert _mode(tmp_path / "run") == 0o777 & ~umask
