"""One reference page per command, written from the command's own parser.

Each volume-making command's options come from its configuration's fields
(:mod:`npmrf3d.options`), so a page written from the parser states exactly what ``--help``
states: every option, its default and its meaning, by section, and a runnable example on
bundled data. ``python -m npmrf3d.cli.reference docs/commands`` writes the pages;
``tests/test_reference_pages.py`` checks that the committed pages are what this module writes.
"""

from __future__ import annotations

import argparse
import pathlib
import sys

from ._common import say
from .main import build_parser

__all__ = ["COMMAND_PAGES", "command_page", "write_pages"]

#: The commands with a page, each with a runnable example on bundled data (small sizes, so the
#: example is quick).
COMMAND_PAGES = {
    "synth": "npmrf3d synth bundled:wood --size 32 --out wood",
    "coherent": "npmrf3d coherent bundled:ihc64 --size 32 --out coherent",
    "chen-wang": "npmrf3d chen-wang bundled:ihc64 --size 32 --out cw",
    "kopf": "npmrf3d kopf --size 32 --levels 2 --out npk",
    "volume": "npmrf3d volume bundled:fibres48 --size 64 --out grown",
    "volume-npmrf": "npmrf3d volume-npmrf bundled:fibres48 --size 16 --levels 2 --out vol-npmrf",
    "metrics": "npmrf3d metrics bundled:wood wood/volume.npy --out scores",
    "materials": "npmrf3d materials bundled:phase_bands --size 32 --out bands",
}


def _sub_parser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices[name]


def _help(action: argparse.Action) -> str:
    return (action.help or "").replace("%(default)s", str(action.default))


def _default(action: argparse.Action) -> str:
    text = _help(action)
    if "(default:" in text:
        return text.rsplit("(default:", 1)[1].rstrip(")").strip()
    if action.default is False or action.default is None or action.default is argparse.SUPPRESS:
        return "off" if action.default is False else "none"
    return str(action.default)


def _meaning(action: argparse.Action) -> str:
    text = _help(action).split("(default:", 1)[0].strip()
    return " ".join(text.replace("%%", "%").replace("|", "/").split())


def command_page(name: str, parser: argparse.ArgumentParser | None = None) -> str:
    """The Markdown reference of command ``name``: what it does, an example, and a table per
    section of ``--help`` (option, default, meaning)."""
    if parser is None:
        parser = build_parser()
    sub = _sub_parser(parser, name)
    lines = [f"# `npmrf3d {name}`", "",
             "<!-- written by `python -m npmrf3d.cli.reference docs/commands`; do not edit -->", "",
             " ".join((sub.description or "").split("examples:")[0].split()), "",
             "```bash", COMMAND_PAGES[name], "```", ""]
    for group in sub._action_groups:
        rows = [a for a in group._group_actions if a.help is not argparse.SUPPRESS and a.dest != "help"]
        if not rows:
            continue
        title = "arguments" if group.title in ("positional arguments", "options") else group.title
        lines += [f"## {title}", "", "| option | default | meaning |", "| --- | --- | --- |"]
        for action in rows:
            spelled = max(action.option_strings, key=len) if action.option_strings else action.metavar
            metavar = "" if not action.option_strings or action.nargs == 0 else f" {action.metavar or ''}".rstrip()
            lines.append(f"| `{spelled}{metavar}` | {_default(action)} | {_meaning(action)} |")
        lines.append("")
    return "\n".join(lines)


def write_pages(folder: str | pathlib.Path) -> list[pathlib.Path]:
    """Write every page of :data:`COMMAND_PAGES` into ``folder``; returns the paths."""
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    parser = build_parser()
    paths = []
    for name in COMMAND_PAGES:
        path = folder / f"{name}.md"
        path.write_text(command_page(name, parser), encoding="utf-8")
        paths.append(path)
    return paths


if __name__ == "__main__":  # pragma: no cover - the docs' writer
    for written in write_pages(sys.argv[1] if len(sys.argv) > 1 else "docs/commands"):
        say(str(written))
