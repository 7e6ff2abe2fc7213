"""Tests for the command line (npmrf3d.cli): help, tiny runs, run folders and user errors.

Runs are tiny (8^3 with one level and window 3, or 16^3 with two levels) and call ``main``
in-process; two tests start ``python -m npmrf3d`` in a subprocess.
"""

from __future__ import annotations

import argparse

import json
import os
import pathlib
import subprocess
import sys

import imageio.v3 as iio
import numpy as np
import pytest

from npmrf3d import cli
from npmrf3d.errors import ParameterError
from npmrf3d.io import runs

REPO = pathlib.Path(__file__).resolve().parents[1]
TINY = ["--size", "8", "--levels", "1", "--window", "3"]


@pytest.fixture
def exemplar(tmp_path) -> pathlib.Path:
    """A 32x32 random 8-bit grey PNG."""
    path = tmp_path / "exemplar.png"
    iio.imwrite(path, np.random.default_rng(0).integers(0, 256, (32, 32), dtype=np.uint8))
    return path


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = cli.main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def leftovers(folder: pathlib.Path) -> list[str]:
    """Staging folders or temporary files that a failed write would leave behind."""
    return sorted(p.name for p in folder.iterdir() if ".partial-" in p.name or ".tmp-" in p.name)


def assert_user_error(code: int, out: str, err: str, out_dir: pathlib.Path) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2
    assert len(lines) == 1, err
    assert lines[0].startswith("npmrf3d: error: ") and len(lines[0]) > len("npmrf3d: error: ")
    assert "Traceback" not in err and out == ""
    assert not out_dir.exists()
    assert leftovers(out_dir.parent) == []
    return lines[0]


def snapshot(folder: pathlib.Path) -> dict[str, tuple[int, bytes]]:
    return {name: ((folder / name).stat().st_mtime_ns, (folder / name).read_bytes())
            for name in runs.RUN_FILES}


# --------------------------------------------------------------------------- help and info


def test_synth_help_lists_every_option_with_its_default(capsys):
    code, out, err = run_cli(capsys, "synth", "--help")
    assert code == 0 and err == ""
    text = " ".join(out.split())  # undo line wrapping
    synth = cli.build_parser()._subparsers._group_actions[0].choices["synth"]
    for action in synth._actions:
        if action.help is argparse.SUPPRESS:  # the older --variant: accepted, not listed
            assert action.dest == "variant"
            continue
        for option in action.option_strings:
            assert option in text
        assert action.help and action.help.strip()
        if action.option_strings != ["-h", "--help"]:
            assert "default" in action.help or action.default is not None or action.default is False
    for expected in ("(default: 7)", "(default: 64)", "(default: 3; one more per doubling", "(default: ML_H2b)",
                     "(default: icm)", "(default: -1; support full: -3)", "(default: 0.95)", "(default: 30)",
                     "support full with icm: 1/8", "(default: resynth)", "(default: front,right,top)",
                     "(default: coherent)", "(default: 0)", "(default: npmrf3d-synth-out)",
                     "(default: metropolis; support full: heat-bath)", "(default: geometric)", "(default: 10)",
                     "(default: 0.05)", "(default: exemplar)", "(Urs et al. 2014)", "docs/commands/synth.md",
                     "(default: --preset's)", "bundled:gravel64"):
        assert expected in text, expected


@pytest.mark.parametrize("heuristic", ["ML_H1a", "ML_H1b"])
def test_annealing_with_objective_free_heuristic_exits_2_naming_the_valid_ones(capsys, tmp_path, heuristic):
    out = tmp_path / "run"
    code, _, err = run_cli(capsys, "synth", "--relaxation", "anneal", "--heuristic", heuristic,
                           "--out", str(out))
    assert code == 2
    assert err.count("\n") == 1 and "Traceback" not in err
    assert f"{heuristic} cannot drive annealing" in err and "use ML_H2a or ML_H2b" in err
    assert not out.exists()


