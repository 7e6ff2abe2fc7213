"""Tests for ``npmrf3d metrics`` (npmrf3d._cli_metrics), run in-process through ``cli.main``."""

from __future__ import annotations

import json
import pathlib
import re

import imageio.v3 as iio
import numpy as np
import pytest
from scipy import ndimage

from npmrf3d import cli, io
from npmrf3d.analysis import metrics
from npmrf3d.cli.metrics import OUT_FILES

SIDE, DEPTH = 24, 12


@pytest.fixture
def exemplar_u8() -> np.ndarray:
    x = ndimage.gaussian_filter(np.random.default_rng(0).standard_normal((SIDE, SIDE)), 1.5)
    return np.round((x - x.min()) / (x.max() - x.min()) * 255).astype(np.uint8)


@pytest.fixture
def files(tmp_path, exemplar_u8) -> dict[str, pathlib.Path]:
    """An 8-bit PNG exemplar; a float volume whose right slices volume[i] are that exemplar
    (as synth writes volumes: float32 in [0, 1]); and a white-noise volume."""
    paths = {"exemplar": tmp_path / "exemplar.png", "stacked": tmp_path / "stacked" / "volume.npy",
             "noise": tmp_path / "noise.npy"}
    iio.imwrite(paths["exemplar"], exemplar_u8)
    paths["stacked"].parent.mkdir()
    stacked = np.stack([exemplar_u8.astype(np.float32) / 255] * DEPTH)[..., None]
    np.save(paths["stacked"], stacked)
    np.save(paths["noise"], np.random.default_rng(1).random((DEPTH, SIDE, SIDE), dtype=np.float32))
    return paths


