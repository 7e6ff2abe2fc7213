"""Output folders that cannot be mixed (npmrf3d.io.runs): the exclusive lock on --out, atomic
--overwrite, run.json last, stale staging folders of killed runs cleaned by the next run."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from npmrf3d.errors import ParameterError
from npmrf3d.io import runs
from npmrf3d.io.runs import RUN_FILES, OutputLock, clean_stale_staging, write_run

TINY = ["--size", "8", "--levels", "1", "--window", "3"]


def _write(out, seed=0, **kwargs):
    volume = np.random.default_rng(seed).random((4, 4, 4, 1), dtype=np.float32)
    ex = {"front": np.zeros((6, 6, 1), dtype=np.float32)}
    return write_run(out, volume=volume, exemplars=ex, record={"seed": seed}, **kwargs)


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_second_lock_on_one_folder_is_refused_while_the_owner_lives(tmp_path):
    out = tmp_path / "a" / "out"
    lock = tmp_path / ".a_out.lock"
    lock.write_text(f"{os.getppid()}\n")  # a live process other than this one
    with pytest.raises(ParameterError, match="in use by another run"):
        OutputLock(out).acquire()
    lock.write_text(f"{_dead_pid()} elsewhere.example\n")  # another host: never taken over
    with pytest.raises(ParameterError, match="on elsewhere.example"):
        OutputLock(out).acquire()
    lock.write_text(f"{_dead_pid()}\n")  # its owner died: taken over
    with OutputLock(out):
        assert lock.read_text().split()[0] == str(os.getpid())
        with OutputLock(out):  # re-entrant in one process
            pass
        assert lock.exists()
    assert not lock.exists()


def test_overwrite_swaps_the_whole_folder_and_keeps_other_files(tmp_path):
    out = tmp_path / "out"
    _write(out, seed=1)
    (out / "notes.txt").write_text("mine")
    (out / "metrics.json").write_text("{}")  # the old run's metrics: dropped with it
    with pytest.raises(ParameterError, match="already holds a run"):
        _write(out, seed=2)
    _write(out, seed=2, overwrite=True)
    assert json.loads((out / "run.json").read_text())["seed"] == 2
    assert (out / "notes.txt").read_text() == "mine" and not (out / "metrics.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_failed_overwrite_keeps_the_old_run(tmp_path, monkeypatch):
    out = tmp_path / "out"
    _write(out, seed=1)
    before = (out / "volume.npy").read_bytes()

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runs, "write_volume_tiff", broken)
    with pytest.raises(OSError):
        _write(out, seed=2, overwrite=True)
    assert (out / "volume.npy").read_bytes() == before and (out / "run.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_stale_staging_of_a_dead_owner_is_cleaned_a_live_ones_kept(tmp_path):
    dead, live = _dead_pid(), os.getppid()
    stale = tmp_path / f".out.partial-{dead}-abc"
    stale.mkdir()
    (stale / "volume.npy").write_bytes(b"x")
    busy = tmp_path / f".out.partial-{live}-def"
    busy.mkdir()
    other = tmp_path / f".other.partial-{dead}-ghi"
    other.mkdir()
    _write(tmp_path / "out")
    assert not stale.exists() and busy.exists() and other.exists()
    assert clean_stale_staging(tmp_path / "other") == [other]


def test_two_concurrent_runs_into_one_folder_exactly_one_wins(tmp_path):
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "npmrf3d", "synth", *TINY, "--out", "shared", "--quiet"]
    procs = [subprocess.Popen(cmd, cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    results = []
    for proc in procs:
        _, err = proc.communicate(timeout=600)
        results.append((proc.returncode, err))
    codes = sorted(code for code, _ in results)
    assert codes == [0, 2], results
    loser = next(err for code, err in results if code == 2)
    assert len(loser.strip().splitlines()) == 1
    assert "in use by another run" in loser or "already holds a run" in loser
    out = tmp_path / "shared"
    assert sorted(p.name for p in out.iterdir()) == sorted(RUN_FILES)
    record = json.loads((out / "run.json").read_text())
    assert record["command"] == "synth"
    assert np.load(out / "volume.npy").shape == (8, 8, 8, 1)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shared"]
