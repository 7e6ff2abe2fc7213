"""One-line errors everywhere: every sub-command, bad option types and values, bad files, study
and report failures, a full disk.

Each bad input must give exactly one line ``npmrf3d[ <command>]: error: ...`` on stderr, exit
code 2, no traceback, and leave nothing new in the working folder. ``BAD_INPUTS`` counts them.
"""

from __future__ import annotations

import errno
import json
import pathlib

import imageio.v3 as iio
import numpy as np
import pytest

from npmrf3d import cli
from tests.cli_checks import one_line_error

TINY = ["--size", "8", "--levels", "1", "--window", "3"]
KTINY = ["--size", "8", "--levels", "1", "--window", "4", "--iterations", "1"]

#: (sub-command argv) of every bad input; files named here are made by the ``place`` fixture.
SYNTH_TYPES = [["synth", opt, "x"] for opt in (
    "--window", "--levels", "--xi", "--stop", "--max-sweeps", "--t0", "--t-end", "--proposals",
    "--bandwidth", "--centre-bandwidth", "--adaptive", "--tau", "--histogram-weight", "--outlier",
    "--grey-levels", "--palette", "--seed")] + [
    ["synth", "--window", "3.5"], ["synth", "--max-sweeps", "1.5"], ["synth", "--bogus-flag"],
    ["synth", "a.png", "b.png"], ["synth", "--window"],
]
SYNTH_VALUES = [["synth", *TINY, *extra] for extra in (
    ["--window", "4"], ["--window", "1"], ["--window", "17"], ["--levels", "0"], ["--levels", "9"],
    ["--size", "0"], ["--size", "-8"], ["--size", "8,8"], ["--size", "a,b,c"], ["--size", ""],
    ["--size", "7", "--levels", "2"], ["--size", "2", "--window", "7"],
    ["--heuristic", "ML_X"], ["--relaxation", "gibbs"], ["--xi", "0"], ["--xi", "1"],
    ["--xi", "nan"], ["--xi", "-inf"], ["--stop", "0"], ["--stop", "1.5"], ["--max-sweeps", "0"],
    ["--relaxation", "anneal", "--sampler", "gibbs"], ["--relaxation", "anneal", "--schedule", "cosine"],
    ["--relaxation", "anneal", "--t0", "0"], ["--relaxation", "anneal", "--t0", "-1"],
    ["--relaxation", "anneal", "--t-end", "2"], ["--relaxation", "anneal", "--proposals", "0"],
    ["--relaxation", "anneal", "--proposal", "uniform"], ["--variant", "paper"],
    ["--bandwidth", "0"], ["--bandwidth", "-1"], ["--bandwidth", "inf"],
    ["--centre-bandwidth", "0"], ["--adaptive", "-1"], ["--decision", "vote"], ["--tau", "0"],
    ["--histogram-weight", "-1"], ["--outlier", "1"], ["--outlier", "-0.1"],
    ["--grey-levels", "1"], ["--grey-levels", "70000"], ["--palette", "1"], ["--seed", "-1"],
    ["--views", "side"], ["--views", ""], ["--views", "front,front"], ["--upsample", "2/8"],
    ["--inherit", "always"], ["--relaxation", "anneal", "--heuristic", "ML_H1a"],
    ["--heuristic", "ML_H1b", "--decision", "sample"],
    ["missing.png"], ["folder"], ["text.txt"], ["truncated.png"], ["garbage.npy"], ["nan.npy"],
    ["inf.npy"], ["small.png", "--window", "5"], ["complex.npy"], ["four_d.npy"], ["empty.npy"],
    ["bundled:nope"], ["--exemplar-front", "missing.png"], ["--exemplar-top", "truncated.png"],
    ["--out", ""], ["--out", "/"], ["--out", "afile"], ["--out", "afile/sub"], ["--checkpoint", "folder"],
    ["--checkpoint", "nofolder/c.npz"], ["--checkpoint", "foreign.npz"],
    ["--checkpoint", "garbage.npz"], ["--size", "4096", "--levels", "1"],
    ["--size", "100000", "--levels", "1"], ["sp ace/ünï.png"],
)]
KOPF = [["baseline", "kopf", *extra] for extra in (
    ["--window", "x"], ["--grid", "z"], ["--r", "x"], ["--eps", "x"], ["--seed", "x"],
    ["--levels", "x"], ["--variance", "x"], ["--histogram-bins", "x"], ["--histogram-weight", "x"],
    [*KTINY, "--iterations", "x"], [*KTINY, "--iterations", "0"], [*KTINY, "--mean-shift", "a,b"],
    [*KTINY, "--mean-shift", "1,2,3"], [*KTINY, "--window", "1"], [*KTINY, "--r", "3"],
    [*KTINY, "--eps", "-1"], [*KTINY, "--variance", "0"], [*KTINY, "--variance", "2"],
    [*KTINY, "--grid", "0"], [*KTINY, "--histogram-bins", "1"], [*KTINY, "--histogram-weight", "-1"],
    [*KTINY, "--upsample", "cubic"], [*KTINY, "--views", "side"], [*KTINY, "--constraint", "missing.npy"],
    [*KTINY, "--constraint-weight", "abc"], [*KTINY, "--constraint", "garbage.npy"],
    [*KTINY, "--size", "4096"], [*KTINY, "--levels", "0"], [*KTINY, "--checkpoint", "foreign.npz"],
    [*KTINY, "--out", "afile"], [*KTINY, "truncated.png"], [*KTINY, "nan.npy"], ["nonesuch"],
    ["--nonsense"], [*KTINY, "--window", "9", "small.png"], [*KTINY, "--constraint", "vol.npy", "--size", "16"],
)]
METRICS = [["metrics"], ["metrics", "missing.png", "vol.npy"], ["metrics", "bundled:gravel64", "missing.npy"],
           ["metrics", "bundled:gravel64", "garbage.npy"], ["metrics", "bundled:gravel64", "vol.npy", "--views", "x"],
           ["metrics", "truncated.png", "vol.npy"], ["metrics", "bundled:gravel64", "text.txt"],
           ["metrics", "bundled:gravel64", "vol.npy", "--out", "afile"]]
