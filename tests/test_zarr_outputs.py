"""``--out VOL.zarr`` of every command that makes a volume: the array equals the run folder's
volume; the output is locked for the whole run; a volume replaced with ``--overwrite`` stays
until the new one is complete (made beside it, resumable); a folder that is not an npmrf3d
volume is never replaced; a failed or interrupted run leaves nothing it cannot resume; the
refusal of another run's volume names what differs; ``--block`` is clamped to the volume; the
block plan gives the whole run's time and memory."""

from __future__ import annotations

import errno
import json
import os
import socket
import subprocess
import sys

import numpy as np
import pytest
import zarr

import npmrf3d.methods.blocks as blocks
from npmrf3d.cli import _blocks
from npmrf3d.cli.main import main
from npmrf3d.io.zarr_blocks import finished_blocks

from .cli_checks import COMMANDS, listing, refused_naming

SMALL = ["--size", "16", "--levels", "2", "--quiet"]
#: A block-wise run of the default sampler at 16^3 (``RUN``), into Zarr in 8 blocks of 8 (``BLOCKWISE``).
RUN = ["synth", "bundled:gravel64", "--size", "16", "--levels", "2", "--window", "3", "--blockwise",
       "--whole-voxels", "1", "--quiet"]
BLOCKWISE = [*RUN, "--block", "8"]


def _volume(path) -> np.ndarray:
    return np.asarray(zarr.open_array(path, mode="r")[...])


def _seed(path) -> int:
    return json.loads(zarr.open_array(path, mode="r").attrs["npmrf3d_run"])["config"]["seed"]


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_every_command_writes_its_run_folder_volume_into_zarr(tmp_path, name):
    argv = [*COMMANDS[name], *SMALL]
    assert main([*argv, "--out", str(tmp_path / "v.zarr")]) == 0
    assert main([*argv, "--out", str(tmp_path / "run")]) == 0
    expected = np.load(tmp_path / "run" / "volume.npy")
    array = zarr.open_array(tmp_path / "v.zarr", mode="r")
    assert array.shape == expected.shape == (16, 16, 16, 1)
    np.testing.assert_array_equal(array[...], expected)
    assert "npmrf3d_record" in array.attrs and (tmp_path / "v.zarr" / "preview.png").is_file()
    assert not (tmp_path / "v.zarr" / "volume.npy").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run", "v.zarr"]  # no lock, no staging left


@pytest.mark.parametrize("name", ["chen-wang", "coherent"])
def test_the_block_local_commands_write_zarr_in_blocks(tmp_path, capsys, name):
    argv = [*COMMANDS[name], *SMALL, "--blockwise", "--whole-voxels", "1"]
    assert main([*argv, "--out", str(tmp_path / "v.zarr"), "--block", "8"]) == 0
    assert main([*argv, "--out", str(tmp_path / "run")]) == 0
    array = zarr.open_array(tmp_path / "v.zarr", mode="r")
    assert array.chunks == (8, 8, 8, 1) and len(finished_blocks(tmp_path / "v.zarr")) == 8
    np.testing.assert_array_equal(array[...], np.load(tmp_path / "run" / "volume.npy"))
    refused_naming([*argv, "--out", str(tmp_path / "run2"), "--block", "8"], tmp_path, capsys,
                   words=("--block", "--out VOL.zarr"))


def test_a_second_writer_is_refused_and_mixes_nothing(tmp_path, capsys):
    out = tmp_path / "v.zarr"
    assert main([*BLOCKWISE, "--out", str(out)]) == 0
    before = _volume(out)
    # a live run of another process holds the output's lock
    owner = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (tmp_path / ".v.zarr.lock").write_text(f"{owner.pid} {socket.gethostname()}\n")
        line = refused_naming([*BLOCKWISE, "--out", str(out), "--overwrite", "--seed", "1"], tmp_path, capsys,
                              words=("in use by another run", f"PID {owner.pid}"))
        assert "v.zarr" in line
    finally:
        owner.kill()
        owner.wait()
    np.testing.assert_array_equal(_volume(out), before)
    assert _seed(out) == 0


def test_an_interrupted_overwrite_keeps_the_old_volume_and_resumes(tmp_path, capsys, monkeypatch):
    out = tmp_path / "v.zarr"
    assert main([*BLOCKWISE, "--out", str(out)]) == 0
    old = _volume(out)
    task, made = blocks._task, []

    def cut_off(*args, **kwargs):
        if len(made) == 3:
            raise KeyboardInterrupt
        made.append(args[4])
        return task(*args, **kwargs)

    monkeypatch.setattr(blocks, "_task", cut_off)
    argv = [*BLOCKWISE, "--out", str(out), "--overwrite", "--seed", "1"]
    capsys.readouterr()
    assert main(argv) == 130
    err = capsys.readouterr().err
    np.testing.assert_array_equal(_volume(out), old)
    assert _seed(out) == 0
    kept = [p for p in tmp_path.iterdir() if p.name.startswith(".v.zarr.next-")]
    assert len(kept) == 1 and len(finished_blocks(kept[0])) == 3
    assert f"the 3 finished blocks are kept in '{kept[0]}'" in err
    monkeypatch.setattr(blocks, "_task", task)
    assert main(argv) == 0  # the same command: the 5 other blocks, then the swap
    assert main([*RUN, "--seed", "1", "--out", str(tmp_path / "run")]) == 0
    np.testing.assert_array_equal(_volume(out), np.load(tmp_path / "run" / "volume.npy"))
    assert _seed(out) == 1 and sorted(p.name for p in tmp_path.iterdir()) == ["run", "v.zarr"]


