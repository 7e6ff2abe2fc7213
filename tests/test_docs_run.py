"""Docs that run: the shell commands and Python snippets of README.md and docs/*.md, on tiny sizes.

Every fenced ``bash``/``console``/``sh``/``python`` block is either run here or listed as long:
by a marker comment ``<!-- long: N min (why) -->`` on the line(s) right before the block, or in
:data:`NOT_RUN_HERE` below with its reason and time. Blocks that are neither fail
:func:`test_every_block_is_run_or_listed_as_long`. A run block may hold only ``npmrf3d ...`` /
``python -m npmrf3d ...`` lines (bash) or Python; each runs in a fresh temporary folder that
holds small stand-ins for the files the docs name (``crop.npy``, ``slice.npy``, ``wood.png``,
...), with ``--size N`` made 16 (and at most 2 pyramid levels for the 2D methods) and Python's
``size=N`` made 16 (2 levels at most), in this process (``npmrf3d.cli.main``), so the whole module takes well under
two minutes on one core once the kernels are compiled.
"""

from __future__ import annotations

import os
import pathlib
import re
import shlex
from dataclasses import dataclass

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))

#: Blocks not run here and not marked in their page: (page, first line) -> why, and how long.
NOT_RUN_HERE = {
    ("README.md", "pip install . && npmrf3d synth --size 64 --out npmrf3d-out"):
        "run as written by .ci/run in a fresh virtual environment (about 2 min with the install)",
    ("README.md", 'pip install -e ".[test]" && python -m pytest'):
        "the whole test suite, run by .ci/run (about 10 min)",
    ("docs/architecture.md", "@dataclass(frozen=True)"):
        "a template of a method module, not a program (0 min: nothing to run)",
}

_FENCE = re.compile(r"^```(bash|console|sh|python)[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)
_LONG = re.compile(r"<!--\s*long:\s*(\d+(?:\.\d+)?)\s*(?:min|h)\b[^>]*-->")
_TWO_D = {"synth", "npmrf", "coherent", "kopf", "chen-wang", "baseline", "materials"}


@dataclass(frozen=True)
class Block:
    page: str
    line: int
    lang: str
    body: str
    long: bool

    @property
    def key(self) -> tuple[str, str]:
        first = next((ln.strip() for ln in self.body.splitlines() if ln.strip()), "")
        return self.page, first

    def __str__(self) -> str:
        return f"{self.page}:{self.line}"


def _blocks() -> list[Block]:
    out = []
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for m in _FENCE.finditer(text):
            before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
            out.append(Block(str(path.relative_to(ROOT)), text.count("\n", 0, m.start()) + 1,
                             m.group(1), m.group(2), bool(_LONG.search(before))))
    return out


BLOCKS = _blocks()
RUN = [b for b in BLOCKS if not b.long and b.key not in NOT_RUN_HERE]


def test_every_block_is_run_or_listed_as_long():
    assert len(BLOCKS) > 10
    listed = {b.key for b in BLOCKS if b.key in NOT_RUN_HERE}
    assert listed == set(NOT_RUN_HERE), set(NOT_RUN_HERE) - listed   # no stale entries
    for b in RUN:   # everything else runs here, so it must be something this module can run
        if b.lang == "python":
            continue
        for cmd in _commands(b.body):
            assert cmd[:1] == ["npmrf3d"], (
                f"{b}: {' '.join(cmd)!r} is not an npmrf3d command: mark the block "
                "<!-- long: N min (why) --> or list it in NOT_RUN_HERE")


def _commands(body: str) -> list[list[str]]:
    text = re.sub(r"\\\n\s*", " ", body)
    cmds = []
    for line in text.splitlines():
        line = re.sub(r"^\$\s+", "", line.strip())
        if not line or line.startswith("#"):
            continue
        argv = shlex.split(line, comments=True)
        if argv[:3] == ["python", "-m", "npmrf3d"]:
            argv = ["npmrf3d"] + argv[3:]
        cmds.append(argv)
    return cmds


def _tiny(argv: list[str]) -> list[str]:
    """The command at a tiny size: ``--size 16``; 2D methods at most 2 levels."""
    args = list(argv[1:])
    for i, a in enumerate(args[:-1]):
        if a == "--size":
            args[i + 1] = "16"
    if args and args[0] in _TWO_D and "--size" in args:
        if "--levels" in args:
            i = args.index("--levels") + 1
            args[i] = str(min(int(args[i]), 2))
        else:
            args += ["--levels", "2"]
        if "--window" in args and "," in args[args.index("--window") + 1]:
            i = args.index("--window") + 1
            args[i] = ",".join(args[i].split(",")[-2:])
    return args


def _tiny_python(body: str) -> str:
    """Python at a tiny size: ``size=16``, at most 2 levels (added to a call that names none)."""
    body = re.sub(r"\bwindow=\(\d+, (\d+), (\d+)\)", r"window=(\1, \2)", body)
    body = re.sub(r"\blevels=\d+", "levels=2", body)
    out, pos = [], 0
    for m in re.finditer(r"\bsize=\d+", body):
        depth, end = 0, m.end()
        while end < len(body) and not (depth == 0 and body[end] == ")"):
            depth += {"(": 1, ")": -1}.get(body[end], 0)
            end += 1
        start = body.rfind("(", 0, m.start())
        call = body[start:end]
        out.append(body[pos:m.start()] + ("size=16" if "levels=" in call else "size=16, levels=2"))
        pos = m.end()
    return "".join(out) + body[pos:]


@pytest.fixture
def stand_ins(tmp_path, monkeypatch):
    """A folder with small stand-ins for every file the docs name."""
    import imageio.v3 as iio
    import tifffile
    from scipy import ndimage

    import npmrf3d

    rng = np.random.default_rng(0)
    porous = ndimage.gaussian_filter(rng.random((24, 24, 24)), 2)
    crop = (porous > np.median(porous)).astype(np.uint8) * 255
    np.save(tmp_path / "crop.npy", crop)
    tifffile.imwrite(tmp_path / "crop.tif", crop, imagej=True, metadata={"axes": "ZYX"})
    flat = ndimage.gaussian_filter(rng.random((48, 48)), 1.5)
    np.save(tmp_path / "slice.npy", (flat > np.quantile(flat, 0.2)).astype(np.uint8) * 255)
    wood = np.asarray(iio.imread(npmrf3d.data.path("wood")))
    iio.imwrite(tmp_path / "wood.png", wood[:64, :64])
    gravel = np.asarray(iio.imread(npmrf3d.data.path("gravel64")))
    iio.imwrite(tmp_path / "a.png", gravel)
    iio.imwrite(tmp_path / "b.png", gravel[::-1])
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.slow
@pytest.mark.parametrize("block", RUN, ids=str)
def test_the_block_runs(block, stand_ins, capsys):
    from npmrf3d import cli

    if block.lang == "python":
        code = compile(_tiny_python(block.body), str(block), "exec")
        exec(code, {"__name__": "__docs__"})  # noqa: S102 -- the docs' own snippets
        return
    for argv in _commands(block.body):
        code = cli.main(_tiny(argv))
        out = capsys.readouterr()
        assert code in (0, None), (str(block), argv, out.err[-2000:])
    assert os.getcwd() == str(stand_ins)
