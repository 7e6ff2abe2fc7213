"""The command line's contract for bad input, checked once for every test that needs it: exit
code 2, one line ``npmrf3d...: error: ...`` on stderr, no traceback, nothing new on disk."""

from __future__ import annotations

import pathlib

from npmrf3d import cli


#: Every command that makes a volume, with a small window where it takes one (add --size and
#: --levels for a quick run).
COMMANDS = {
    "synth": ["synth", "bundled:gravel64", "--window", "3"],
    "kopf": ["kopf", "bundled:gravel64"],
    "chen-wang": ["chen-wang", "bundled:gravel64", "--window", "3"],
    "coherent": ["coherent", "bundled:gravel64", "--window", "3"],
    "volume": ["volume", "bundled:fibres48"],
    "volume-npmrf": ["volume-npmrf", "bundled:fibres48"],
}


def listing(root: pathlib.Path) -> set[str]:
    """Every path below ``root``, relative to it."""
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def one_line_error(argv, root: pathlib.Path, capsys) -> str:
    """Run ``argv``: exit 2, one line ``npmrf3d...: error: ...`` on stderr, no traceback, no
    usage block, nothing new below ``root``; return the line."""
    before = listing(root)
    code = cli.main(list(argv))
    captured = capsys.readouterr()
    lines = [line for line in captured.err.splitlines() if line.strip()]
    assert code == 2, (argv, code, captured.err)
    assert len(lines) == 1, (argv, captured.err)
    assert lines[0].startswith("npmrf3d") and ": error: " in lines[0], lines
    assert "Traceback" not in captured.err and "usage:" not in captured.err
    assert listing(root) == before, (argv, listing(root) - before)
    return lines[0]


def refused_naming(argv, root: pathlib.Path, capsys, words=(), not_words=()) -> str:
    """:func:`one_line_error`, whose line holds every one of ``words`` and none of
    ``not_words``; return the line."""
    line = one_line_error(argv, root, capsys)
    for word in words:
        assert word in line, (word, line)
    for word in not_words:
        assert word not in line, (word, line)
    return line
