"""The product speaks of itself only: no development-process words in the tracked text.

Walks the git-tracked text files of the product (README, docs, the package, benchmarks, studies,
tests, the figures' READMEs and JSON notes, pyproject.toml, CITATION.cff) and the command
line's own text (``info`` and every sub-command's ``--help``), and fails on words that belong to
how the project was made rather than to what it is: numbered stops, rounds or issues,
development seeds, references to the working session, dated changes, figure folders named
after a stop.
"""

from __future__ import annotations

import contextlib
import io
import pathlib
import re
import subprocess

import pytest

from npmrf3d import cli

ROOT = pathlib.Path(__file__).resolve().parents[1]

_MONTHS = ("January|February|March|April|May|June|July|August|September|October|November"
           "|December")

#: One alternative per kind of process word. ``stop`` is followed by a space or hyphen and a
#: whole number that is not a decimal (``--stop 0.95`` and the cooling study's ``stop95`` are
#: the product's own); a date counts only with its day (a data snapshot's "December 2026" is
#: provenance, one with its day a change log).
PROCESS_WORDS = re.compile("|".join((
    r"\b[Ss]top[- ]\d+(?![.\d])",
    r"\bstop\d+/",
    r"\b[Ii]ssue #?\d+\b",
    r"\b[Tt]he issue(?:'s)?\b",
    r"\bseed ?00\d\b",
    r"\b[Tt]his (?:session|stop|round)\b",
    r"\b(?:an|the) earlier (?:round|stop|session)s?\b",
    r"\b[Rr]ound \d+\b",
    r"\b[Nn]ew this (?:stop|round|session)\b",
    r"\b[Ss]ince this (?:stop|round|session)\b",
    r"\b[Bb]etween stops\b",
    r"\bheldout\d+\b",
    rf"\b\d{{1,2}} (?:{_MONTHS}) 20\d\d\b",
    r"\b(?:HEAD|commit) \(?[0-9a-f]{7,40}\b",
)))

THIS_FILE = pathlib.Path(__file__).resolve()


def _product_files() -> list[pathlib.Path]:
    """The git-tracked text files the product is made of."""
    out = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True)
    names = [n for n in out.stdout.decode().split("\0") if n]
    keep = []
    for name in names:
        top = name.split("/", 1)[0]
        if name in ("README.md", "pyproject.toml", "CITATION.cff"):
            keep.append(name)
        elif top in ("docs", "npmrf3d", "benchmarks", "studies", "tests"):
            if name.endswith((".py", ".md", ".json", ".toml", ".txt", ".cff", ".cfg", ".yaml")):
                keep.append(name)
        elif top == "figures" and name.endswith((".md", ".json")):
            keep.append(name)
    return [ROOT / n for n in keep if (ROOT / n).is_file()]


def offending_lines(text: str, where: str) -> list[str]:
    """``where:line: text`` for every line of ``text`` holding a process word."""
    return [f"{where}:{i}: {line.strip()[:160]}"
            for i, line in enumerate(text.splitlines(), 1) if PROCESS_WORDS.search(line)]


def _text_of(path: pathlib.Path) -> str:
    text = path.read_text(encoding="utf-8", errors="replace")
    if path.resolve() == THIS_FILE:
        # this module's own patterns and planted examples are not product text
        text = text.split("# -- planted examples --", 1)[0]
        text = re.sub(r"PROCESS_WORDS = re\.compile\(.*?\)\)\)", "", text, flags=re.DOTALL)
    return text


def test_the_tracked_text_holds_no_process_words():
    files = _product_files()
    assert any(p.name == "README.md" for p in files) and len(files) > 100, len(files)
    bad = [hit for p in files for hit in offending_lines(_text_of(p), str(p.relative_to(ROOT)))]
    assert not bad, "process words in the product:\n" + "\n".join(bad)


def _help_texts() -> dict[str, str]:
    """``npmrf3d info`` and ``npmrf3d [SUB ...] --help`` of every command, as the user sees them."""
    names = ["synth", "npmrf", "coherent", "kopf", "chen-wang", "baseline", "baseline kopf",
             "baseline chen-wang", "volume", "volume-lh", "volume-npmrf", "npmrf-3d", "neural",
             "neural train", "neural generate", "metrics", "study", "report", "info"]
    texts = {}
    for name in [""] + names:
        argv = name.split() + ["--help"]
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(io.StringIO()):
            try:
                cli.main(argv)
            except SystemExit:
                pass
        texts[" ".join(argv)] = buf.getvalue()
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        cli.main(["info"])
    texts["info"] = buf.getvalue()
    return texts


def test_info_and_every_help_text_read_as_a_product():
    texts = _help_texts()
    assert "usage:" in texts["synth --help"] and "bundled:gravel64" in texts["info"]
    bad = [hit for where, text in texts.items() for hit in offending_lines(text, where)]
    assert not bad, "process words in the command line's text:\n" + "\n".join(bad)


# -- planted examples --

#: Process words the matcher must find, each written with a ``|`` inside a word so that this file
#: itself holds none; :func:`_planted` removes it.
PLANTED = (
    "as measured at st|op 30, the gain", "the st|op-26 rule", "figures/volume3d/st|op33/x.png",
    "fixed in iss|ue 12", "(iss|ue #7)", "the iss|ue's bar", "alias se|ed002 of gravel",
    "se|ed 003 was used", "redrawn this sess|ion", "an earl|ier round chose it", "in rou|nd 2",
    "new this st|op", "since this st|op", "between st|ops", "figures/volume3d/held|out29/",
    "measured on 2 Dece|mber 2026", "the defaults of HE|AD (6aa05c6)",
)


def _planted(line: str) -> str:
    return line.replace("|", "")


@pytest.mark.parametrize("line", [_planted(p) for p in PLANTED])
def test_the_matcher_finds_a_planted_process_word(line):
    assert offending_lines(f"ok\n{line}\n", "planted.md") == [f"planted.md:2: {line}"]


@pytest.mark.parametrize("line", [
    "--stop 0.95 stops a level", "the cooling study's xi-1-stop95 run", "seed 7, 8 and 9",
    "the newest snapshot (December 2026)", "np.round(x, 3)", "a round pore", "the heldout set",
    "stop at 95 %", "issues a warning",
])
def test_the_matcher_leaves_product_words_alone(line):
    assert offending_lines(line, "fine.md") == []
