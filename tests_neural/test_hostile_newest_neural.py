"""The neural part of tests/test_hostile_newest.py: ``neural generate --out X.zarr`` given a
symbolic link that leads nowhere is refused naming the link (one line, exit 2, nothing written)."""

from __future__ import annotations

import os
import pathlib

from tests.cli_checks import refused_naming


def test_neural_generate_names_a_dangling_link_given_as_its_zarr_output(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    os.symlink("nowhere.zarr", "dangling.zarr")
    pathlib.Path("model.pt").write_bytes(b"not read before the output is checked")
    refused_naming(["neural", "generate", "model.pt", "--size", "8", "--out", "dangling.zarr"], tmp_path, capsys,
                   words=["'dangling.zarr' is a symbolic link to 'nowhere.zarr', which does not exist"],
                   not_words=[".partial-"])
