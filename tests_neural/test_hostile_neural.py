"""Hostile command lines of the neural method (train, generate): each refused in one line with
exit code 2 and nothing left behind, or working as a user expects (the other sub-commands:
``tests/test_hostile_cases.py``, whose folder fixture and checks these share)."""

from __future__ import annotations

import pathlib

import imageio.v3 as iio
import numpy as np
import pytest

from npmrf3d import cli
from tests.cli_checks import one_line_error, refused_naming
from tests.test_hostile_cases import _unwritable, place  # noqa: F401 (a fixture)


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> pathlib.Path:
    folder = tmp_path_factory.mktemp("model")
    rng = np.random.default_rng(0)
    iio.imwrite(folder / "good.png", rng.integers(0, 256, (16, 16, 3), dtype=np.uint8))
    code = cli.main(["neural", "train", str(folder / "good.png"), "--iterations", "1", "--size", "16",
                     "--threads", "1", "--out", str(folder / "model.pt"), "--quiet"])
    assert code == 0
    return folder / "model.pt"


@pytest.fixture
def neural_place(place, model_file) -> pathlib.Path:  # noqa: F811 (the imported fixture)
    import torch

    from npmrf3d.methods.neural.engine import FORMAT

    (place / "model.pt").write_bytes(model_file.read_bytes())
    payload = torch.load(model_file, weights_only=True)
    assert payload["format"] == FORMAT
    torch.save({k: v for k, v in payload.items() if k != "state"}, place / "nostate.pt")
    torch.save({**payload, "config": "{not json"}, place / "badconfig.pt")
    torch.save({**payload, "out_channels": 7}, place / "badchannels.pt")
    torch.save({"folder": pathlib.Path("x")}, place / "objects.pt")  # a Python object, never unpickled
    (place / "trunc.pt").write_bytes(model_file.read_bytes()[:2000])
    return place


NEURAL = [
    (["neural", "generate", "good.png", "--size", "8", "--out", "g.npy"],
     ["cannot be read as a neural model", "not a file written by torch"], ["weights_only", "Python objects"]),
    (["neural", "generate", "objects.pt", "--size", "8", "--out", "g.npy"],
     ["cannot be read as a neural model", "Python objects"], ["weights_only"]),
    (["neural", "generate", "trunc.pt", "--size", "8", "--out", "g.npy"],
     ["cannot be read as a neural model"], ["If you are seeing"]),
    (["neural", "generate", "nostate.pt", "--size", "8", "--out", "g.npy"], ["damaged", "'state'"], []),
    (["neural", "generate", "badconfig.pt", "--size", "8", "--out", "g.npy"], ["damaged"], []),
    (["neural", "generate", "badchannels.pt", "--size", "8", "--out", "g.npy"], ["damaged"], []),
    (["neural", "train", "good.png", "--iterations", "1", "--descriptor", "vgg19", "--vgg19", "good.png",
      "--out", "m.pt"], ["--vgg19 'good.png'"], ["vgg19_weights", "weights_only"]),
    (["neural", "train", "good.png", "--iterations", "1", "--threads", "0", "--out", "m.pt"],
     ["--threads", "positive"], []),
    (["neural", "generate", "model.pt", "--size", "8", "--out", "g.npy", "--threads=-2"],
     ["--threads", "positive"], []),
    (["neural", "generate", "model.pt", "--size", "8", "--origin", "99999999999999999999999,0,0",
      "--out", "g.npy"], ["--origin must be between"], []),
    (["neural", "generate", "model.pt", "--size", "8", "--origin", "1.5,0,0", "--out", "g.npy"],
     ["--origin must be"], ["--size"]),
    (["neural", "generate", "model.pt", "--size", "8", "--out", "g.zarr", "--scheduler", "garbage"],
     ["--scheduler must be", "'garbage'"], []),
    (["neural", "generate", "model.pt", "--size", "8", "--out", "g.zarr", "--scheduler", "serial"],
     ["--scheduler must be"], []),
    (["neural", "generate", "model.pt", "--size", "8", "--out", "g.zarr", "--scheduler",
      "tcp://127.0.0.1:1"], ["cannot reach the Dask scheduler"], []),
    (["neural", "train", "good.png", "--iterations", "0", "--out", "m.pt"], ["--iterations must"], []),
    (["neural", "generate", "adir", "--size", "8", "--out", "g.npy"], ["model must be an existing"], []),
]


@pytest.mark.parametrize("argv, words, not_words", NEURAL, ids=[" ".join(a) for a, _, _ in NEURAL])
def test_neural_refusal(argv, words, not_words, neural_place, capsys):
    refused_naming(argv, neural_place, capsys, words, not_words)


@pytest.mark.parametrize("argv, words", [
    (["neural", "train", "good.png", "--iterations", "1", "--size", "16", "--out", "ro/m.pt"],
     "folder of model file 'ro/m.pt' is not writable"),
    (["neural", "train", "good.png", "--iterations", "1", "--size", "16", "--out", "m.pt",
      "--checkpoint", "ro/c.ckpt"], "folder of checkpoint 'ro/c.ckpt' is not writable"),
])
def test_neural_unwritable_folders_are_refused_before_training(argv, words, neural_place, capsys,
                                                                monkeypatch):
    _unwritable(monkeypatch)
    assert words in one_line_error(argv, neural_place, capsys)


def test_neural_far_origin_within_the_bound_works(neural_place, capsys):
    argv = ["neural", "generate", "model.pt", "--size", "8", "--origin=-1099511627776,5,0",
            "--out", "g.npy", "--quiet", "--threads", "1"]
    assert cli.main(argv) == 0, capsys.readouterr().err
    assert np.load(neural_place / "g.npy").shape[:3] == (8, 8, 8)