def run_cli(capsys, *argv: str) -> tuple[int, str, str]:
    code = cli.main(list(argv))
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def assert_user_error(code: int, out: str, err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 2 and out == ""
    assert len(lines) == 1, err
    assert lines[0].startswith("npmrf3d: error: ") and "Traceback" not in err
    return lines[0]


def no_leftovers(folder: pathlib.Path) -> bool:
    return not any(".tmp-" in p.name for p in folder.rglob("*"))


def table_rows(out: str) -> dict[str, list[float]]:
    rows = {}
    for line in out.splitlines():
        parts = line.split()
        if parts and parts[0] in ("front", "right", "top", "mean"):
            rows[parts[0]] = [float(x) for x in parts[1:]]
    return rows


def test_help_lists_every_option_with_its_default(capsys):
    code, out, err = run_cli(capsys, "metrics", "--help")
    assert code == 0 and err == ""
    text = " ".join(out.split())
    parser = cli.build_parser()._subparsers._group_actions[0].choices["metrics"]
    for action in parser._actions:
        for option in action.option_strings:
            assert option in text
        if action.option_strings and action.option_strings != ["-h", "--help"]:
            assert "default" in action.help or action.default is not None or action.default is False
    for expected in ("(default: front,right,top)", "(default: the folder holding VOLUME)",
                     "(default: none = EXEMPLAR)", "docs/metrics.md",
                     "bundled:NAME"):
        assert expected in text, expected
    code, out, _ = run_cli(capsys, "--help")
    assert code == 0 and "metrics" in out


def test_stacked_volume_table_json_and_figure(files, capsys):
    volume = files["stacked"]
    code, out, err = run_cli(capsys, "metrics", str(files["exemplar"]), str(volume))
    assert code == 0, err
    assert err == ""
    header = out.splitlines()[0].split()
    assert header == ["view", *metrics.METRICS]
    rows = table_rows(out)
    assert list(rows) == ["front", "right", "top", "mean"]
    assert rows["right"] == pytest.approx([0.0] * 4, abs=1e-9)
    assert rows["front"][1] > 1.0  # front slices are constant along i
    folder = volume.parent  # default --out: the folder holding VOLUME
    assert all((folder / name).is_file() for name in OUT_FILES)
    assert no_leftovers(folder)
    record = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
    for key in ("command", "argv", "inputs", "views", "metrics", "per_view", "mean", "settings",
                "details", "versions", "created"):
        assert key in record, key
    assert record["argv"][:2] == ["npmrf3d", "metrics"]
    assert record["inputs"]["exemplars"] == {v: str(files["exemplar"])
                                             for v in ("front", "right", "top")}
    assert record["inputs"]["volume_shape"] == [DEPTH, SIDE, SIDE, 1]
    assert record["versions"]["numpy"] == np.__version__
    assert record["settings"]["bins"] == 32 and record["settings"]["max_lag"] == 32
    assert record["per_view"]["right"]["histogram_kl"] == 0.0
    for name in metrics.METRICS:
        assert record["mean"][name] == pytest.approx(rows["mean"][metrics.METRICS.index(name)],
                                                     rel=1e-3, abs=1e-12)
    picture = iio.imread(folder / "histograms.png")
    assert picture.ndim == 3 and picture.shape[1] > picture.shape[0] > 200


def test_noise_scores_worse_and_tif_volumes_agree_with_npy(files, tmp_path, capsys):
    code, out, err = run_cli(capsys, "metrics", str(files["exemplar"]), str(files["noise"]),
                             "--views", "right", "--out", str(tmp_path / "noise_out"))
    assert code == 0, err
    noise = table_rows(out)["right"]
    assert noise[0] > 0.05 and noise[1] > 1.0 and noise[3] > 0.05
    tif = tmp_path / "noise.tif"
    io.write_volume_tiff(tif, np.load(files["noise"])[..., None])
    code, out, err = run_cli(capsys, "metrics", str(files["exemplar"]), str(tif),
                             "--views", "right", "--out", str(tmp_path / "tif_out"))
    assert code == 0, err
    assert table_rows(out)["right"] == noise


def test_integer_volume_is_scaled_like_the_exemplar(files, exemplar_u8, tmp_path, capsys):
    path = tmp_path / "u8.npy"
    np.save(path, np.stack([exemplar_u8] * DEPTH))
    code, out, err = run_cli(capsys, "metrics", str(files["exemplar"]), str(path),
                             "--views", "right")
    assert code == 0, err
    assert table_rows(out)["right"] == pytest.approx([0.0] * 4, abs=1e-9)
    record = json.loads((tmp_path / "metrics.json").read_text(encoding="utf-8"))
    assert record["inputs"]["volume_dtype"] == "uint8"


def test_bundled_and_per_view_exemplars(files, tmp_path, capsys):
    other = tmp_path / "other.npy"
    np.save(other, np.random.default_rng(2).random((SIDE, SIDE)))
    code, out, err = run_cli(capsys, "metrics", "bundled:gravel64", str(files["stacked"]),
                             "--views", "right,top", "--exemplar-right", str(files["exemplar"]),
                             "--exemplar-top", str(other), "--out", str(tmp_path / "o"))
    assert code == 0, err
    rows = table_rows(out)
    assert list(rows) == ["right", "top", "mean"] and rows["right"][0] == 0.0
    record = json.loads((tmp_path / "o" / "metrics.json").read_text(encoding="utf-8"))
    assert record["inputs"]["exemplars"] == {"right": str(files["exemplar"]), "top": str(other)}
    code, out, err = run_cli(capsys, "metrics", "bundled:gravel64", str(files["stacked"]),
                             "--views", "front", "--out", str(tmp_path / "g"))
    assert code == 0, err
    assert json.loads((tmp_path / "g" / "metrics.json").read_text(encoding="utf-8"))[
        "inputs"]["exemplars"] == {"front": "bundled:gravel64"}


def test_colour_exemplar_and_volume(tmp_path, capsys):
    rng = np.random.default_rng(3)
    colour = (rng.random((16, 16, 3)) * 255).astype(np.uint8)
    iio.imwrite(tmp_path / "c.png", colour)
    np.save(tmp_path / "c.npy", np.stack([colour.astype(np.float32) / 255] * 8))
    code, out, err = run_cli(capsys, "metrics", str(tmp_path / "c.png"), str(tmp_path / "c.npy"))
    assert code == 0, err
    assert table_rows(out)["right"] == pytest.approx([0.0] * 4, abs=1e-9)
    record = json.loads((tmp_path / "metrics.json").read_text(encoding="utf-8"))
    assert record["settings"]["channels"] == 3 and record["settings"]["joint_bins_used"] == 8


def test_rerun_needs_overwrite(files, capsys):
    args = ["metrics", str(files["exemplar"]), str(files["stacked"]), "--views", "right"]
    assert run_cli(capsys, *args)[0] == 0
    folder = files["stacked"].parent
    before = {name: (folder / name).read_bytes() for name in OUT_FILES}
    line = assert_user_error(*run_cli(capsys, *args))
    assert "--overwrite" in line and "metrics.json" in line
    assert {name: (folder / name).read_bytes() for name in OUT_FILES} == before
    code, out, err = run_cli(capsys, *args, "--views", "front", "--overwrite")
    assert code == 0, err
    record = json.loads((folder / "metrics.json").read_text(encoding="utf-8"))
    assert record["views"] == ["front"]


def _nan_volume(tmp_path):
    array = np.zeros((8, 8, 8), dtype=np.float32)
    array[1, 2, 3] = np.nan
    np.save(tmp_path / "nan.npy", array)
    return tmp_path / "nan.npy"


@pytest.mark.parametrize("case, expected", [
    ("missing volume", "volume file"),
    ("nan volume", "volume file .* contains 1 NaN"),
    ("2d volume", "must hold an array of shape"),
    ("channel mismatch", "3 channel"),
    ("bad view", "view must be one of front, right, top; got 'back'"),
    ("unused per-view exemplar", "--exemplar-top is given but top is not among --views"),
    ("unknown bundled", "gravel99"),
    ("missing exemplar", "exemplar file"),
    ("tiny volume", "too small"),
    ("empty out", "--out must name a folder"),
    ("out is a file", "exists and is not a folder"),
])
def test_user_errors_are_one_line_and_write_nothing(case, expected, files, tmp_path, capsys):
    out_dir = tmp_path / "out"
    exemplar, volume = str(files["exemplar"]), str(files["noise"])
    extra: list[str] = []
    if case == "missing volume":
        volume = str(tmp_path / "nope.npy")
    elif case == "nan volume":
        volume = str(_nan_volume(tmp_path))
    elif case == "2d volume":
        np.save(tmp_path / "flat.npy", np.zeros((8, 8)))
        volume = str(tmp_path / "flat.npy")
    elif case == "channel mismatch":
        iio.imwrite(tmp_path / "rgb.png", np.zeros((16, 16, 3), np.uint8))
        exemplar = str(tmp_path / "rgb.png")
    elif case == "bad view":
        extra = ["--views", "front,back"]
    elif case == "unused per-view exemplar":
        extra = ["--views", "front", "--exemplar-top", exemplar]
    elif case == "unknown bundled":
        exemplar = "bundled:gravel99"
    elif case == "missing exemplar":
        exemplar = str(tmp_path / "none.png")
    elif case == "tiny volume":
        np.save(tmp_path / "tiny.npy", np.zeros((3, 8, 8)))
        volume = str(tmp_path / "tiny.npy")
    out = str(out_dir)
    if case == "empty out":
        out = " "
    elif case == "out is a file":
        out_dir.write_text("x")
    line = assert_user_error(*run_cli(capsys, "metrics", exemplar, volume, "--out", out, *extra))
    assert re.search(expected, line), line
    if case != "out is a file":
        assert not out_dir.exists()
    assert no_leftovers(tmp_path)


def test_write_failure_leaves_no_folder(files, tmp_path, capsys, monkeypatch):
    from npmrf3d import io as npio

    def broken(path, obj):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(npio, "write_json", broken)
    out_dir = tmp_path / "new" / "deeper"
    line = assert_user_error(*run_cli(capsys, "metrics", str(files["exemplar"]),
                                      str(files["noise"]), "--out", str(out_dir)))
    assert "cannot write" in line and "Permission denied" in line
    assert not (tmp_path / "new").exists()
