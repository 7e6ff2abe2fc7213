"""The command lines of the coherent methods: ``npmrf3d coherent`` and ``npmrf3d baseline chen-wang``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from npmrf3d.cli import main

COMMANDS = {"coherent": ["coherent"], "chen-wang": ["baseline", "chen-wang"]}


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_tiny_run_writes_a_complete_folder_of_exemplar_colours(name, tmp_path, capsys):
    out = tmp_path / "run"
    code = main([*COMMANDS[name], "bundled:gravel64", "--size", "16", "--levels", "2", "--window", "4",
                 "--iterations", "2", "--out", str(out), "--quiet"])
    assert code == 0
    assert {p.name for p in out.iterdir()} == {"volume.npy", "volume.tif", "preview.png", "run.json"}
    record = json.loads((out / "run.json").read_text())
    assert record["method"] == name
    assert record["config"]["levels"] == 2 and record["config"]["window"] == [4, 4]
    volume = np.load(out / "volume.npy")
    assert volume.shape == (16, 16, 16, 1)
    from npmrf3d import data, load_exemplar
    assert set(np.unique(volume)) <= set(np.unique(load_exemplar(data.path("gravel64"))))


@pytest.mark.parametrize("name", sorted(COMMANDS))
@pytest.mark.parametrize("bad, message", [
    (["--window", "8,6"], "--window must be one integer or 3 integers"),
    (["--window", "x"], "--window"),
    (["--size", "30"], "size"),
    (["--k", "0"], "--k must be"),
])
def test_bad_options_exit_2_and_write_nothing(name, bad, message, tmp_path, capsys):
    out = tmp_path / "never"
    try:
        code = main([*COMMANDS[name], *bad, "--out", str(out)])
    except SystemExit as exc:  # argparse's own type errors
        code = exc.code
    assert code == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_coherent_refuses_to_anneal_a_heuristic_without_objective(tmp_path, capsys):
    assert main(["coherent", "--heuristic", "ML_H1a", "--t0", "1", "--out", str(tmp_path / "x")]) == 2
    assert "heuristic ML_H1a cannot be annealed (t0 > 0): ML_H1a and ML_H1b are ICM-only" in capsys.readouterr().err
    assert main(["coherent", "--heuristic", "ML_H3", "--out", str(tmp_path / "y")]) == 2
    assert "--heuristic must be one of ML_H2b, ML_H2a, ML_H1a, ML_H1b" in capsys.readouterr().err


def test_synth_grid_is_refused_where_it_cannot_apply(tmp_path, capsys):
    """Sparse sites need the coherent support, a spacing within the window and levels it divides."""
    from tests.cli_checks import refused_naming
    base = ["synth", "--size", "16", "--levels", "2", "--window", "3", "--out", str(tmp_path / "o")]
    refused_naming([*base, "--grid", "2", "--support", "full"], tmp_path, capsys, words=("grid 2", "coherent"))
    refused_naming([*base, "--grid", "5"], tmp_path, capsys, words=("grid",))
    refused_naming(["synth", "--size", "36", "--levels", "3", "--window", "3", "--grid", "2", "--out",
                    str(tmp_path / "o")], tmp_path, capsys, words=("grid 2", "level 2", "9 voxels"))
    assert not (tmp_path / "o").exists()
    assert main([*base, "--grid", "2", "--seed", "1"]) == 0
    assert json.loads((tmp_path / "o" / "run.json").read_text())["config"]["grid"] == 2
