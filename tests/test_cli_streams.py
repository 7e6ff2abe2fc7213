"""The command line's streams, progress and reports: closed or full stdout and stderr, the one
line said while the kernels compile, one progress line over a run, and the reports of
``metrics`` and ``study``."""

from __future__ import annotations

import errno
import os
import pathlib
import subprocess
import sys

import pytest

from npmrf3d import cli
from npmrf3d.cli import _progress, _streams
from npmrf3d.cli.main import _compile_notice
from npmrf3d.config import SynthesisConfig
from npmrf3d.io.runs import RUN_FILES

RUN = ["synth", "--size", "16", "--levels", "2", "--seed", "1"]


def _closed(fd: int):
    """A ``preexec_fn`` that starts the command with descriptor ``fd`` closed (``>&-``)."""
    return lambda: os.close(fd)


def _npmrf3d(cwd: pathlib.Path, *argv: str, stdout=None, stderr=None, close: int | None = None):
    """Run ``python -m npmrf3d ARGV`` in ``cwd``; ``close``: a standard descriptor closed."""
    return subprocess.run([sys.executable, "-m", "npmrf3d", *argv], cwd=cwd, timeout=600,
                          stdin=subprocess.DEVNULL,
                          stdout=subprocess.PIPE if stdout is None else stdout,
                          stderr=subprocess.PIPE if stderr is None else stderr,
                          preexec_fn=None if close is None else _closed(close))


# --------------------------------------------------------------------------- closed or full streams


@pytest.mark.parametrize("how", ["closed", "full"])
def test_info_without_its_stdout_fails_in_one_line_without_a_traceback(tmp_path, how):
    with open(os.devnull if how == "closed" else "/dev/full", "w") as sink:
        done = _npmrf3d(tmp_path, "info", stdout=sink, close=1 if how == "closed" else None)
    err = done.stderr.decode()
    assert done.returncode == 1, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("npmrf3d: error: cannot write to standard output"), err
    assert ("No space left" in err) if how == "full" else ("Bad file descriptor" in err)


