"""Ctrl-C at any moment of an ``npmrf3d`` process, the first second too (while numpy, numba,
scipy and matplotlib are imported): one line, exit code 130, nothing written; ``import npmrf3d``
imports no heavy module until a public name is used."""

from __future__ import annotations

import importlib
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import time

import pytest

import npmrf3d
from npmrf3d import cli
from npmrf3d.errors import ParameterError
from npmrf3d.io import runs

RUN = ["synth", "--size", "16", "--levels", "2", "--seed", "1", "--quiet", "--out", "run"]
DELAYS = (0.05, 0.1, 0.2, 0.35, 0.5, 0.8, 1.2, 2.0)


def _script() -> str:
    """The installed ``npmrf3d`` console script of this interpreter."""
    found = shutil.which("npmrf3d", path=os.path.dirname(sys.executable))
    assert found, "the npmrf3d console script is not installed beside this Python"
    return found


def _handles_signals(pid: int) -> bool:
    """Whether process ``pid`` catches SIGTERM (Linux's ``SigCgt`` mask): Python does not by
    default, the package's entry point does from its first statements. A signal before that
    moment (the interpreter's own start, then ``import npmrf3d`` settling its cache folders) is
    Python's to report; the delays count from it."""
    try:
        status = pathlib.Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:  # ended already
        return True
    mask = next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:"))
    return bool(int(mask, 16) >> (signal.SIGTERM - 1) & 1)


def _interrupt_after(command: list[str], delay: float, tmp_path: pathlib.Path, signum=signal.SIGINT):
    """Start ``command`` in an empty folder, send ``signum`` ``delay`` seconds after the process
    began to handle it; return (exit code, stderr, what the folder holds)."""
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    proc = subprocess.Popen(command, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    started = time.monotonic()
    while proc.poll() is None and not _handles_signals(proc.pid):
        assert time.monotonic() - started < 60, "the process never handled the signals"
        time.sleep(0.001)
    time.sleep(delay)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=600)
    return proc.returncode, err, sorted(p.name for p in tmp_path.iterdir())


def _check(code: int, err: str, left: list[str], delay: float) -> None:
    lines = [line for line in err.splitlines() if line.strip()]
    assert "Traceback" not in err and "Exception ignored" not in err, (delay, err)
    if code == 0:  # finished before the signal
        assert lines == [] and left == ["run"], (delay, err, left)
        return
    assert code == 130, (delay, code, err)
    assert len(lines) == 1 and lines[0].startswith("npmrf3d: interrupted"), (delay, err)
    assert left == [], (delay, left)


@pytest.mark.parametrize("delay", DELAYS)
def test_python_m_interrupted_at_any_moment_is_one_line_and_130(delay, tmp_path):
    _check(*_interrupt_after([sys.executable, "-m", "npmrf3d", *RUN], delay, tmp_path), delay)


@pytest.mark.parametrize("delay", (0.05, 0.3, 1.0, 2.0))
def test_console_script_interrupted_at_any_moment_is_one_line_and_130(delay, tmp_path):
    _check(*_interrupt_after([_script(), *RUN], delay, tmp_path), delay)


def test_sigterm_while_importing_is_one_line_and_130(tmp_path):
    _check(*_interrupt_after([sys.executable, "-m", "npmrf3d", *RUN], 0.2, tmp_path, signal.SIGTERM), 0.2)


def test_the_console_script_enters_through_the_light_entry_point():
    text = pathlib.Path(_script()).read_text()
    assert "from npmrf3d.__main__ import main" in text, text


def test_import_npmrf3d_and_the_entry_point_import_nothing_heavy():
    probe = ("import sys, npmrf3d, npmrf3d.__main__; "
             "print(sorted(m for m in ('numba', 'numpy', 'scipy', 'matplotlib') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out


def test_every_public_name_is_there_on_first_use():
    from npmrf3d.analysis import metrics
    from npmrf3d.methods import synthesize
    from npmrf3d.methods.kopf import kopf_synthesize

    for name in npmrf3d.__all__:
        assert getattr(npmrf3d, name) is not None, name
        assert name in dir(npmrf3d), name
    assert npmrf3d.metrics is metrics and npmrf3d.synthesize is synthesize
    assert npmrf3d.kopf_synthesize is kopf_synthesize and npmrf3d.ParameterError is ParameterError
    assert npmrf3d.data.path("gravel64").is_file()
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        npmrf3d.not_a_name  # noqa: B018
    namespace: dict = {}
    exec("from npmrf3d import *", namespace)
    assert set(npmrf3d.__all__) <= set(namespace)


def test_an_interrupt_while_parsing_is_one_line_and_130(monkeypatch, capsys):
    main_module = importlib.import_module("npmrf3d.cli.main")  # the package's name is the function

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(main_module, "build_parser", interrupted)
    assert cli.main(["info"]) == 130
    assert capsys.readouterr().err == "npmrf3d: interrupted\n"


def test_a_lock_interrupted_while_it_is_taken_is_not_left_behind(monkeypatch, tmp_path):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runs, "clean_stale_staging", interrupted)
    with pytest.raises(KeyboardInterrupt):
        runs.OutputLock(tmp_path / "run").acquire()
    assert list(tmp_path.iterdir()) == [] and not runs._HELD


def test_a_lock_that_cannot_be_written_is_not_left_behind(monkeypatch, tmp_path):
    def full(fd, *args, **kwargs):
        os.close(fd)
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(runs.os, "fdopen", full)
    with pytest.raises(OSError, match="No space left on device"):  # the command line's one line
        runs.OutputLock(tmp_path / "run").acquire()
    assert list(tmp_path.iterdir()) == [] and not runs._HELD
