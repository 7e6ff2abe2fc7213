"""The documentation is a reference: its links resolve, the code it names exists, and the
defaults it writes are the defaults of the parser and the configurations.

Pages: README.md, docs/*.md and studies/README.md. Checked:

* every relative link ``[text](target)`` names a file that exists, and its ``#anchor`` a heading
  of that page;
* every source path written in backquotes (``npmrf3d/model/regions.py``, ``relax/icm.py``,
  ``benchmarks/bench_icm.py``) names a file or folder of the repository (a shorter path must be
  the end of one), and every file of the architecture page's tree exists under ``npmrf3d/``;
* every dotted name ``npmrf3d.x.y`` imports (a module, or an attribute of one);
* every default written as "`--option` (default X)" or in a table whose columns are
  ``option | default`` equals the parser's default of the page's command, and for the options
  whose default depends on the support (``--xi``, ``--sampler``) each "`value` with `support`"
  pair equals the code's :data:`~npmrf3d.methods.npmrf_options.BY_SUPPORT`;
* the defaults the pages write in prose for the ``coherent`` and ``chen-wang`` commands and for
  ``--variant``, against their configurations.

Each check is a pure function of a page's text, so a planted contradiction fails it
(:func:`test_a_planted_contradiction_is_caught`).
"""

from __future__ import annotations

import argparse
import importlib
import pathlib
import re

import pytest

from npmrf3d.cli import build_parser
from npmrf3d.config import VARIANTS
from npmrf3d.methods.chen_wang import ChenWangConfig
from npmrf3d.methods.npmrf_coherent import CoherentConfig
from npmrf3d.methods.npmrf_options import BY_SUPPORT

ROOT = pathlib.Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "studies" / "README.md"]
#: Where the source paths the pages name may live.
SOURCE_DIRS = ("npmrf3d", "benchmarks", "studies", "tests", "tests_neural", "figures", ".ci")

_LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
_CODE = re.compile(r"`([^`\n]+)`")
_PATH = re.compile(r"^(?:[\w.-]+/)*[\w.-]+\.py$|^(?:npmrf3d|benchmarks|studies|tests)/[\w./-]*$")
_DOTTED = re.compile(r"\bnpmrf3d(?:\.[A-Za-z_]\w*)+")
_FENCE = re.compile(r"^```.*?^```", re.MULTILINE | re.DOTALL)


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    text = re.sub(r"[`*]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(page: pathlib.Path) -> set[str]:
    text = _FENCE.sub("", page.read_text(encoding="utf-8"))
    return {_slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", text, re.MULTILINE)}


def broken_links(page: pathlib.Path, text: str) -> list[str]:
    """The relative links of ``text`` (the text of ``page``) that lead nowhere."""
    bad = []
    for m in _LINK.finditer(_FENCE.sub("", text)):
        target = m.group(1) or m.group(2)
        if re.match(r"^[a-z]+:", target):
            continue
        name, _, anchor = target.partition("#")
        where = (page.parent / name).resolve() if name else page
        if not where.exists():
            bad.append(target)
        elif anchor and where.suffix == ".md" and anchor not in _anchors(where):
            bad.append(target)
    return bad


def _repository_files() -> list[str]:
    out = []
    for folder in SOURCE_DIRS:
        base = ROOT / folder
        if base.is_dir():
            out += [p.relative_to(ROOT).as_posix() for p in base.rglob("*") if "__pycache__" not in p.parts]
    return out


FILES = _repository_files()


def _exists(path: str) -> bool:
    path = path.rstrip("/")
    return (ROOT / path).exists() or any(f == path or f.endswith("/" + path) for f in FILES)


def missing_paths(text: str) -> list[str]:
    """The source paths written in backquotes in ``text`` that no file of the repository has."""
    bad = []
    for m in _CODE.finditer(text):
        token = m.group(1).strip()
        for word in re.split(r"[\s,:()]+", token):
            word = word.rstrip(".")
            if _PATH.match(word) and "*" not in word and "<" not in word and not _exists(word):
                bad.append(word)
    return bad


def missing_tree_files(text: str) -> list[str]:
    """The files and folders of a ``text`` fence laid out as a tree under ``npmrf3d/``."""
    bad = []
    for block in re.findall(r"^```text\n(npmrf3d/\n.*?)^```", text, re.MULTILINE | re.DOTALL):
        stack: list[tuple[int, str]] = []
        for line in block.splitlines()[1:]:
            m = re.match(r"^([│├└─\s]*)([\w.-]+/?)((?:,\s*[\w.-]+/?)*)", line)
            if not m or not m.group(2).strip() or not re.search(r"[├└]", m.group(1)):
                continue
            depth = len(m.group(1))
            stack = [(d, n) for d, n in stack if d < depth]
            parent = "/".join(n.rstrip("/") for _, n in stack)
            names = [m.group(2)] + [n.strip() for n in m.group(3).split(",") if n.strip()]
            for name in names:
                path = "/".join(filter(None, ["npmrf3d", parent, name.rstrip("/")]))
                if not (ROOT / path).exists():
                    bad.append(path)
            if m.group(2).endswith("/"):
                stack.append((depth, m.group(2)))
    return bad


def unresolved_names(text: str) -> list[str]:
    """The dotted names ``npmrf3d.x.y`` of ``text`` that are neither a module nor an attribute."""
    bad = []
    for name in sorted(set(_DOTTED.findall(text))):
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            try:
                for attr in parts[cut:]:
                    obj = getattr(obj, attr)
            except AttributeError:
                bad.append(name)
            break
        else:
            bad.append(name)
    return bad


# ----------------------------------------------------------------------------- defaults


def _options(*path) -> dict[str, argparse.Action]:
    """The options of ``npmrf3d PATH...`` by their spellings."""
    parser = build_parser()
    for name in path:
        parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[name]
    return {opt: a for a in parser._actions for opt in a.option_strings}


def _spell(value) -> str:
    if isinstance(value, (tuple, list)):
        return ",".join(str(v) for v in value)
    return str(value)


def _same(written: str, value) -> bool:
    """Whether a default written in the docs (``64``, `` `ML_H2b` ``, ``8, 6, 4``) is ``value``."""
    words = re.sub(r"[`*]", "", written).strip()
    first = re.split(r"\s+(?:with|for|where|=|\()", words, maxsplit=1)[0].strip().rstrip(".;")
    if value is None or value is False:
        return first.lower() in ("none", "off", "")
    if value is True:
        return first.lower() in ("on", "true")
    compact = first.replace(" ", "")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        try:
            return float(compact) == float(value)
        except ValueError:
            return False
    return compact == _spell(value).replace(" ", "")


def by_support_errors(option: str, written: str) -> list[str]:
    """For ``--xi``/``--sampler``: the "`value` with `support`" pairs that are not the code's."""
    field = option.lstrip("-").replace("-", "_")
    bad = []
    for value, support in re.findall(r"`?([\w.-]+)`?\s+(?:with|for)\s+(?:support\s+)?`?(full|coherent)`?",
                                     written):
        expected = BY_SUPPORT[field][support]
        if not _same(value, expected):
            bad.append(f"{option}: {value} with {support} (the code: {expected})")
    return bad


def default_errors(text: str, command: tuple[str, ...]) -> list[str]:
    """Defaults written in ``text`` that differ from those of ``npmrf3d COMMAND``."""
    options = _options(*command)
    bad = []
    rows = re.findall(r"^\|\s*((?:`--[\w-]+`(?:\s*(?:/|,)\s*)?)+)[^|]*\|\s*([^|]+?)\s*\|", text, re.MULTILINE)
    prose = re.findall(r"`(--[\w-]+)(?:\s[^`]*)?`\s*\(default:?\s+([^)]+)\)", text)
    pairs = []
    for names, cell in rows:   # a row of N options gives N defaults, split by "/" or ","
        opts = re.findall(r"--[\w-]+", names)
        parts = [cell]
        for separator in (r"\s+/\s+", r",\s+"):
            if len(parts) != len(opts):
                parts = re.split(separator, cell)
        if len(parts) != len(opts):
            parts = [cell] * len(opts)
        pairs += list(zip(opts, parts))
    for opt, written in pairs + prose:
        if opt not in options:
            bad.append(f"{opt}: no such option of npmrf3d {' '.join(command)}")
            continue
        field = opt.lstrip("-").replace("-", "_")
        if field in BY_SUPPORT:
            bad += by_support_errors(opt, written)
            continue
        default = options[opt].default
        if default is None or default is False:
            continue  # a default the run decides (written out in prose, checked where it is)
        if not _same(written, default):
            bad.append(f"{opt}: written {written.strip()!r}, the parser's default is {default!r}")
    return bad


def _section(text: str, heading: str) -> str:
    start = text.index(heading)
    end = text.find("\n## ", start + len(heading))
    return text[start:] if end < 0 else text[start:end]


def _text(name: str) -> str:
    return (ROOT / name).read_text(encoding="utf-8")


# ----------------------------------------------------------------------------- tests


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_resolve(page):
    assert broken_links(page, page.read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_named_source_files_exist(page):
    text = page.read_text(encoding="utf-8")
    assert missing_paths(text) == []
    assert missing_tree_files(text) == []


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_dotted_names_resolve(page):
    assert unresolved_names(page.read_text(encoding="utf-8")) == []


def test_synth_defaults_in_the_cli_page():
    assert default_errors(_section(_text("docs/cli.md"), "## `synth` options"), ("synth",)) == []


def test_prose_defaults_of_the_option_pages():
    for page, command in (("docs/segmented.md", ("synth",)), ("docs/chen_wang.md", ("chen-wang",))):
        assert default_errors(_text(page), command) == [], page


def test_sampler_defaults_are_written_per_command():
    """``synth`` anneals coherent candidates by Metropolis and the full support by heat-bath;
    the ``coherent`` command by heat-bath (its own configuration)."""
    assert BY_SUPPORT["sampler"] == {"full": "heat-bath", "coherent": "metropolis"}
    assert CoherentConfig.sampler == "heat-bath"
    model = _text("docs/model.md")
    assert "`coherent` command's default" in model and "`synth`'s default" in model
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for sentence in re.findall(r"[^.]*\b(?:heat-bath|Metropolis|metropolis)\b[^.]*default[^.]*\.", text):
            flat = " ".join(sentence.split())
            if "synth" in flat and "coherent" in flat and "heat-bath" in flat and "metropolis" not in flat.lower():
                pytest.fail(f"{page.name}: {flat!r} gives heat-bath as synth's coherent default")


def test_chen_wang_windows_and_variants():
    windows = ", ".join(map(str, ChenWangConfig.window))
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for written in re.findall(r"default\s+`?\(?(\d,\s*\d,\s*\d)", text):
            if "chen" in page.name or "Chen" in text[max(0, text.find(written) - 300):text.find(written)]:
                assert written.replace(" ", "") == windows.replace(" ", ""), (page.name, written)
    cli = _text("docs/cli.md")
    for name, (support, preset) in VARIANTS.items():
        if support == "full":
            assert re.search(rf"`{name}`[^|]*`--support full --preset {preset}`|{name}[^|]*= `--support full --preset {preset}`"
                             rf"|`--support full --preset {preset}`, also `{name}`", cli), name


def test_the_bundled_volume_is_addressable():
    import npmrf3d
    from npmrf3d.model.exemplar import exemplar_source
    from npmrf3d.model.exemplar3d import load_volume_exemplar

    assert "fibres48" in npmrf3d.data.volumes() and "fibres48" not in npmrf3d.data.available()
    path, record = exemplar_source("bundled:fibres48")
    assert record == "bundled:fibres48"
    assert load_volume_exemplar(path).shape == (48, 48, 48, 1)
    assert "fibres48.npy" in _text("npmrf3d/data/SOURCES.md")


def test_a_planted_contradiction_is_caught(tmp_path):
    """Each check fails on a page that contradicts the code."""
    page = tmp_path / "page.md"
    text = ("See [cli](missing.md) and [cli](cli.md#no-such-heading); `npmrf3d/model/nowhere.py`, "
            "`npmrf3d.model.nowhere`.\n\n# Title\n")
    page.write_text(text)
    (tmp_path / "cli.md").write_text("# Command line\n")
    assert broken_links(page, text) == ["missing.md", "cli.md#no-such-heading"]
    assert missing_paths(text) == ["npmrf3d/model/nowhere.py"]
    assert unresolved_names(text) == ["npmrf3d.model.nowhere"]
    tree = "```text\nnpmrf3d/\n├── model/\n│   ├── pyramid.py\n│   └── synthesis.py\n```\n"
    assert missing_tree_files(tree) == ["npmrf3d/model/synthesis.py"]
    table = ("| option | default | meaning |\n| --- | --- | --- |\n| `--window` | 9 | w |\n"
             "| `--sampler` | `metropolis` with `full`, `metropolis` with `coherent` | s |\n")
    assert len(default_errors(table, ("synth",))) == 2
    assert default_errors("`--window W` (default 9)", ("synth",)) != []
    assert default_errors("`--window W` (default 7)", ("synth",)) == []
    assert by_support_errors("--xi", "-3 with `full`, -1 with `coherent`") == []