def test_info_into_a_reader_that_hung_up_stops_quietly(tmp_path):
    proc = subprocess.Popen([sys.executable, "-m", "npmrf3d", "info"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()  # like 'npmrf3d info | head -0'
    with proc.stderr:
        err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 1
    assert err == ""


@pytest.mark.parametrize("streams", ["stderr closed", "stdout closed", "both full"])
def test_a_run_without_its_streams_still_writes_its_folder_and_exits_0(tmp_path, streams):
    with open("/dev/full", "w") as full:
        kwargs = {"stderr closed": dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close=2),
                  "stdout closed": dict(stdout=subprocess.DEVNULL, close=1),
                  "both full": dict(stdout=full, stderr=full)}[streams]
        done = _npmrf3d(tmp_path, *RUN, "--out", "run", **kwargs)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == sorted(RUN_FILES)
    if done.stderr is not None:  # stderr was open: nothing on it but the progress line
        assert b"Traceback" not in done.stderr and b"error" not in done.stderr


def test_a_user_error_with_stdout_full_is_still_the_user_error(tmp_path):
    with open("/dev/full", "w") as full:
        done = _npmrf3d(tmp_path, *RUN, "--window", "4", "--out", "run", stdout=full)
    err = done.stderr.decode()
    assert done.returncode == 2 and err.count("\n") == 1 and "--window" in err, err
    assert not (tmp_path / "run").exists()


class _Failing:
    """A stream whose every write fails like a full disk."""

    def __init__(self):
        self.writes = 0

    def write(self, text):
        self.writes += 1
        raise OSError(errno.ENOSPC, "No space left on device")

    def flush(self):
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_tolerant_stream_drops_and_remembers_a_failed_write(tmp_path, monkeypatch):
    # the descriptor given is a file of the test's, so that pointing it at the null device is seen
    fd = os.open(tmp_path / "sink", os.O_WRONLY | os.O_CREAT)
    try:
        failing = _Failing()
        stream = _streams.TolerantStream(failing, fd)
        assert stream.write("one line\n") == len("one line\n")
        stream.flush()
        stream.write("another\n")
        assert failing.writes == 1  # lost once, not tried again
        assert _streams.lost_reason(stream) == "No space left on device"
        assert os.path.samestat(os.fstat(fd), os.stat(os.devnull))
    finally:
        os.close(fd)


def test_the_streams_come_back_after_a_command(capsys):
    before = sys.stdout, sys.stderr
    assert cli.main(["info"]) == 0
    assert (sys.stdout, sys.stderr) == before
    assert "numba threads" in capsys.readouterr().out


# --------------------------------------------------------------------------- compiling kernels


def _probe(module: str):
    """A fresh jitted function that claims to live in ``module`` (not cached: it compiles on
    its first call)."""
    import numba

    space = {"__name__": module}
    exec("def probe(x):\n    return x + 1\n", space)
    return numba.njit(cache=False)(space["probe"])


def test_the_first_compile_of_a_kernel_is_said_once(capsys):
    with _compile_notice(quiet=False):
        assert _probe("npmrf3d._probe_a")(1) == 2
        assert _probe("npmrf3d._probe_b")(1.5) == 2.5
    err = capsys.readouterr().err
    assert err.count("compiling the kernels once") == 1 and err.count("\n") == 1, err


def test_nothing_is_said_without_a_compile_of_the_package_or_with_quiet(capsys):
    kernel = _probe("npmrf3d._probe_c")
    kernel(1)  # compiled before the block: loaded, like a warm cache
    with _compile_notice(quiet=False):
        assert kernel(2) == 3
        assert _probe("someone_else")(1) == 2  # not one of the package's kernels
    with _compile_notice(quiet=True):
        assert _probe("npmrf3d._probe_d")(1) == 2
    assert capsys.readouterr().err == ""


# --------------------------------------------------------------------------- one progress line


def test_one_line_over_the_levels_weighted_by_their_voxels(capsys):
    line = _progress.LevelProgress((16, 16, 16), enabled=True, symbol="E")
    coarse, fine = 8 ** 3, 16 ** 3
    line(1, 0, 4, float("nan"))
    assert line.bar.n / line.bar.total == 0
    line(1, 2, 4, 0.7)
    assert line.bar.n / line.bar.total == pytest.approx(0.5 * coarse / (coarse + fine))
    line(0, 0, 3, 0.6)
    assert line.bar.n / line.bar.total == pytest.approx(coarse / (coarse + fine))
    line(0, 2, 3, 0.5)
    assert line.bar.n / line.bar.total == pytest.approx((coarse + 2 / 3 * fine) / (coarse + fine))
    assert line.bar.postfix == "E=0.5" and "level 0 (16^3)" in line.bar.desc
    line.finish()
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err  # one line, redrawn in place
    assert "100%" in err.rsplit("\r", 1)[-1] and "<" in err  # elapsed<left


def test_a_second_pyramid_starts_a_new_line(capsys):
    line = _progress.LevelProgress((16, 16, 16), enabled=True)
    line(1, 1, 1, 1.0)
    line(0, 1, 1, 1.0)
    line.note("second pyramid")
    line(1, 0, 2, 1.0)
    assert line.bar.n == 0
    line.close()
    assert capsys.readouterr().err.count("second pyramid") == 1


def test_the_value_is_named_by_what_it_is():
    assert _progress.value_symbol(SynthesisConfig(size=(8, 8, 8))) == "E"  # the default: coherent
    assert _progress.value_symbol(SynthesisConfig(size=(8, 8, 8), support="full")) == "T"


def test_a_run_draws_one_line_and_quiet_none(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main([*RUN, "--out", "loud"]) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.split("\n")[:-1] if "compiling the kernels" not in line]
    assert len(lines) == 1 and "E=" in lines[0] and "T=" not in lines[0], err
    assert "level 0 (16^3)" in lines[0].rsplit("\r", 1)[-1]
    assert cli.main([*RUN, "--out", "quiet", "--quiet"]) == 0
    assert capsys.readouterr() == ("", "")


# --------------------------------------------------------------------------- metrics: ratios and Zarr


def _metrics_inputs(tmp_path: pathlib.Path):
    """A smooth 8-bit exemplar, a volume whose right slices are it, and white noise."""
    import imageio.v3 as iio
    import numpy as np
    from scipy import ndimage

    x = ndimage.gaussian_filter(np.random.default_rng(0).standard_normal((24, 24)), 1.5)
    exemplar = np.round((x - x.min()) / (x.max() - x.min()) * 255).astype(np.uint8)
    iio.imwrite(tmp_path / "ex.png", exemplar)
    np.save(tmp_path / "stacked.npy", np.stack([exemplar.astype(np.float32) / 255] * 12))
    np.save(tmp_path / "noise.npy", np.random.default_rng(1).random((12, 24, 24), dtype=np.float32))
    return tmp_path / "ex.png"


def _ratio_table(out: str) -> dict[str, dict[str, float]]:
    """metric -> column -> ratio, from the table under 'ratio to the control'."""
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("ratio to the control"))
    columns = lines[head].split()[4:]
    table = {}
    for line in lines[head + 1:]:
        parts = line.split()
        if not parts:
            break
        if len(parts) == len(columns) + 1:
            table[parts[0]] = dict(zip(columns, map(float, parts[1:])))
    return table


