"""Checkpoints whose checksum holds but whose contents are not a state of this run.

A checkpoint is re-sealed after one member is changed (:func:`craft`, with the checksum
recomputed by :func:`npmrf3d.io.checkpoints.seal`), so it passes the integrity check; the run
must still refuse it before any work: one line, exit code 2, no run folder, the checkpoint left
as it was. An unchanged checkpoint re-sealed the same way resumes (the control).
"""

from __future__ import annotations

import json
import pathlib

import numpy as np
import pytest

from npmrf3d.cli import main
from npmrf3d.errors import ParameterError
from npmrf3d.io.checkpoints import CHECKSUM, seal
from npmrf3d.methods import METHODS

#: Commands that resume through the level loop: tiny runs of two levels (16^3, then 8^3).
COMMANDS = {
    "synth": ["synth", "bundled:gravel64", "--size", "16", "--levels", "2"],
    "synth-full": ["synth", "bundled:gravel64", "--size", "16", "--levels", "2", "--window", "5",
                   "--support", "full", "--grey-levels", "4"],
    "chen-wang": ["baseline", "chen-wang", "bundled:gravel64", "--size", "16", "--levels", "2",
                  "--window", "4", "--iterations", "2"],
}
REFUSED = "does not hold a state this run can resume"


def craft(source: pathlib.Path, target: pathlib.Path, change) -> pathlib.Path:
    """Load the checkpoint ``source`` member by member (exact dtypes), let ``change(members)``
    alter it, and write it re-sealed with its checksum recomputed to ``target``."""
    with open(source, "rb") as handle, np.load(handle, allow_pickle=False) as npz:
        members = {name: npz[name] for name in npz.files if name != CHECKSUM}
    change(members)
    with open(target, "wb") as handle:
        np.savez(handle, **seal(members))
    return target


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """command -> the checkpoint of a finished run (its last member: level 0, 16^3)."""
    root = tmp_path_factory.mktemp("finished")
    paths = {}
    for name, argv in COMMANDS.items():
        paths[name] = root / f"{name}.npz"
        code = main([*argv, "--quiet", "--out", str(root / name), "--checkpoint", str(paths[name])])
        assert code == 0 and paths[name].is_file()
    return paths