def test_anneal_run_writes_a_colour_run(capsys, tmp_path):
    out = tmp_path / "run"
    code, _, err = run_cli(capsys, "synth", "bundled:ihc64", "--relaxation", "anneal", "--support", "full",
                           "--sampler", "heat-bath", "--palette", "16", "--size", "8",
                           "--levels", "2", "--window", "3", "--proposals", "2", "--out", str(out),
                           "--quiet")
    assert code == 0, err
    import json

    record = json.loads((out / "run.json").read_text())
    assert record["config"]["relaxation"] == "anneal" and record["config"]["upsample"] == "8/8"
    assert record["config"]["sampler"] == "heat-bath" and record["labels"] == 16
    assert len(record["history"]) == 2 and len(record["history"][0]) == 3
    assert np.load(out / "volume.npy").shape == (8, 8, 8, 3)


def test_synth_suggests_a_palette_for_many_colours(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr(cli.synth, "MANY_VALUES", 50)
    code, _, err = run_cli(capsys, "synth", "bundled:ihc64", "--size", "8", "--levels", "1",
                           "--window", "3", "--grey-levels", "4",
                           "--out", str(tmp_path / "a"))
    assert code == 0 and "--palette 64" not in err  # asked for few labels: no note
    code, _, err = run_cli(capsys, "synth", "bundled:gravel64", "--size", "8", "--levels", "1",
                           "--window", "3", "--out", str(tmp_path / "b"))
    assert code == 0 and "178 distinct values" in err and "--palette 64" in err


def test_info_prints_version_and_registries(capsys):
    import npmrf3d

    code, out, err = run_cli(capsys, "info")
    assert code == 0 and err == ""
    assert f"npmrf3d {npmrf3d.__version__}" in out
    for word in ("numba threads", "CPU count", "numpy", "gravel64", "ML_H2b", "paper", "coherent",
                 "histogram_weight"):
        assert word in out


def test_no_command_is_a_usage_error(capsys):
    code, out, err = run_cli(capsys)
    assert code == 2 and out == "" and "usage:" not in err
    assert err.strip().splitlines() == [
        "npmrf3d: error: the following arguments are required: COMMAND (see 'npmrf3d --help')"]


# --------------------------------------------------------------------------- successful runs


def test_tiny_run_writes_a_complete_run_folder(tmp_path, exemplar, capsys):
    out_dir = tmp_path / "run"
    code, out, err = run_cli(capsys, "synth", str(exemplar), *TINY, "--seed", "3",
                             "--out", str(out_dir))
    assert code == 0, err
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(runs.RUN_FILES)
    volume = np.load(out_dir / "volume.npy")
    assert volume.shape == (8, 8, 8, 1) and volume.dtype == np.float32
    record = json.loads((out_dir / "run.json").read_text(encoding="utf-8"))
    for key in ("command", "argv", "config", "seed", "exemplars", "versions", "threads",
                "timings", "history", "stats", "labels", "created"):
        assert key in record, key
    assert record["command"] == "synth" and record["seed"] == 3
    assert record["argv"][:2] == ["npmrf3d", "synth"]
    assert record["config"]["size"] == [8, 8, 8] and record["config"]["window"] == 3
    assert record["exemplars"] == {v: str(exemplar) for v in ("front", "right", "top")}
    assert record["versions"]["numpy"] == np.__version__
    assert "total" in record["timings"] and len(record["history"]) == 1
    # progress bar on stderr, summary on stdout
    assert "level 0 (8^3)" in err and "100%" in err and "sweep" in err
    assert str(out_dir) in out and "8x8x8x1" in out


def test_rerun_needs_overwrite_and_leaves_files_untouched(tmp_path, exemplar, capsys):
    out_dir = tmp_path / "run"
    args = ["synth", str(exemplar), *TINY, "--out", str(out_dir), "--quiet"]
    code, out, err = run_cli(capsys, *args)
    assert (code, out, err) == (0, "", "")
    before = snapshot(out_dir)

    code, out, err = run_cli(capsys, *args)
    lines = err.splitlines()
    assert code == 2 and out == "" and len(lines) == 1
    assert lines[0].startswith("npmrf3d: error: ") and "--overwrite" in lines[0]
    assert snapshot(out_dir) == before
    assert leftovers(tmp_path) == []

    code, out, err = run_cli(capsys, *args, "--seed", "1", "--overwrite")
    assert (code, out, err) == (0, "", "")
    assert json.loads((out_dir / "run.json").read_text(encoding="utf-8"))["seed"] == 1


def test_views_per_view_exemplar_and_box_size(tmp_path, exemplar, capsys):
    other = tmp_path / "other.npy"
    np.save(other, np.random.default_rng(1).random((24, 24), dtype=np.float32))
    out_dir = tmp_path / "run"
    code, out, err = run_cli(capsys, "synth", str(exemplar), "--size", "8,8,16", "--levels", "1",
                             "--window", "3", "--views", "front,top", "--exemplar-top",
                             str(other), "--out", str(out_dir), "--quiet")
    assert code == 0, err
    assert np.load(out_dir / "volume.npy").shape == (8, 8, 16, 1)
    record = json.loads((out_dir / "run.json").read_text(encoding="utf-8"))
    assert record["exemplars"] == {"front": str(exemplar), "top": str(other)}
    assert record["config"]["views"] == ["front", "top"]


def test_checkpoint_of_another_configuration_is_a_user_error(tmp_path, exemplar, capsys):
    checkpoint = tmp_path / "ck.npz"
    common = ["synth", str(exemplar), *TINY, "--quiet", "--checkpoint", str(checkpoint)]
    assert run_cli(capsys, *common, "--out", str(tmp_path / "a"))[0] == 0
    assert checkpoint.is_file()
    code, out, err = run_cli(capsys, *common, "--seed", "5", "--out", str(tmp_path / "b"))
    message = assert_user_error(code, out, err, tmp_path / "b")
    assert "checkpoint" in message


def test_keyboard_interrupt_exits_130(tmp_path, exemplar, capsys, monkeypatch):
    import npmrf3d.methods.npmrf

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(npmrf3d.methods.npmrf, "run", interrupted)
    out_dir = tmp_path / "run"
    code, out, err = run_cli(capsys, "synth", str(exemplar), *TINY, "--variant", "sharp", "--out", str(out_dir))
    assert code == 130 and len(err.strip().splitlines()) == 1
    assert err.startswith("npmrf3d: interrupted; nothing was written")
    assert not out_dir.exists()


def _swallowed_interrupt():
    """What a callback from C (llvmlite's ctypes callbacks while numba compiles, importlib's
    module-lock callback) does to a Ctrl-C: the handler's KeyboardInterrupt is reported through
    ``sys.unraisablehook`` and dropped, and the caller goes on (here: an object's ``__del__``)."""
    import signal

    class Dropping:
        def __del__(self):
            signal.getsignal(signal.SIGINT)(signal.SIGINT, None)

    Dropping()


@pytest.mark.parametrize("where", ["between levels", "after the last level", "in the compiler"])
def test_swallowed_interrupt_still_exits_130_and_writes_nothing(tmp_path, exemplar, capsys, monkeypatch,
                                                                 where):
    import npmrf3d.methods.npmrf
    real_run = npmrf3d.methods.npmrf.run

    def run(*args, progress=None, **kwargs):
        if where == "between levels":
            def ticking(*a):
                if a[1] == 0 and a[0] == 0:  # the start of the finest level
                    _swallowed_interrupt()
                return progress(*a)
            return real_run(*args, progress=ticking, **kwargs)
        if where == "in the compiler":  # numba, interrupted mid-compile, fails on the next call
            _swallowed_interrupt()
            raise RuntimeError("no compiled object yet for <Library 'project'>")
        result = real_run(*args, progress=progress, **kwargs)
        _swallowed_interrupt()
        return result

    monkeypatch.setattr(npmrf3d.methods.npmrf, "run", run)
    out_dir = tmp_path / "run"
    code, out, err = run_cli(capsys, "synth", str(exemplar), *TINY, "--variant", "sharp", "--quiet",
                             "--out", str(out_dir))
    assert code == 130 and err.startswith("npmrf3d: interrupted; nothing was written"), err
    assert len(err.strip().splitlines()) == 1 and not out_dir.exists()
    # the latch is cleared with the run: the next one in the same process is not interrupted
    monkeypatch.setattr(npmrf3d.methods.npmrf, "run", real_run)
    assert run_cli(capsys, "synth", str(exemplar), *TINY, "--variant", "sharp", "--quiet",
                   "--out", str(out_dir))[0] == 0


def test_an_unexpected_error_without_an_interrupt_is_not_called_one(tmp_path, exemplar, capsys, monkeypatch):
    import npmrf3d.methods.npmrf

    def broken(*args, **kwargs):
        raise RuntimeError("a real bug")

    monkeypatch.setattr(npmrf3d.methods.npmrf, "run", broken)
    with pytest.raises(RuntimeError, match="a real bug"):
        cli.main(["synth", str(exemplar), *TINY, "--variant", "sharp", "--quiet", "--out", str(tmp_path / "r")])


def test_parameter_error_from_writing_is_one_line(tmp_path, exemplar, capsys, monkeypatch):
    def refuse(*args, **kwargs):
        raise ParameterError("disk says no\nsecond line")

    monkeypatch.setattr(cli._common, "write_run", refuse)
    out_dir = tmp_path / "run"
    code, out, err = run_cli(capsys, "synth", str(exemplar), *TINY, "--out", str(out_dir),
                             "--quiet")
    assert assert_user_error(code, out, err, out_dir) == "npmrf3d: error: disk says no second line"


# --------------------------------------------------------------------------- user errors


def _missing(tmp_path):
    return [str(tmp_path / "missing.png")]


def _corrupt_png(tmp_path):
    path = tmp_path / "corrupt.png"
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(np.random.default_rng(0).integers(0, 256, 200,
                                                                                     dtype=np.uint8)))
    return [str(path)]


