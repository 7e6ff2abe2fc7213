"""Ctrl-C, SIGTERM and SIGKILL: checkpoints with a checksum, one-line interruption message with
exit 130, and a resumed run bit-identical to an uninterrupted one."""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from npmrf3d import cli, io
from npmrf3d.errors import ParameterError
from npmrf3d.io.checkpoints import CHECKSUM

#: Two levels, the finest long enough to be interrupted in its middle: about 6 s on one thread
#: of the 2-core EPYC with every site searched (at 24^3 it took about 2 s, and a resumed run
#: sometimes finished before the SIGINT half a second after its lock arrived: a flaky failure;
#: the default's sparse sites make it 2.5 times shorter).
RUN = ["synth", "--size", "48", "--levels", "2", "--window", "5", "--grid", "1", "--seed", "3", "--quiet"]


def _start(cwd: pathlib.Path, *extra: str) -> subprocess.Popen:
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "npmrf3d", *RUN, *extra], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _holds_lock(lock: pathlib.Path, proc: subprocess.Popen) -> bool:
    """Whether ``proc`` holds the run lock (a stale lock is replaced: it may vanish between a
    look and a read)."""
    try:
        return lock.read_text().split()[:1] == [str(proc.pid)]
    except FileNotFoundError:
        return False


def _wait_for(condition, proc: subprocess.Popen, timeout: float = 300) -> None:
    t0 = time.monotonic()
    while not condition():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout
        time.sleep(0.02)


@pytest.mark.slow
def test_sigkill_then_sigint_then_resume_is_bit_identical(tmp_path):
    reference = _start(tmp_path, "--out", "ref")
    assert reference.communicate(timeout=600)[1] == "" and reference.returncode == 0
    checkpoint = tmp_path / "c.npz"
    lock = tmp_path / ".run.lock"

    # 1. SIGKILL in the middle of level 0 (level 1 is in the checkpoint)
    first = _start(tmp_path, "--out", "run", "--checkpoint", "c.npz")
    _wait_for(checkpoint.exists, first)
    first.send_signal(signal.SIGKILL)
    first.communicate(timeout=60)
    assert first.returncode == -signal.SIGKILL
    assert lock.exists() and not (tmp_path / "run").exists()  # a stale lock, no output
    level = io.load_checkpoint(checkpoint)["level"]
    assert level == 1

    # 2. SIGINT in the middle of the resumed level 0: one line, exit 130
    second = _start(tmp_path, "--out", "run", "--checkpoint", "c.npz")
    _wait_for(lambda: _holds_lock(lock, second), second)
    time.sleep(0.5)
    sent = time.monotonic()
    second.send_signal(signal.SIGINT)
    _, err = second.communicate(timeout=60)
    # on failure, say how long the run went on after the signal: a run that finished seconds
    # later lost the signal; one that ended at once had finished before it (failed once in CI
    # at 48^3, not reproduced in 30 local tries)
    assert second.returncode == 130, (err, f"exited {time.monotonic() - sent:.2f} s after SIGINT")
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "c.npz" in lines[0] and "run the same command again" in lines[0]
    assert not lock.exists() and not (tmp_path / "run").exists()

    # 3. SIGTERM is Ctrl-C too
    third = _start(tmp_path, "--out", "run", "--checkpoint", "c.npz")
    _wait_for(lambda: _holds_lock(lock, third), third)
    third.send_signal(signal.SIGTERM)
    _, err = third.communicate(timeout=60)
    assert third.returncode == 130 and len(err.strip().splitlines()) == 1, err

    # 4. the same command again finishes, bit for bit the uninterrupted volume
    last = _start(tmp_path, "--out", "run", "--checkpoint", "c.npz")
    assert last.communicate(timeout=600)[1] == "" and last.returncode == 0
    assert (tmp_path / "run" / "volume.npy").read_bytes() == (tmp_path / "ref" / "volume.npy").read_bytes()
    hidden = sorted(p.name for p in tmp_path.iterdir() if p.name.startswith("."))
    assert hidden == []


@pytest.mark.slow
def test_kopf_sigkill_mid_level_then_resume_is_bit_identical(tmp_path):
    run = ["baseline", "kopf", "--size", "32", "--levels", "2", "--seed", "2", "--quiet"]
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}

    def start(*extra):
        return subprocess.Popen([sys.executable, "-m", "npmrf3d", *run, *extra], cwd=tmp_path,
                                env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    reference = start("--out", "ref")
    assert reference.communicate(timeout=600)[1] == "" and reference.returncode == 0
    checkpoint = tmp_path / "k.npz"
    first = start("--out", "run", "--checkpoint", "k.npz")
    _wait_for(checkpoint.exists, first)
    first.send_signal(signal.SIGKILL)
    first.communicate(timeout=60)
    assert first.returncode == -signal.SIGKILL and not (tmp_path / "run").exists()
    last = start("--out", "run", "--checkpoint", "k.npz")
    assert last.communicate(timeout=600)[1] == "" and last.returncode == 0
    assert (tmp_path / "run" / "volume.npy").read_bytes() == (tmp_path / "ref" / "volume.npy").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def _checkpoint(tmp_path) -> pathlib.Path:
    path = tmp_path / "c.npz"
    io.save_checkpoint(path, volume=np.arange(64, dtype=np.float32), level=1, config="{}")
    return path


def test_checkpoint_has_a_checksum_and_round_trips(tmp_path):
    path = _checkpoint(tmp_path)
    with np.load(path) as raw:
        assert CHECKSUM in raw.files
    loaded = io.load_checkpoint(path)
    assert CHECKSUM not in loaded and loaded["level"] == 1
    assert np.array_equal(loaded["volume"], np.arange(64, dtype=np.float32))


@pytest.mark.parametrize("offset", [-300, -200, 60, 120, 200, 400])
def test_a_corrupt_byte_is_refused_with_exit_2_and_says_why(offset, tmp_path, capsys):
    path = _checkpoint(tmp_path)
    data = bytearray(path.read_bytes())
    data[offset] ^= 0x5A
    path.write_bytes(bytes(data))
    with pytest.raises(ParameterError) as info:
        io.load_checkpoint(path)
    text = str(info.value)
    assert "damaged" in text or "cannot be read" in text or "not an npmrf3d checkpoint" in text
    code = cli.main(["synth", "--size", "8", "--levels", "1", "--window", "3", "--checkpoint",
                     str(path), "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "checkpoint" in err
    assert not (tmp_path / "out").exists()


def test_a_changed_value_with_a_valid_zip_is_caught_by_the_checksum(tmp_path):
    path = _checkpoint(tmp_path)
    with np.load(path) as raw:
        members = {name: raw[name] for name in raw.files}
    members["volume"] = members["volume"] + 1  # a consistent zip, a wrong checksum
    with open(path, "wb") as handle:
        np.savez(handle, **members)
    with pytest.raises(ParameterError, match="checksum does not match"):
        io.load_checkpoint(path)


def test_a_checkpoint_without_checksum_is_not_ours(tmp_path):
    path = tmp_path / "foreign.npz"
    np.savez(path, volume=np.zeros(3))
    with pytest.raises(ParameterError, match="is not a checkpoint file of npmrf3d") as info:
        io.load_checkpoint(path)
    assert "delete" not in str(info.value)