STUDY = [["study", *extra] for extra in (
    ["nonesuch", "--quick"], ["heuristics", "--workers", "0"], ["heuristics", "--workers", "-1"],
    ["heuristics", "--workers", "x"], ["heuristics", "--threads", "-1"], ["heuristics", "--threads", "0"],
    ["heuristics", "--threads", "x"], ["heuristics", "--seeds", "-1"], ["heuristics", "--seeds", "x"],
    ["heuristics", "--size", "0"], ["heuristics", "--levels", "0"], ["heuristics", "--slice-axis", "5"],
    ["heuristics", "--quick", "--scheduler", "bogus"], ["heuristics", "--quick", "--scheduler", "tcp://127.0.0.1:1"],
    ["heuristics", "--quick", "--scheduler", "tcp://localhost"], ["heuristics", "--quick", "--scheduler", "http://x:1"],
    ["heuristics", "--quick", "--scheduler", "tcp://h:99999"], ["heuristics", "--quick", "--out", "afile"],
    ["heuristics", "--quick", "--out", "afile/sub"], ["heuristics", "--quick", "--out", ""],
    ["groundtruth", "--quick", "--scheduler", "serial"],
    ["groundtruth", "--quick", "--scheduler", "serial", "--volume", "missing.npy"],
    ["groundtruth", "--quick", "--scheduler", "serial", "--volume", "garbage.npy"], [],
)]
REPORT = [["report", *extra] for extra in (
    ["missing"], ["afile"], ["emptydir"], ["badjson"], ["badcsv"], ["listjson"], ["binarycsv"],
    ["badjson", "--out", "folder"], ["badjson", "--out", "nofolder/r.html"], [],
)]
OTHER = [[], ["nonesuch"], ["--bogus"], ["info", "extra"], ["baseline"], ["baseline", "nonesuch"]]
BAD_INPUTS = SYNTH_TYPES + SYNTH_VALUES + KOPF + METRICS + STUDY + REPORT + OTHER


def _study_folder(root: pathlib.Path, csv_text: bytes, json_text: str | None) -> None:
    root.mkdir()
    (root / "results.csv").write_bytes(csv_text)
    if json_text is not None:
        (root / "study.json").write_text(json_text)