def _npy(tmp_path, array):
    path = tmp_path / "bad.npy"
    np.save(path, array)
    return [str(path)]


def _small_png(tmp_path):
    path = tmp_path / "small.png"
    iio.imwrite(path, np.random.default_rng(0).integers(0, 256, (5, 5), dtype=np.uint8))
    return [str(path), "--window", "7"]


BAD_INPUTS = {
    "missing-exemplar": (_missing, "does not exist"),
    "corrupt-png": (_corrupt_png, "cannot be read"),
    "nan-npy": (lambda t: _npy(t, np.array([[0.0, np.nan], [1.0, 2.0]] * 8)), "NaN"),
    "4d-npy": (lambda t: _npy(t, np.zeros((8, 8, 1, 1))), "shape"),
    "empty-npy": (lambda t: _npy(t, np.zeros((0, 0))), "empty"),
    "exemplar-smaller-than-window": (_small_png, "too small"),
    "even-window": (lambda t: ["--window", "6"], "window"),
    "window-17": (lambda t: ["--window", "17"], "window"),
    "unknown-heuristic": (lambda t: ["--heuristic", "ML_H3"], "ML_H1a, ML_H1b, ML_H2a, ML_H2b"),
    "unknown-upsample": (lambda t: ["--upsample", "2/8"], "upsample"),
    "size-not-divisible": (lambda t: ["--size", "10", "--levels", "3"], "divisible"),
    "size-not-a-number": (lambda t: ["--size", "8,x,8"], "size"),
    "xi-zero": (lambda t: ["--xi", "0"], "xi"),
    "xi-positive": (lambda t: ["--xi", "1"], "xi"),
    "stop-zero": (lambda t: ["--stop", "0"], "stop"),
    "stop-above-one": (lambda t: ["--stop", "1.5"], "stop"),
    "empty-views": (lambda t: ["--views", ""], "views"),
    "duplicate-views": (lambda t: ["--views", "front,front"], "repeat"),
    "unknown-view": (lambda t: ["--views", "front,side"], "view"),
    "exemplar-for-unconstrained-view": (lambda t: ["--views", "front", "--exemplar-top",
                                                   "bundled:gravel64"], "not constrained"),
    "unknown-bundled-exemplar": (lambda t: ["bundled:marble"], "gravel64"),
    "negative-seed": (lambda t: ["--seed", "-1"], "seed"),
    "sample-with-H1": (lambda t: ["--heuristic", "ML_H1a", "--decision", "sample", "--variant", "sharp"], "argmax"),
    "coherent-anneal-with-H1": (lambda t: ["--heuristic", "ML_H1a", "--relaxation", "anneal"],
                                "ML_H1a cannot drive annealing"),
    "coherent-xi-without-temperatures": (lambda t: ["--xi", "-1"], "needs per-voxel temperatures"),
    "anneal-option-with-icm": (lambda t: ["--proposal", "labels"], "option --proposal does not apply to support 'coherent'"),
    "variant-contradicts-support": (lambda t: ["--variant", "literal", "--support", "coherent"],
                                    "contradicts"),
    "coherent-anneal-hot-end": (lambda t: ["--relaxation", "anneal", "--variant", "coherent", "--t0", "0.5",
                                           "--t-end", "0.9"], "--t-end"),
}


