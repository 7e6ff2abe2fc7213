"""Study figures and the self-contained HTML report (``npmrf3d report RESULTS_DIR``).

Figures: :mod:`npmrf3d.studies.figures` (re-exported here as :func:`make_figures`).

The report is one HTML file with everything inside it (figures as base64 PNG, no scripts, no
links to the network), so it opens offline in any browser and can be mailed as is. Per study it
shows the question, the declaration (methods and parameters), the scheduler, versions, wall
time, the table of runs (one ``<tr id="row-<study>-<run_id>">`` each, with status, seed,
timings and metrics), the study figures and one preview per run
(``<img id="fig-<study>-<run_id>">``), and every failure with its message.
"""

from __future__ import annotations

import base64
import csv
import html
import json
import math
import pathlib
from datetime import datetime, timezone
from typing import Any

from ..errors import ParameterError
from ..io import atomic_write, check_regular_target
from ..methods import METHODS
from .figures import make_figures  # noqa: F401 (re-exported: report.make_figures)
from .table import as_float, metric_columns, read_results_checked, separations, summarise, unique

__all__ = ["build_report", "find_studies", "make_figures", "write_report"]


# --------------------------------------------------------------------------- report


def find_studies(results_dir) -> list[pathlib.Path]:
    """Study folders under ``results_dir`` (itself if it is one), sorted by name."""
    root = pathlib.Path(results_dir)
    if not root.is_dir():
        raise ParameterError(f"results folder '{root}' does not exist or is not a folder")
    if (root / "results.csv").is_file():
        return [root]
    found = sorted(p for p in root.iterdir() if (p / "results.csv").is_file())
    if not found:
        raise ParameterError(f"no study results in '{root}': expected results.csv in it or in "
                             f"its sub-folders (run 'npmrf3d study NAME --out {root}' first)")
    return found


def _esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _png(path: pathlib.Path) -> str:
    return "data:image/png;base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def _fmt(value: str) -> str:
    x = as_float(value)
    if value in ("", None):
        return ""
    if math.isfinite(x) and not str(value).lstrip("-").isdigit():
        return f"{x:.4g}"
    return str(value)


#: What the study-only algorithms are (the registered methods describe themselves).
_STUDY_ONLY = {"control": "structureless control: voxels drawn independently from the exemplar",
               "real": "a crop of the real volume (ground-truth study)"}


def _params_table(declaration: dict) -> str:
    rows = []
    for m in declaration.get("methods", []):
        params = ", ".join(f"{k}={v}" for k, v in m["params"].items())
        known = METHODS.get(m["algorithm"])
        what = known.description if known is not None else _STUDY_ONLY.get(m["algorithm"], "")
        rows.append(f"<tr><td>{_esc(m['name'])}</td><td title='{_esc(what)}'>{_esc(m['algorithm'])}</td>"
                    f"<td>{_esc(params)}</td></tr>")
    common = ", ".join(f"{k}={v}" for k, v in declaration.get("common", {}).items())
    return ("<table class='params'><tr><th>method</th><th>algorithm</th><th>parameters</th></tr>"
            + "".join(rows) + "</table>"
            + f"<p><b>common (npmrf methods):</b> {_esc(common or 'none')}</p>")


