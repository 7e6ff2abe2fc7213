"""``npmrf3d metrics --structure`` (the structure judge per view, as ratios to the floor), the
views a volume's run constrained, and Zarr volumes whose made blocks lost their chunk files."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from npmrf3d import cli
from npmrf3d.analysis.metrics import layout
from npmrf3d.io.zarr_blocks import blocks_without_chunks, open_blocks, write_block
from tests.cli_checks import refused_naming

SIDE, PERIOD = 32, 8


def _lines(n: int) -> np.ndarray:
    return (np.arange(n) % PERIOD == 0).astype(np.float32)


@pytest.fixture
def planted(tmp_path):
    """A grid of thin bright lines with a little noise as the exemplar; a volume of the same
    grid in 3-D (planes every 8 voxels along each axis: every slice of every view holds the
    exemplar's lines); and that volume with its voxels shuffled (the same values, no layout)."""
    rng = np.random.default_rng(0)
    line = _lines(SIDE)
    exemplar = np.maximum(line[:, None], line[None, :]) * 0.8 + 0.2 * rng.random((SIDE, SIDE))
    grid = np.maximum(np.maximum(line[:, None, None], line[None, :, None]), line[None, None, :])
    volume = (grid * 0.8 + 0.2 * rng.random(grid.shape)).astype(np.float32)
    shuffled = rng.permutation(volume.ravel()).reshape(volume.shape)
    paths = {"exemplar": tmp_path / "exemplar.npy", "planted": tmp_path / "planted" / "volume.npy",
             "shuffled": tmp_path / "shuffled" / "volume.npy"}
    np.save(paths["exemplar"], exemplar.astype(np.float32))
    for name, array in (("planted", volume), ("shuffled", shuffled)):
        paths[name].parent.mkdir()
        np.save(paths[name], array)
    return paths


def _judged(paths, name, capsys) -> tuple[dict, str]:
    assert cli.main(["metrics", str(paths["exemplar"]), str(paths[name]), "--structure"]) == 0
    out = capsys.readouterr().out
    record = json.loads((paths[name].parent / "metrics.json").read_text())
    return record["structure"], out


def test_a_planted_layout_scores_better_than_its_voxels_shuffled(planted, capsys):
    good, table = _judged(planted, "planted", capsys)
    bad, _ = _judged(planted, "shuffled", capsys)
    assert set(good["per_view"]) == {"front", "right", "top"}
    for view in good["per_view"]:
        for k in ("pyramid", "continuity"):
            assert good["per_view"][view]["to_floor"][k] < bad["per_view"][view]["to_floor"][k] / 2
            floor = max(good["floor"][view][k], layout.MIN_FLOOR)
            assert good["per_view"][view]["to_floor"][k] == pytest.approx(
                good["per_view"][view]["ratio"][k] / floor)
    assert bad["per_view"]["front"]["ratio"]["pyramid"] == pytest.approx(1.0, abs=0.25)
    assert good["worst"]["pyramid"] == max(s["to_floor"]["pyramid"] for s in good["per_view"].values())
    assert good["per_view"][good["worst_view"]["pyramid"]]["to_floor"]["pyramid"] == good["worst"]["pyramid"]
    row = next(line for line in table.splitlines() if line.startswith("pyramid "))
    assert f"{good['worst']['pyramid']:.3f} {good['worst_view']['pyramid']}" in row
    assert "structure judge, ratio to the floor" in table and "views:" not in table  # no run.json


def test_the_views_a_run_left_free_are_named(planted, capsys):
    folder = planted["planted"].parent
    (folder / "run.json").write_text(json.dumps({"config": {"views": ["front", "top"]}}))
    judged, table = _judged(planted, "planted", capsys)
    assert "views: the run constrained front, top; right was free" in table
    assert "right (free)" in table.splitlines()[[i for i, line in enumerate(table.splitlines())
                                                 if line.startswith("structure judge, ratio")][0]]
    record = json.loads((folder / "metrics.json").read_text())
    assert record["run_views"]["free"] == ["right"] and judged is not None
    assert cli.main(["metrics", str(planted["exemplar"]), str(planted["planted"]), "--overwrite"]) == 0
    out = capsys.readouterr().out
    assert "structure judge" not in out and "right was free" in out     # said without --structure
    assert json.loads((folder / "metrics.json").read_text())["structure"] is None


def test_half_floor_is_the_right_half_against_the_left(planted):
    e = np.load(planted["exemplar"])
    floor = layout.half_floor(e)
    assert 0 < floor["pyramid"] < 0.5 and 0 <= floor["continuity"] < 0.5
    with pytest.raises(ValueError, match="no halves"):
        layout.half_floor(e[:, :12])


def test_missing_scikit_image_is_one_line_naming_the_extra(planted, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "skimage.morphology", None)
    refused_naming(["metrics", str(planted["exemplar"]), str(planted["planted"]), "--structure"],
                   tmp_path, capsys, words=("npmrf3d[structure]", "scikit-image"))


def test_an_exemplar_too_narrow_for_the_floor_is_refused(planted, tmp_path, capsys):
    narrow = tmp_path / "narrow.npy"
    np.save(narrow, np.load(planted["exemplar"])[:, :12])
    refused_naming(["metrics", str(narrow), str(planted["planted"]), "--structure"], tmp_path,
                   capsys, words=("--structure needs exemplars at least 16 pixels wide", "32 x 12"))


# --------------------------------------------------------------------------- Zarr chunks

def _zarr(tmp_path, values: np.ndarray, block: int = 8):
    out = tmp_path / "v.zarr"
    open_blocks(out, size=values.shape[:3], channels=1, block=block, attrs={"test": 1})
    for i in range(values.shape[0] // block):
        for j in range(values.shape[1] // block):
            for k in range(values.shape[2] // block):
                write_block(out, (i, j, k), block, values[i * block:(i + 1) * block,
                                                          j * block:(j + 1) * block,
                                                          k * block:(k + 1) * block])
    return out


def test_a_made_block_whose_chunk_file_is_gone_is_refused(tmp_path, capsys):
    values = (0.1 + 0.8 * np.random.default_rng(0).random((16, 16, 16, 1))).astype(np.float32)
    exemplar = tmp_path / "exemplar.npy"
    np.save(exemplar, values[:, :, 0, 0])
    volume = _zarr(tmp_path, values)
    argv = ["metrics", str(exemplar), str(volume), "--out", str(tmp_path / "m")]
    assert cli.main(argv) == 0
    capsys.readouterr()
    (volume / "0.1.1.0").unlink()          # deleted, while its marker says the block is made
    (volume / "1.0.0.0").unlink()
    assert blocks_without_chunks(volume) == [(0, 1, 1), (1, 0, 0)]
    argv[-1] = str(tmp_path / "m2")
    refused_naming(argv, tmp_path, capsys, words=("is missing 2 of 8 blocks", "chunk files are gone",
                                                  "--overwrite"))


def test_an_unfinished_run_is_refused_with_the_missing_count(tmp_path, capsys):
    values = (0.1 + 0.8 * np.random.default_rng(1).random((16, 16, 16, 1))).astype(np.float32)
    exemplar = tmp_path / "exemplar.npy"
    np.save(exemplar, values[:, :, 0, 0])
    volume = _zarr(tmp_path, values)
    for marker in ("0.0.1", "1.1.1", "1.1.0"):
        (volume / ".npmrf3d-done" / marker).unlink()
    refused_naming(["metrics", str(exemplar), str(volume), "--out", str(tmp_path / "m")], tmp_path,
                   capsys, words=("not complete (5 of 8 blocks made): 3 blocks missing",))


def test_a_block_of_zeros_has_its_chunk_file_and_is_read(tmp_path, capsys):
    values = np.random.default_rng(2).integers(0, 2, (16, 16, 16, 1)).astype(np.float32)
    values[:8, :8, :8] = 0.0               # an all-zero block: its chunk file is written all the same
    exemplar = tmp_path / "exemplar.npy"
    np.save(exemplar, values[:, :, 12, 0])
    volume = _zarr(tmp_path, values)
    assert blocks_without_chunks(volume) == []
    assert cli.main(["metrics", str(exemplar), str(volume), "--out", str(tmp_path / "m")]) == 0
    assert capsys.readouterr().err == ""
    assert (tmp_path / "m" / "metrics.json").is_file()
    (volume / "0.0.0.0").unlink()          # now lost: refused like any other lost chunk
    refused_naming(["metrics", str(exemplar), str(volume), "--out", str(tmp_path / "m2")], tmp_path,
                   capsys, words=("is missing 1 of 8 blocks",))