@pytest.mark.parametrize("name", list(BAD_INPUTS))
def test_bad_input_is_one_line_error_and_writes_nothing(name, tmp_path, exemplar, capsys):
    make_args, expected = BAD_INPUTS[name]
    args = make_args(tmp_path)
    if not args or args[0].startswith("--"):
        args = [str(exemplar), *args]
    defaults = TINY
    out_dir = tmp_path / "out"
    code, out, err = run_cli(capsys, "synth", *_merge(defaults, args), "--out", str(out_dir))
    message = assert_user_error(code, out, err, out_dir)
    if expected is not None:
        assert expected in message


def _merge(defaults: list[str], args: list[str]) -> list[str]:
    """``args`` plus those ``--option value`` pairs of ``defaults`` that ``args`` does not set."""
    merged = list(args)
    for option, value in zip(defaults[::2], defaults[1::2]):
        if option not in args:
            merged += [option, value]
    return merged


def test_output_path_that_is_a_file_is_a_user_error(tmp_path, exemplar, capsys):
    target = tmp_path / "file"
    target.write_text("not a folder")
    code, out, err = run_cli(capsys, "synth", str(exemplar), *TINY, "--out", str(target))
    assert code == 2 and err.startswith("npmrf3d: error: ") and len(err.splitlines()) == 1
    assert target.read_text() == "not a folder"