def _study_section(study_dir: pathlib.Path, warn=None) -> str:
    info = {}
    if (study_dir / "study.json").is_file():
        info = json.loads((study_dir / "study.json").read_text(encoding="utf-8"))
    declaration = info.get("study", {})
    name = declaration.get("name", study_dir.name)
    rows = read_results_checked(study_dir / "results.csv", warn)
    mode = info.get("mode", "?")
    scale = declaration.get(mode, {}) if mode in ("quick", "full") else {}
    parts = [f"<section id='study-{_esc(name)}'>",
             f"<h2>{_esc(declaration.get('title', name))}</h2>",
             f"<p class='q'>{_esc(declaration.get('question', ''))}</p>"]
    if declaration.get("notes"):
        parts.append(f"<p>{_esc(declaration['notes'])}</p>")
    counts = info.get("counts", {})
    facts = [
        ("study", name), ("mode", mode),
        ("runs", f"{len(rows)} ({', '.join(f'{k} {v}' for k, v in counts.items())})"),
        ("seeds", ", ".join(unique(r["seed"] for r in rows))),
        ("sizes", ", ".join(unique(r["size"] for r in rows))),
        ("levels", ", ".join(unique(r["levels"] for r in rows))),
        ("exemplar crop", scale.get("crop")),
        ("scheduler", info.get("scheduler", "?")),
        ("workers x numba threads", f"{info.get('workers', '?')} x {info.get('threads') or 'default'}"),
        ("started", info.get("started", "?")), ("finished", info.get("finished", "?")),
        ("wall time", f"{as_float(info.get('wall_seconds')):.1f} s"),
    ]
    for item in info.get("left_out") or ():
        facts.append((f"left out: {item['method']}", f"{item['runs']} runs; {item['reason']}"))
    versions = info.get("versions", {})
    facts.append(("versions", ", ".join(f"{k} {v}" for k, v in versions.items())))
    options = {k: v for k, v in (info.get("options") or {}).items() if v is not None}
    if options:
        facts.append(("options", json.dumps(options)))
    parts.append("<table class='facts'>" + "".join(
        f"<tr><th>{_esc(k)}</th><td>{_esc(v)}</td></tr>" for k, v in facts) + "</table>")
    parts.append("<h3>Methods and parameters</h3>" + _params_table(declaration))

    columns = [c for c in ("run_id", "exemplar", "method", "seed", "size", "levels", "status",
                           "seconds", "train_seconds", "generate_seconds", "wall_seconds", "threads")
               if rows and c in rows[0]]
    metric_cols = [c for c in metric_columns(rows)] + (
        ["largest_value_share"] if rows and "largest_value_share" in rows[0] else [])
    header = "".join(f"<th>{_esc(c.removeprefix('mean_'))}</th>" for c in columns + metric_cols)
    body = []
    for r in rows:
        cls = " class='failed'" if r.get("status") == "failed" else ""
        cells = "".join(f"<td>{_esc(_fmt(r.get(c, '')))}</td>" for c in columns + metric_cols)
        body.append(f"<tr id='row-{_esc(name)}-{_esc(r['run_id'])}' data-run='{_esc(r['run_id'])}'"
                    f"{cls}>{cells}</tr>")
    parts.append("<h3>Runs</h3><p>Metrics are means over the constrained views; lower is "
                 "better. Full per-view values are in results.csv.</p>"
                 f"<table class='runs'><tr>{header}</tr>{''.join(body)}</table>")

    parts.append(_spread_section(rows))

    failures = [r for r in rows if r.get("status") == "failed"]
    if failures:
        items = "".join(f"<li><b>{_esc(r['run_id'])}</b>: <code>{_esc(r.get('error', ''))}</code>"
                        f"</li>" for r in failures)
        parts.append(f"<h3>Failures ({len(failures)})</h3><ul class='failures'>{items}</ul>"
                     "<p>Tracebacks are in each run's error.json.</p>")

    figures = info.get("figures") or sorted(p.name for p in study_dir.glob("*.png"))
    for fig_name in figures:
        path = study_dir / fig_name
        if path.is_file():
            parts.append(f"<figure><img id='study-fig-{_esc(name)}-{_esc(path.stem)}' "
                         f"alt='{_esc(fig_name)}' src='{_png(path)}'>"
                         f"<figcaption>{_esc(fig_name)}</figcaption></figure>")

    parts.append("<h3>Runs one by one</h3><div class='gallery'>")
    for r in rows:
        run_dir = study_dir / r["run_id"]
        preview = run_dir / "preview.png"
        label = f"{r['run_id']} ({r.get('status', '?')})"
        if preview.is_file() and r.get("status") != "failed":
            img = f"<img id='fig-{_esc(name)}-{_esc(r['run_id'])}' alt='{_esc(label)}' src='{_png(preview)}'>"
        else:
            img = (f"<div id='fig-{_esc(name)}-{_esc(r['run_id'])}' class='missing'>no picture: "
                   f"{_esc(r.get('error') or 'run not finished')}</div>")
        parts.append(f"<figure class='run'>{img}<figcaption>{_esc(label)}</figcaption></figure>")
    parts.append("</div></section>")
    return "\n".join(parts)