@pytest.fixture
def place(tmp_path, monkeypatch) -> pathlib.Path:
    """A working folder holding every bad file that BAD_INPUTS names."""
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(0)
    iio.imwrite(tmp_path / "good.png", rng.integers(0, 256, (24, 24), dtype=np.uint8))
    (tmp_path / "truncated.png").write_bytes((tmp_path / "good.png").read_bytes()[:60])
    iio.imwrite(tmp_path / "small.png", rng.integers(0, 256, (4, 4), dtype=np.uint8))
    (tmp_path / "folder").mkdir()
    (tmp_path / "emptydir").mkdir()
    (tmp_path / "text.txt").write_text("hello")
    (tmp_path / "afile").write_text("a file")
    (tmp_path / "garbage.npy").write_bytes(b"\x93NUMPY garbage")
    (tmp_path / "garbage.npz").write_bytes(b"PK\x03\x04 not a zip")
    np.save(tmp_path / "nan.npy", np.full((16, 16), np.nan, dtype=np.float32))
    np.save(tmp_path / "inf.npy", np.full((16, 16), np.inf, dtype=np.float64))
    np.save(tmp_path / "complex.npy", np.ones((16, 16), dtype=np.complex64))
    np.save(tmp_path / "four_d.npy", np.ones((4, 4, 4, 4, 4), dtype=np.float32))
    np.save(tmp_path / "empty.npy", np.ones((0, 16), dtype=np.float32))
    np.save(tmp_path / "vol.npy", rng.random((8, 8, 8)).astype(np.float32))
    np.savez(tmp_path / "foreign.npz", a=np.arange(3))
    (tmp_path / "sp ace").mkdir()
    (tmp_path / "sp ace" / "ünï.png").write_bytes(b"not a png")
    _study_folder(tmp_path / "badjson", b"run_id,status\n", "{not json")
    _study_folder(tmp_path / "badcsv", b"a,b\n1,2,3\n", None)
    _study_folder(tmp_path / "listjson", b"run_id,status\n", "[1, 2]")
    _study_folder(tmp_path / "binarycsv", b"\xff\xfe\x00garbage\x80", None)
    return tmp_path




def test_bad_inputs_are_distinct_and_many():
    distinct = {tuple(argv) for argv in BAD_INPUTS}
    assert len(distinct) == len(BAD_INPUTS)
    assert len(distinct) >= 170


@pytest.mark.parametrize("argv", BAD_INPUTS, ids=lambda a: " ".join(a) or "(none)")
def test_bad_input_is_one_line_exit_2_nothing_written(argv, place, capsys):
    one_line_error(argv, place, capsys)


def test_usage_block_only_with_help(capsys):
    assert cli.main(["synth", "--help"]) == 0
    assert "usage:" in capsys.readouterr().out


def test_argparse_message_names_the_command(place, capsys):
    line = one_line_error(["baseline", "kopf", "--grid", "z"], place, capsys)
    assert line.startswith("npmrf3d baseline kopf: error: argument --grid: invalid int value")


def test_scheduler_that_does_not_answer_fails_fast(place, capsys):
    import time
    t0 = time.perf_counter()
    line = one_line_error(["study", "heuristics", "--quick", "--scheduler", "tcp://127.0.0.1:1"],
                                place, capsys)
    assert time.perf_counter() - t0 < 10 and "cannot reach the Dask scheduler" in line


@pytest.mark.parametrize("where", ["volume", "checkpoint"])
def test_full_disk_is_one_line(where, place, capsys, monkeypatch):
    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    if where == "volume":
        monkeypatch.setattr("npmrf3d.io.runs.np.save", full)
        argv = ["synth", *TINY, "good.png", "--out", "out", "--quiet"]
    else:
        monkeypatch.setattr("npmrf3d.io.checkpoints.np.savez", full)
        argv = ["synth", *TINY, "good.png", "--out", "out", "--quiet", "--checkpoint", "c.npz"]
    line = one_line_error(argv, place, capsys)
    assert "No space left on device" in line and "free some space" in line


def test_study_with_failed_runs_exits_non_zero_and_says_how_many(place, capsys, monkeypatch):
    from npmrf3d.studies import execute, runner
    from npmrf3d.studies.catalog import STUDIES

    def fail(spec, study_dir, threads=None):
        return execute.record_failure(spec, pathlib.Path(study_dir), RuntimeError("boom"))

    monkeypatch.setattr(runner, "execute_run", fail)
    runs = len(STUDIES["heuristics"].runs("quick"))
    code = cli.main(["study", "heuristics", "--quick", "--scheduler", "serial", "--out", "s", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and f"all {runs} runs failed" in err and "Traceback" not in err
    calls = []

    def some(spec, study_dir, threads=None):
        calls.append(spec)
        if len(calls) == 1:
            return fail(spec, study_dir)
        return execute.record_failure(spec, pathlib.Path(study_dir), RuntimeError("boom")) | {"status": "done"}

    monkeypatch.setattr(runner, "execute_run", some)
    code = cli.main(["study", "heuristics", "--quick", "--scheduler", "serial", "--out", "s2", "--quiet"])
    err = capsys.readouterr().err
    assert code == 1 and f"1 of {runs} runs failed" in err


def test_study_json_report_garbage_message(place, capsys):
    line = one_line_error(["report", "badjson"], place, capsys)
    assert "cannot be read" in line and "JSONDecodeError" in line
    json.loads(json.dumps(line))