def test_non_numeric_option_is_a_one_line_usage_error(tmp_path, exemplar, capsys):
    out_dir = tmp_path / "out"
    code, out, err = run_cli(capsys, "synth", str(exemplar), "--window", "seven",
                             "--out", str(out_dir))
    assert code == 2 and "usage:" not in err and len(err.strip().splitlines()) == 1
    assert err.startswith("npmrf3d synth: error: argument --window: invalid int value")
    assert not out_dir.exists()


# --------------------------------------------------------------------------- subprocesses


def _python_m(*argv: str, cwd: pathlib.Path) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "npmrf3d", *argv], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600, check=False)


def test_python_m_help(tmp_path):
    proc = _python_m("synth", "--help", cwd=tmp_path)
    assert proc.returncode == 0 and proc.stderr == ""
    assert "--window" in proc.stdout and "(default: 7)" in proc.stdout


def test_python_m_synth_end_to_end(tmp_path, exemplar):
    proc = _python_m("synth", str(exemplar), "--size", "16", "--levels", "2", "--window", "3",
                     "--out", "result", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    out_dir = tmp_path / "result"
    assert sorted(p.name for p in out_dir.iterdir()) == sorted(runs.RUN_FILES)
    assert np.load(out_dir / "volume.npy").shape == (16, 16, 16, 1)
    assert "level 1 (8^3)" in proc.stderr and "level 0 (16^3)" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert "result" in proc.stdout


@pytest.mark.parametrize("mode, expected", [("auto", True), ("no", False)])
def test_segmented_preset_is_recorded_in_run_json(tmp_path, capsys, mode, expected):
    from PIL import Image
    r, c = np.mgrid[:24, :24]
    pores = ((r - 8) ** 2 + (c - 8) ** 2 <= 16) | ((r - 17) ** 2 + (c - 16) ** 2 <= 9)
    Image.fromarray(np.where(pores, 0, 255).astype(np.uint8)).save(tmp_path / "phase.png")
    code, out, err = run_cli(capsys, "synth", str(tmp_path / "phase.png"), "--size", "16", "--levels", "2",
                             "--segmented", mode, "--quiet", "--out", str(tmp_path / "run"),
                             "--checkpoint", str(tmp_path / "ck.npz"))
    assert code == 0, err
    record = json.loads((tmp_path / "run" / "run.json").read_text())
    stats = record["stats"]
    assert record["config"]["segmented"] == mode and stats["segmented"] is expected
    assert stats["levels"]["level_0"]["window"] == (5 if expected else 7)
    # the preset's second run (one level fewer) has its own checkpoint beside the first
    assert (tmp_path / "ck.npz").is_file() and (tmp_path / "ck.levels1.npz").is_file() is expected
    if expected:
        errors = [t["two_point_shape_error"] for t in stats["level_trials"]]
        assert [t["levels"] for t in stats["level_trials"]] == [2, 1]
        assert stats["levels_kept"] == (2, 1)[int(np.argmin(errors))]
        assert len(stats["levels"]) == stats["levels_kept"]
    else:
        assert "level_trials" not in stats and stats["levels_kept"] == 2


def test_segmented_preset_says_which_pyramid_runs_and_which_it_kept(tmp_path, capsys):
    from PIL import Image
    r, c = np.mgrid[:24, :24]
    pores = ((r - 8) ** 2 + (c - 8) ** 2 <= 16) | ((r - 17) ** 2 + (c - 16) ** 2 <= 9)
    Image.fromarray(np.where(pores, 0, 255).astype(np.uint8)).save(tmp_path / "phase.png")
    code, out, err = run_cli(capsys, "synth", str(tmp_path / "phase.png"), "--size", "16", "--levels", "2",
                             "--out", str(tmp_path / "run"))
    assert code == 0, err
    kept = json.loads((tmp_path / "run" / "run.json").read_text())["stats"]["levels_kept"]
    lines = err.splitlines()
    first = lines.index("segmented exemplar: pyramid 1 of 2, 2 levels")
    second = lines.index("segmented exemplar: pyramid 2 of 2, 1 level")
    assert first < second and any(f"kept the {kept}-level volume" in line for line in lines[second:])


def test_only_dropped_interrupts_are_kept_quiet():
    from types import SimpleNamespace

    import llvmlite.binding.ffi as ffi

    from npmrf3d.cli import _interrupt
    seen = []
    previous = _interrupt.install()
    try:
        try:
            _interrupt.interrupt()
        except KeyboardInterrupt:
            pass
        # a dropped interrupt, and the compiler's finalizer failing on an object the interrupt
        # left half-built (freed with the interrupt's traceback, before the run's end): quiet
        for exc_type, obj in ((KeyboardInterrupt, None), (ValueError, None), (AttributeError, ffi.ObjectRef.__del__),
                              (AttributeError, test_synth_help_lists_every_option_with_its_default)):
            _interrupt._quiet_dropped_interrupts(SimpleNamespace(exc_type=exc_type, object=obj), fallback=seen.append)
    finally:
        _interrupt.restore(previous)
    assert [(u.exc_type, u.object) for u in seen] == [(ValueError, None), (AttributeError, test_synth_help_lists_every_option_with_its_default)]
    assert not _interrupt.pending()


def test_after_an_interrupt_only_the_compilers_failing_finalizers_are_kept_quiet():
    """An interrupt inside the compiler can leave an llvmlite object half-built; its finalizer
    fails when the process exits, and that must not print a traceback after the one line."""
    import sys
    from types import SimpleNamespace

    import llvmlite.binding.ffi as ffi

    from npmrf3d.cli import _interrupt
    seen = []
    kept = sys.unraisablehook
    sys.unraisablehook = seen.append
    try:
        previous = _interrupt.install()
        try:
            _interrupt.interrupt()
        except KeyboardInterrupt:
            pass
        _interrupt.restore(previous)
        compiler = SimpleNamespace(exc_type=AttributeError, object=ffi.ObjectRef.__del__)
        other = SimpleNamespace(exc_type=AttributeError, object=test_only_dropped_interrupts_are_kept_quiet)
        sys.unraisablehook(compiler)
        sys.unraisablehook(other)
        assert seen == [other]
        before = sys.unraisablehook      # a run that is not interrupted puts the hook back as it was
        _interrupt.restore(_interrupt.install())
        assert sys.unraisablehook is before
    finally:
        sys.unraisablehook = kept