def _run(name, checkpoint, out, capsys):
    code = main([*COMMANDS[name], "--quiet", "--out", str(out), "--checkpoint", str(checkpoint)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def _set(name, value):
    def change(members):
        members[name] = np.asarray(value)
    return change


def _drop(name):
    def change(members):
        del members[name]
    return change


def _apply(name, fn):
    def change(members):
        members[name] = fn(members[name])
    return change


def _json(name, fn):
    return _apply(name, lambda text: np.asarray(json.dumps(fn(json.loads(str(text))))))


def _nan(volume):
    volume = volume.copy()
    volume[1, 2, 3, 0] = np.nan
    return volume


#: id -> (change, words the message must contain): each changes one member, every command.
CASES = {
    "level 99": (_set("level", 99), "'level' is 99"),
    "level -1": (_set("level", -1), "'level' is -1"),
    "level 1 with the 16^3 volume of level 0": (_set("level", 1), "shape (16, 16, 16, "),
    "level as text": (_set("level", "0"), "'level' is '0'"),
    "rng_state not JSON": (_set("rng_state", "garbage{"), "'rng_state'"),
    "rng_state of another generator": (
        _json("rng_state", lambda s: {**s, "bit_generator": "MT19937"}), "'MT19937'"),
    "rng_state out of range": (
        _json("rng_state", lambda s: {**s, "state": {"state": -1, "inc": 1}}), "'rng_state'"),
    "rng_state without its state": (
        _json("rng_state", lambda s: {"bit_generator": s["bit_generator"]}), "'rng_state'"),
    "rng_state a list": (_json("rng_state", lambda s: [1, 2, 3]), "'rng_state'"),
    "volume of a coarser level": (_apply("volume", lambda v: v[::2, ::2, ::2]), "'volume' has shape (8, 8, 8, "),
    "volume with three channels": (_apply("volume", lambda v: np.repeat(v, 3, axis=3)), "'volume' has shape"),
    "volume float64": (_apply("volume", lambda v: v.astype(np.float64)), "'volume' has dtype float64"),
    "volume with NaN": (_apply("volume", _nan), "'volume' holds NaN"),
    "volume a scalar": (_set("volume", 0.5), "'volume' is float"),
    "temps wrong shape": (_apply("temps", lambda t: t[:8]), "'temps' has shape"),
    "temps negative": (_apply("temps", lambda t: t - 2.0), "'temps' holds values below"),
    "inherited as integers": (_apply("inherited", lambda m: m.astype(np.int8)), "'inherited' has dtype int8"),
    "volume missing": (_drop("volume"), "member 'volume' is missing"),
    "rng_state missing": (_drop("rng_state"), "member 'rng_state' is missing"),
    "extra member": (_set("bogus", np.zeros(3)), "member 'bogus' is not part"),
    "history too short": (_json("history", lambda h: h[:1]), "'history'"),
    "history not numbers": (_json("history", lambda h: [["x"]] * len(h)), "'history'"),
    "timings a list": (_json("timings", lambda t: [1]), "'timings'"),
    "stats without levels": (_json("stats", lambda s: {"threads": 1}), "'stats'"),
}
#: Members of one kind of state only: id -> (commands, change, words).
SPECIFIC = {
    "sources beyond the exemplar": (("synth", "chen-wang"),
                                    _apply("sources", lambda s: s + 64 * 64), "'sources' holds values above"),
    "sources int64": (("synth", "chen-wang"),
                      _apply("sources", lambda s: s.astype(np.int64)), "'sources' has dtype int64"),
    "widths of another level": (("synth", "chen-wang"), _apply("widths", lambda w: w // 2), "'widths'"),
    "labels beyond the label set": (("synth-full",),
                                    _apply("labels_volume", lambda s: s + 1000), "'labels_volume' holds values above"),
    "labels negative": (("synth-full",), _apply("labels_volume", lambda s: s - 1000), "'labels_volume' holds values below"),
}


def _assert_refused(code, out, err, run_dir, checkpoint, before, words):
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2, err
    assert len(lines) == 1, err
    assert lines[0].startswith(("npmrf3d: error: checkpoint ", "npmrf3d: error: --checkpoint ")) and REFUSED in lines[0], lines[0]
    assert words in lines[0], lines[0]
    assert "Traceback" not in err and out == ""
    assert not run_dir.exists()
    assert checkpoint.read_bytes() == before
    assert sorted(p.name for p in checkpoint.parent.iterdir()) == [checkpoint.name]


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_unchanged_checkpoint_resealed_resumes(name, finished, tmp_path, capsys):
    checkpoint = craft(finished[name], tmp_path / "ck.npz", lambda members: None)
    code, out, err = _run(name, checkpoint, tmp_path / "run", capsys)
    assert code == 0, err
    assert np.load(tmp_path / "run" / "volume.npy").shape == (16, 16, 16, 1)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_changed_member_is_refused_before_any_work(name, case, finished, tmp_path, capsys):
    change, words = CASES[case]
    folder = tmp_path / "ck"
    folder.mkdir()
    checkpoint = craft(finished[name], folder / "ck.npz", change)
    before = checkpoint.read_bytes()
    code, out, err = _run(name, checkpoint, tmp_path / "run", capsys)
    _assert_refused(code, out, err, tmp_path / "run", checkpoint, before, words)


@pytest.mark.parametrize("case, name", [(case, name) for case, (names, _, _) in sorted(SPECIFIC.items())
                                        for name in names])
def test_changed_method_member_is_refused(name, case, finished, tmp_path, capsys):
    _, change, words = SPECIFIC[case]
    folder = tmp_path / "ck"
    folder.mkdir()
    checkpoint = craft(finished[name], folder / "ck.npz", change)
    before = checkpoint.read_bytes()
    code, out, err = _run(name, checkpoint, tmp_path / "run", capsys)
    _assert_refused(code, out, err, tmp_path / "run", checkpoint, before, words)


def test_level_below_zero_never_returns_a_coarser_volume(tmp_path, tiny_grey):
    """Through the library: a checkpoint of level 1 (8^3) re-sealed as level -1 is refused
    rather than returned as the 16^3 run's result."""
    synthesize = METHODS["chen-wang"].synthesize
    kwargs = dict(size=16, window=(4, 4), levels=2, iterations=(2, 2))
    path = tmp_path / "run.npz"

    class Stop(Exception):
        pass

    def interrupt(level, step, steps, value):
        if level == 0 and step == 1:
            raise Stop

    with pytest.raises(Stop):
        synthesize(tiny_grey, rng=5, progress=interrupt, checkpoint=path, **kwargs)
    with np.load(path) as npz:
        assert int(npz["level"]) == 1 and npz["volume"].shape == (8, 8, 8, 1)
    craft(path, path, _set("level", -1))
    with pytest.raises(ParameterError, match=r"'level' is -1; this run has levels 0 to 1"):
        synthesize(tiny_grey, rng=5, checkpoint=path, **kwargs)
    craft(path, path, _set("level", 1))  # the same file as level 1 again resumes
    assert synthesize(tiny_grey, rng=5, checkpoint=path, **kwargs).volume.shape == (16, 16, 16, 1)