def test_metrics_reports_ratios_to_the_control_and_the_floor(tmp_path, capsys):
    import json

    exemplar = _metrics_inputs(tmp_path)
    code = cli.main(["metrics", str(exemplar), str(tmp_path / "stacked.npy"), "--views", "right,front",
                     "--out", str(tmp_path / "m")])
    out = capsys.readouterr().out
    assert code == 0
    ratios = _ratio_table(out)
    assert set(ratios) == {"autocorrelation_l2", "orientation_kl", "sliced_wasserstein"}
    assert all(set(row) == {"right", "front", "mean", "floor"} for row in ratios.values())
    assert all(row["right"] == 0.0 for row in ratios.values())  # the exemplar itself
    assert ratios["autocorrelation_l2"]["front"] > 1.0  # constant along a front slice's rows
    assert "raw only" in out and "control: the exemplar's pixels drawn independently" in out
    assert "floor: another crop of the same texture" in out
    record = json.loads((tmp_path / "m" / "metrics.json").read_text(encoding="utf-8"))
    control = record["control"]["mean"]
    for name, row in ratios.items():
        assert row["mean"] == pytest.approx(record["mean"][name] / control[name], abs=1e-3)
        assert record["ratio"]["mean"][name] == pytest.approx(row["mean"], abs=1e-3)
    assert record["floor"]["half_shape"] == [24, 12]

    # white noise is no better than the control: its ratios are near 1 or above, the floor's lower
    assert cli.main(["metrics", str(exemplar), str(tmp_path / "noise.npy"), "--views", "right",
                     "--out", str(tmp_path / "n")]) == 0
    noise = _ratio_table(capsys.readouterr().out)
    assert noise["autocorrelation_l2"]["right"] > 0.9 and noise["sliced_wasserstein"]["right"] > 0.9
    assert noise["autocorrelation_l2"]["floor"] < noise["autocorrelation_l2"]["right"]


def test_the_structureless_control_of_a_study_is_the_metrics_control():
    import numpy as np

    from npmrf3d.analysis.metrics.references import structureless as of_metrics
    from npmrf3d.studies.execute import structureless as of_study

    exemplar = np.random.default_rng(0).random((8, 8, 1), dtype=np.float32)
    assert np.array_equal(of_study(exemplar, 6, 3), of_metrics(exemplar, (6, 6, 6), 3))


