"""The neural commands' argument checks in the hostile round (tests/test_hostile_round.py):
each refusal is one line, exit code 2, nothing new on disk, before any training or loading."""

from __future__ import annotations

import pytest

from tests.cli_checks import refused_naming
from tests.test_hostile_round import NEURAL_CASES, place  # noqa: F401  (the fixture)

#: (argv, words the line holds)
NEURAL = [
    (["neural", "train", "grey.png", "--iterations", "1", "--out", "m.pt", "--checkpoint-every", "5"],
     ["--checkpoint-every", "--checkpoint PATH"]),
    (["neural", "train", "grey.png", "--iterations", "0", "--out", "m.pt"], ["--iterations"]),
    (["neural", "train", "grey.png", "--iterations", "1", "--out", ""], ["--out", "empty"]),
    (["neural", "train", "grey.png", "--iterations", "1", "--out", "adir"], ["'adir'", "folder"]),
    (["neural", "train", "grey.png", "--iterations", "1", "--out", "adir", "--overwrite"],
     ["'adir'", "folder"]),
    (["neural", "train", "grey.png", "--iterations", "1", "--out", "afile"], ["already exists"]),
    (["neural", "train", "grey.png", "--out", "m.pt", "--learning-rate", "nan"], ["--learning-rate"]),
    (["neural", "train", "grey.png", "--out", "m.pt", "--tile", "7"], ["--tile"]),
    (["neural", "train", "grey.png", "--out", "m.pt", "--vgg19", "nothere.pt"], ["--vgg19"]),
    (["neural", "train", "v.npy", "--out", "m.pt"], ["is a volume"]),
    (["neural", "train", "grey.png", "--out", "m.pt", "--views", "side"], ["'side'"]),
    (["neural", "generate", "afile", "--out", "x.png"], ["--out must end"]),
    (["neural", "generate", "afile", "--out", "x.npy", "--origin", "1,2"], ["--origin"]),
    (["neural", "generate", "afile", "--out", "x.npy", "--size", "0"], ["--size"]),
    (["neural", "generate", "afile", "--out", "x.npy", "--block", "64"], ["--block", ".zarr"]),
    (["neural", "generate", "afile", "--out", "x.tif", "--workers", "1"], ["--workers", ".zarr"]),
    (["neural", "generate", "afile", "--out", "x.npy", "--scheduler", "local"], ["--scheduler"]),
]


def test_the_count_in_the_round_is_this_lists():
    assert len(NEURAL) == NEURAL_CASES


@pytest.mark.parametrize("argv, words", NEURAL, ids=[" ".join(a[:6]) for a, _ in NEURAL])
def test_a_neural_command_refuses_in_one_line(argv, words, place, capsys):  # noqa: F811
    refused_naming(argv, place, capsys, words)