def _spread_section(rows: list[dict]) -> str:
    """Mean +- standard deviation over seeds per exemplar, metric and method, the best method
    in bold, and whether its lead over the runner-up exceeds the spread (the two standard
    deviations added; "one seed" when the spread is unknown)."""
    summary = summarise(rows)
    if not summary:
        return ""
    methods = unique(r["method"] for r in rows)
    cell = {(r["metric"], r["exemplar"], r["method"]): r for r in summary}
    verdicts = {(v["metric"], v["exemplar"]): v for v in separations(summary)}
    header = "".join(f"<th>{_esc(m)}</th>" for m in methods)
    body = []
    for (metric, exemplar), v in verdicts.items():
        cells = []
        for m in methods:
            r = cell.get((metric, exemplar, m))
            if r is None or not r["n"]:
                cells.append("<td></td>")
                continue
            text = f"{r['mean']:.4g} ± {r['std']:.2g} ({r['n']})"
            cells.append(f"<td><b>{_esc(text)}</b></td>" if m == v["best"] else f"<td>{_esc(text)}</td>")
        verdict = ("one seed: spread unknown" if v["exceeds_spread"] is None else
                   f"{'yes' if v['exceeds_spread'] else 'no'} ({v['difference']:.3g} vs {v['spread']:.3g})")
        if v["runner_up"] is None:
            verdict = "one method"
        body.append(f"<tr><td>{_esc(exemplar)}</td><td>{_esc(metric.removeprefix('mean_'))}</td>"
                    f"{''.join(cells)}<td>{_esc(verdict)}</td></tr>")
    return ("<h3>Across seeds</h3><p>Mean ± standard deviation over seeds (number of seeds); the "
            "lowest mean in bold. The last column says whether the best method's lead over the "
            "runner-up exceeds the spread: the difference of their means against the sum of their "
            "standard deviations.</p>"
            f"<table class='spread'><tr><th>exemplar</th><th>metric</th>{header}"
            f"<th>lead exceeds spread?</th></tr>{''.join(body)}</table>")


_STYLE = """
body { font-family: sans-serif; margin: 1.5em; color: #222; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.85em; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: left; }
tr.failed td { background: #fdd; }
p.q { font-style: italic; }
figure { display: inline-block; margin: 0.5em; vertical-align: top; }
figure img { max-width: 100%; }
figure.run img { width: 420px; }
div.missing { width: 300px; padding: 1em; background: #fee; color: #900; }
section { border-top: 2px solid #888; margin-top: 2em; }
"""


def _checked_section(study_dir: pathlib.Path, warn=None) -> str:
    """:func:`_study_section`, with damaged or foreign files refused as a ParameterError."""
    try:
        return _study_section(study_dir, warn)
    except ParameterError:
        raise
    except (ValueError, KeyError, TypeError, IndexError, AttributeError, UnicodeError, OSError,
            csv.Error) as exc:
        reason = str(exc).splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise ParameterError(
            f"study results in '{study_dir}' cannot be read (results.csv or study.json is damaged "
            f"or was not written by 'npmrf3d study'): {type(exc).__name__}: {reason}") from None


def build_report(results_dir, warn=None) -> str:
    """The HTML text of the report on every study under ``results_dir``; ``warn(line)`` hears
    of every cell of a ``results.csv`` that is not a number (shown as missing)."""
    studies = find_studies(results_dir)
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    toc = "".join(f"<li><a href='#study-{_esc(p.name)}'>{_esc(p.name)}</a></li>" for p in studies)
    sections = "\n".join(_checked_section(p, warn) for p in studies)
    title = "npmrf3d studies" if len(studies) > 1 else f"npmrf3d study {studies[0].name}"
    return (f"<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{_esc(title)}</title><style>{_STYLE}</style></head><body>"
            f"<h1>{_esc(title)}</h1><p>Report written {_esc(created)} from "
            f"{_esc(pathlib.Path(results_dir).absolute())}. Self-contained: every figure is "
            f"embedded.</p><ul class='toc'>{toc}</ul>{sections}</body></html>\n")


def write_report(results_dir, out=None, *, overwrite: bool = False, warn=None) -> pathlib.Path:
    """Write :func:`build_report` to ``out`` (default ``RESULTS_DIR/report.html``).

    An existing ``out`` is refused unless ``overwrite``; ``warn`` as in :func:`build_report`.
    """
    if not str(results_dir).strip():
        raise ParameterError("RESULTS_DIR must name a folder; got an empty string")
    find_studies(results_dir)
    if out is not None and not str(out).strip():
        raise ParameterError("--out must name a file; got an empty string")
    out = pathlib.Path(results_dir) / "report.html" if out is None else pathlib.Path(out)
    if out.is_dir():
        raise ParameterError(f"report file '{out}' is a folder; give a file name")
    check_regular_target(out, "report file")
    if not out.absolute().parent.is_dir():
        raise ParameterError(f"folder of report file '{out}' does not exist")
    if out.exists() and not overwrite:
        raise ParameterError(f"report file '{out}' already exists; pass --overwrite to replace it "
                             f"or choose another --out")
    text = build_report(results_dir, warn)
    return atomic_write(out, lambda tmp: tmp.write_text(text, encoding="utf-8"))