def test_metrics_reads_a_zarr_volume_and_refuses_an_unfinished_one(tmp_path, capsys):
    import numpy as np
    import zarr

    from npmrf3d.io.zarr_blocks import DONE, open_blocks, write_block

    exemplar = _metrics_inputs(tmp_path)
    stacked = np.load(tmp_path / "stacked.npy")[..., None]
    volume = tmp_path / "v.zarr"
    open_blocks(volume, size=stacked.shape[:3], channels=1, block=12, attrs={"test": 1})
    for index in [(0, 0, 0), (0, 1, 0), (0, 0, 1), (0, 1, 1)]:
        origin = [i * 12 for i in index]
        write_block(volume, index, 12, stacked[origin[0]:origin[0] + 12, origin[1]:origin[1] + 12,
                                               origin[2]:origin[2] + 12])
    assert np.array_equal(zarr.open_array(volume, mode="r")[...], stacked)
    args = ["metrics", str(exemplar), str(volume), "--views", "right"]
    assert cli.main([*args, "--out", str(tmp_path / "z")]) == 0
    from_zarr = capsys.readouterr().out
    assert cli.main(["metrics", str(exemplar), str(tmp_path / "stacked.npy"), "--views", "right",
                     "--out", str(tmp_path / "npy")]) == 0
    assert from_zarr.split("\n\n")[0] == capsys.readouterr().out.split("\n\n")[0]

    (volume / DONE / "0.1.1").unlink()  # a block not made yet (an interrupted run)
    assert cli.main([*args, "--out", str(tmp_path / "z2")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not complete (3 of 4 blocks made)" in err
    assert not (tmp_path / "z2").exists()


def test_metrics_given_a_run_folder_names_the_volume_inside(tmp_path, capsys):
    exemplar = _metrics_inputs(tmp_path)
    run = tmp_path / "run"
    run.mkdir()
    (tmp_path / "stacked.npy").rename(run / "volume.npy")
    assert cli.main(["metrics", str(exemplar), str(run), "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a folder and not a Zarr volume" in err
    assert str(run / "volume.npy") in err
    assert not (tmp_path / "m").exists()


# --------------------------------------------------------------------------- one study per folder


def test_a_second_study_into_a_held_folder_is_refused_in_one_line(tmp_path, capsys):
    study_dir = tmp_path / "results" / "views"
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys; from npmrf3d.studies.runner import claim_study_dir\n"
         f"with claim_study_dir(__import__('pathlib').Path({str(study_dir)!r})):\n"
         "    print('held', flush=True); sys.stdin.read()"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        code = cli.main(["study", "views", "--quick", "--scheduler", "serial", "--quiet",
                         "--out", str(tmp_path / "results")])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1, err
        assert "study folder" in err and "in use" in err and "Traceback" not in err
        assert list(study_dir.iterdir()) == []  # no run folder, no results.csv
    finally:
        holder.communicate("", timeout=60)
    assert holder.returncode == 0
    assert not any(p.name.endswith(".lock") for p in (tmp_path / "results").iterdir())


def test_the_time_left_leaves_out_the_kernels_compiling(capsys):
    class Clock:
        seconds = 0.0

    clock = Clock()
    line = _progress.LevelProgress((8, 8, 8), enabled=True, symbol="E", compiling=clock)
    line(0, 0, 4, float("nan"))
    clock.seconds = 90.0  # of the next 100 s, 90 went to compiling
    line.bar.start_t -= 100.0
    line(0, 2, 4, 1.0)
    stats = line.bar.format_dict
    assert (stats["total"] - stats["n"]) / stats["rate"] == pytest.approx(10.0, rel=0.05)
    assert "<00:10" in str(line.bar) or "<00:09" in str(line.bar)
    line.close()
    capsys.readouterr()