def test_an_interrupted_run_at_once_leaves_nothing_and_keeps_the_old_volume(tmp_path, capsys, monkeypatch):
    out = tmp_path / "v.zarr"
    argv = [*COMMANDS["synth"], *SMALL, "--out", str(out)]
    assert main(argv) == 0
    old = _volume(out)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(_blocks, "run_method", interrupted)
    for target, extra in ((out, ["--overwrite", "--seed", "1"]), (tmp_path / "new.zarr", [])):
        before = listing(tmp_path)
        capsys.readouterr()
        assert main([*argv[:-1], str(target), *extra]) == 130
        err = capsys.readouterr().err
        assert "nothing was written" in err and "block" not in err
        assert listing(tmp_path) == before
    np.testing.assert_array_equal(_volume(out), old)


def test_a_failed_run_leaves_no_array_behind(tmp_path, capsys, monkeypatch):
    def full_disk(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), "chunk")

    monkeypatch.setattr(_blocks, "write_block", full_disk)
    refused_naming([*COMMANDS["synth"], *SMALL, "--out", str(tmp_path / "v.zarr")], tmp_path, capsys,
                   words=("No space left",))
    monkeypatch.setattr(blocks, "write_block", full_disk)
    refused_naming([*BLOCKWISE, "--out", str(tmp_path / "sub" / "v.zarr")], tmp_path, capsys,
                   words=("No space left",))
    # then another run into the same place is not refused as another volume
    monkeypatch.undo()
    assert main([*BLOCKWISE, "--seed", "2", "--out", str(tmp_path / "v.zarr")]) == 0


def test_a_folder_that_is_not_an_npmrf3d_volume_is_never_replaced(tmp_path, capsys):
    mine = tmp_path / "v.zarr"
    mine.mkdir()
    (mine / "data.txt").write_text("mine")
    for argv in ([*COMMANDS["synth"], *SMALL], BLOCKWISE):
        refused_naming([*argv, "--out", str(mine), "--overwrite"], tmp_path, capsys,
                       words=("not a Zarr volume of npmrf3d", "left untouched"), not_words=("--overwrite",))
    assert (mine / "data.txt").read_text() == "mine"


def test_the_refusal_of_another_volume_names_what_differs(tmp_path, capsys):
    out = tmp_path / "v.zarr"
    assert main([*BLOCKWISE, "--out", str(out)]) == 0
    refused_naming([*BLOCKWISE, "--out", str(out), "--seed", "1"], tmp_path, capsys,
                   words=("another seed (0, this run: 1)", "--overwrite"), not_words=("size", "block ("))
    refused_naming([*BLOCKWISE, "--out", str(out), "--block", "4"], tmp_path, capsys,
                   words=("another block (8, this run: 4)",), not_words=("seed", "size"))
    # the same size: what differs is named, not it
    refused_naming([*COMMANDS["synth"], *SMALL, "--out", str(out)], tmp_path, capsys,
                   words=("blockwise (True, this run: False)", "block (8, this run: 16)"), not_words=("size",))


def test_a_block_larger_than_the_volume_is_clamped(tmp_path, capsys):
    argv = [*COMMANDS["synth"], *SMALL, "--blockwise", "--whole-voxels", "1", "--block", "2000"]
    capsys.readouterr()
    assert main([*argv, "--out", str(tmp_path / "v.zarr"), "--dry-run"]) == 0
    said = capsys.readouterr().out
    assert "1 block of 16" in said and "--block 2000 is more than the volume's largest side" in said
    assert listing(tmp_path) == set()
    assert main([*argv, "--out", str(tmp_path / "v.zarr")]) == 0
    assert zarr.open_array(tmp_path / "v.zarr", mode="r").chunks == (16, 16, 16, 1)


def test_the_block_plan_gives_the_whole_runs_time_and_memory(tmp_path, capsys):
    argv = ["synth", "bundled:gravel64", "--size", "1024", "--blockwise", "--out", str(tmp_path / "big.zarr"),
            "--dry-run"]
    assert main(argv) == 0
    one = capsys.readouterr().out
    assert main([*argv, "--workers", "2"]) == 0
    two = capsys.readouterr().out
    assert "216 blocks of 192" in one and "in all: roughly" in one and "of work on 2 cores for the 216 blocks" in one
    assert "(one block at a time)" in one and "(2 workers holding a block each)" in two
    assert listing(tmp_path) == set()


def test_the_dry_run_names_larger_blocks_that_fit_and_save_time(monkeypatch, capsys, tmp_path):
    from npmrf3d.cli import _blocks

    argv = ["synth", "bundled:gravel64", "--size", "1024", "--blockwise", "--out", str(tmp_path / "big.zarr"),
            "--dry-run"]
    monkeypatch.setattr(_blocks, "available_memory", lambda: 64 * 2**30)
    assert main(argv) == 0
    roomy = capsys.readouterr().out
    line = next(ln for ln in roomy.splitlines() if ln.startswith("larger blocks"))
    assert "--block 256: roughly" in line and "--block 512: roughly" in line
    monkeypatch.setattr(_blocks, "available_memory", lambda: 3 * 2**30)   # only blocks of 256 fit
    assert main(argv) == 0
    tight = capsys.readouterr().out
    assert "--block 256: roughly" in tight and "--block 384" not in tight
    assert main([*argv, "--block", "512"]) == 0   # nothing larger to offer
    assert "larger blocks" not in capsys.readouterr().out
    assert listing(tmp_path) == set()
