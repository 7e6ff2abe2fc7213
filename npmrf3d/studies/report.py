"""Study figures and the self-contained HTML report (``npmrf3d report RESULTS_DIR``).

Figures (written by :func:`make_figures` into the study folder, each with its numbers):

* ``metrics.png`` / ``metrics_summary.csv``: every metric of ``results.csv`` (``mean_*``
  columns), one panel per metric, exemplars on the x axis, one bar per method (mean over seeds,
  error bar = standard deviation when there are several seeds);
* ``slices.png``: the middle slice of the first constrained view of each method's first run
  (seed and size), one row per exemplar, the exemplar first;
* ``temperature.png`` / ``temperature.csv`` (studies that ask for it): global temperature
  after each sweep, levels one after the other;
* ``two_point.png`` / ``two_point.csv`` (ground truth): two-point correlation along each axis,
  the real volume dashed.

The report is one HTML file with everything inside it (figures as base64 PNG, no scripts, no
links to the network), so it opens offline in any browser and can be mailed as is. Per study it
shows the question, the declaration (methods and parameters), the scheduler, versions, wall
time, the table of runs (one ``<tr id="row-<study>-<run_id>">`` each, with status, seed,
timings and metrics), the study figures and one preview per run
(``<img id="fig-<study>-<run_id>">``), and every failure with its message.
"""

from __future__ import annotations

import base64
import html
import json
import math
import pathlib
from collections import defaultdict
from datetime import datetime, timezone
from typing import Any

import numpy as np

from npmrf3d.errors import ParameterError

__all__ = ["build_report", "find_studies", "make_figures", "write_report"]

_MAX_SLICE_ROWS = 16


# --------------------------------------------------------------------------- figures


def _float(value) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _metric_columns(rows: list[dict]) -> list[str]:
    names = []
    for row in rows:
        for key in row:
            if key.startswith("mean_") and key not in names:
                names.append(key)
    extra = [k for k in ("two_point_l2", "fraction_l1") if any(k in r for r in rows)]
    return names + extra


def _unique(values) -> list:
    out = []
    for v in values:
        if v not in out:
            out.append(v)
    return out


def _metrics_figure(study_dir, rows):
    from matplotlib.figure import Figure

    from npmrf3d.plotting import save_figure

    from .runner import _write_csv

    columns = _metric_columns(rows)
    if not columns:
        return []
    exemplars = _unique(r["exemplar"] for r in rows)
    methods = _unique(r["method"] for r in rows)
    values = defaultdict(list)
    for r in rows:
        if r["status"] == "failed":
            continue
        for c in columns:
            x = _float(r.get(c))
            if math.isfinite(x):
                values[(c, r["exemplar"], r["method"])].append(x)
    summary = []
    for c in columns:
        for e in exemplars:
            for m in methods:
                xs = values.get((c, e, m), [])
                summary.append({"metric": c, "exemplar": e, "method": m, "n": len(xs),
                                "mean": float(np.mean(xs)) if xs else math.nan,
                                "std": float(np.std(xs)) if xs else math.nan})
    _write_csv(study_dir / "metrics_summary.csv", summary)
    fig = Figure(figsize=(max(6.0, 0.5 * len(exemplars) * len(methods) + 2), 2.6 * len(columns)),
                 layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(columns), 1, squeeze=False)[:, 0])
    width = 0.8 / max(1, len(methods))
    x = np.arange(len(exemplars))
    lookup = {(s["metric"], s["exemplar"], s["method"]): s for s in summary}
    for ax, c in zip(axes, columns):
        for i, m in enumerate(methods):
            means = [lookup[(c, e, m)]["mean"] for e in exemplars]
            stds = [lookup[(c, e, m)]["std"] if lookup[(c, e, m)]["n"] > 1 else 0.0
                    for e in exemplars]
            ax.bar(x + (i - (len(methods) - 1) / 2) * width, np.nan_to_num(means), width,
                   yerr=stds, label=m, capsize=2)
        ax.set_ylabel(c.removeprefix("mean_"))
        ax.set_xticks(x, exemplars, rotation=30 if len(exemplars) > 4 else 0, ha="right"
                      if len(exemplars) > 4 else "center")
        ax.grid(axis="y", alpha=0.3)
    fig.legend(*axes[0].get_legend_handles_labels(), loc="outside upper center",
               fontsize="small", ncols=min(len(methods), 5),
               title="metrics (lower is better), mean over seeds")
    return [save_figure(fig, study_dir / "metrics.png")]


def _middle_slice(volume: np.ndarray, view: str) -> np.ndarray:
    from npmrf3d.metrics import view_slices

    slices = view_slices(volume, view)
    return slices[len(slices) // 2]


def _slices_figure(study, study_dir, specs, rows):
    from matplotlib.figure import Figure

    from npmrf3d.plotting import save_figure

    status = {r["run_id"]: r["status"] for r in rows}
    exemplars = _unique(s.exemplar for s in specs)[:_MAX_SLICE_ROWS]
    methods = _unique(s.method for s in specs)
    first = {}
    for s in specs:
        first.setdefault((s.exemplar, s.method), s)
    fig = Figure(figsize=(1.6 * (len(methods) + 1), 1.7 * len(exemplars) + 0.3),
                 layout="constrained")
    axes = fig.subplots(len(exemplars), len(methods) + 1, squeeze=False)
    for i, e in enumerate(exemplars):
        row_specs = [first[(e, m)] for m in methods if (e, m) in first]
        exemplar_image = _exemplar_image(row_specs[0]) if row_specs else None
        # one value range per row (the exemplar's): a dark volume must look dark, not be
        # stretched to full contrast panel by panel
        lo, hi = ((float(np.min(exemplar_image)), float(np.max(exemplar_image)))
                  if exemplar_image is not None else (None, None))
        for j, m in enumerate(methods):
            ax = axes[i, j + 1]
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                ax.set_title(m, fontsize="small")
            spec = first.get((e, m))
            path = None if spec is None else study_dir / spec.run_id / "volume.npy"
            if spec is None or status.get(spec.run_id) == "failed" or not path.is_file():
                ax.text(0.5, 0.5, "failed" if spec is not None else "-", ha="center",
                        va="center", transform=ax.transAxes, color="red")
                continue
            _show_in_range(ax, _middle_slice(np.load(path), spec.views[0]), lo, hi)
        ax = axes[i, 0]
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_ylabel(e, fontsize="small")
        if i == 0:
            ax.set_title("exemplar", fontsize="small")
        if exemplar_image is not None:
            _show_in_range(ax, exemplar_image, lo, hi)
    return [save_figure(fig, study_dir / "slices.png")]


def _show_in_range(ax, image, lo, hi):
    """imshow ``image`` (H, W, C) with the value range ``[lo, hi]`` (grey or RGB)."""
    from npmrf3d.plotting import to_display

    data = to_display(image, vmin=lo, vmax=hi)
    if data.ndim == 2:
        ax.imshow(data, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
    else:
        ax.imshow(data, interpolation="nearest")


def _exemplar_image(spec):
    try:
        if spec.reference is not None:
            from . import groundtruth

            real = groundtruth.load_reference(spec.reference)
            return groundtruth.exemplar_slice(real, spec.slice_axis, spec.slice_index)
        from .catalog import load_exemplar

        return load_exemplar(spec.exemplar, spec.crop)
    except Exception:  # the exemplar may be gone (e.g. a report on another machine)
        return None


def _run_json(study_dir, spec, name="run.json"):
    path = study_dir / spec.run_id / name
    if not path.is_file():
        return None
    return json.loads(path.read_text(encoding="utf-8"))


def _temperature_figure(study_dir, specs, rows):
    from matplotlib.figure import Figure

    from npmrf3d.plotting import save_figure

    from .runner import _write_csv

    done = {r["run_id"] for r in rows if r["status"] != "failed"}
    exemplars = _unique(s.exemplar for s in specs)
    table, curves = [], defaultdict(list)
    for s in specs:
        record = _run_json(study_dir, s) if s.run_id in done else None
        history = (record or {}).get("history") or []
        xs, ys, sweep = [], [], 0
        for level_index, level in enumerate(history):
            for k, t in enumerate(level):
                table.append({"run_id": s.run_id, "exemplar": s.exemplar, "method": s.method,
                              "seed": s.seed, "level": level_index, "sweep": k, "temperature": t})
                xs.append(sweep + k)
                ys.append(t)
            sweep += len(level)
        if xs:
            curves[s.exemplar].append((s.method, s.seed, xs, ys))
    if not table:
        return []
    _write_csv(study_dir / "temperature.csv", table)
    fig = Figure(figsize=(5.0 * len(exemplars), 3.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(exemplars), squeeze=False)[0])
    for ax, e in zip(axes, exemplars):
        for method, seed, xs, ys in curves.get(e, []):
            ax.plot(xs, ys, marker=".", label=f"{method} s{seed}")
        ax.set_title(e)
        ax.set_xlabel("sweep (levels one after the other, coarse first)")
        ax.set_ylabel("global temperature")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    return [save_figure(fig, study_dir / "temperature.png")]


def _two_point_figure(study_dir, specs, rows):
    from matplotlib.figure import Figure

    from npmrf3d.plotting import save_figure

    from .runner import _write_csv

    done = {r["run_id"] for r in rows if r["status"] != "failed"}
    table, lines, real = [], [], None
    seen = set()
    for s in specs:
        if s.run_id not in done or s.method in seen:
            continue
        measured = _run_json(study_dir, s, "metrics.json")
        truth = (measured or {}).get("groundtruth")
        if not truth:
            continue
        seen.add(s.method)
        lines.append((s.method, truth["two_point"]))
        real = real or truth["two_point_real"]
    if not lines:
        return []
    axes_names = sorted(real)
    for name, curves in [("real volume", real), *lines]:
        for axis in axes_names:
            for p, curve in enumerate(curves[axis]):
                for lag, value in enumerate(curve):
                    table.append({"method": name, "axis": axis, "curve": p, "lag": lag,
                                  "value": value})
    _write_csv(study_dir / "two_point.csv", table)
    fig = Figure(figsize=(13.0, 3.6), layout="constrained")
    axes = fig.subplots(1, len(axes_names))
    for ax, axis in zip(np.atleast_1d(axes), axes_names):
        for p, curve in enumerate(real[axis]):
            ax.plot(curve, "k--", lw=2, label="real volume (whole)" if p == 0 else None)
        for method, curves in lines:
            for p, curve in enumerate(curves[axis]):
                ax.plot(curve, label=method if p == 0 else None)
        ax.set_title(f"two-point correlation along {axis}")
        ax.set_xlabel("lag (voxels)")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize="small")
    return [save_figure(fig, study_dir / "two_point.png")]


def make_figures(study, study_dir, specs, rows) -> list[pathlib.Path]:
    """Write the study's figures and their numbers (see the module docstring)."""
    study_dir = pathlib.Path(study_dir)
    out = _metrics_figure(study_dir, rows)
    out += _slices_figure(study, study_dir, specs, rows)
    if "temperature" in study.figures:
        out += _temperature_figure(study_dir, specs, rows)
    if "two_point" in study.figures:
        out += _two_point_figure(study_dir, specs, rows)
    return out


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
    x = _float(value)
    if value in ("", None):
        return ""
    if math.isfinite(x) and not str(value).lstrip("-").isdigit():
        return f"{x:.4g}"
    return str(value)


def _params_table(declaration: dict) -> str:
    rows = []
    for m in declaration.get("methods", []):
        params = ", ".join(f"{k}={v}" for k, v in m["params"].items())
        rows.append(f"<tr><td>{_esc(m['name'])}</td><td>{_esc(m['algorithm'])}</td>"
                    f"<td>{_esc(params)}</td></tr>")
    common = ", ".join(f"{k}={v}" for k, v in declaration.get("common", {}).items())
    return ("<table class='params'><tr><th>method</th><th>algorithm</th><th>parameters</th></tr>"
            + "".join(rows) + "</table>"
            + f"<p><b>common (npmrf methods):</b> {_esc(common or 'none')}</p>")


def _study_section(study_dir: pathlib.Path) -> str:
    from .runner import read_results

    info = {}
    if (study_dir / "study.json").is_file():
        info = json.loads((study_dir / "study.json").read_text(encoding="utf-8"))
    declaration = info.get("study", {})
    name = declaration.get("name", study_dir.name)
    rows = read_results(study_dir / "results.csv")
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
        ("seeds", ", ".join(_unique(r["seed"] for r in rows))),
        ("sizes", ", ".join(_unique(r["size"] for r in rows))),
        ("levels", ", ".join(_unique(r["levels"] for r in rows))),
        ("exemplar crop", scale.get("crop")),
        ("scheduler", info.get("scheduler", "?")),
        ("workers x numba threads", f"{info.get('workers', '?')} x {info.get('threads') or 'default'}"),
        ("started", info.get("started", "?")), ("finished", info.get("finished", "?")),
        ("wall time", f"{_float(info.get('wall_seconds')):.1f} s"),
    ]
    versions = info.get("versions", {})
    facts.append(("versions", ", ".join(f"{k} {v}" for k, v in versions.items())))
    options = {k: v for k, v in (info.get("options") or {}).items() if v is not None}
    if options:
        facts.append(("options", json.dumps(options)))
    parts.append("<table class='facts'>" + "".join(
        f"<tr><th>{_esc(k)}</th><td>{_esc(v)}</td></tr>" for k, v in facts) + "</table>")
    parts.append("<h3>Methods and parameters</h3>" + _params_table(declaration))

    columns = [c for c in ("run_id", "exemplar", "method", "seed", "size", "levels", "status",
                           "seconds", "wall_seconds", "threads") if rows and c in rows[0]]
    metric_cols = [c for c in _metric_columns(rows)] + (
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


def build_report(results_dir) -> str:
    """The HTML text of the report on every study under ``results_dir``."""
    studies = find_studies(results_dir)
    created = datetime.now(timezone.utc).isoformat(timespec="seconds")
    toc = "".join(f"<li><a href='#study-{_esc(p.name)}'>{_esc(p.name)}</a></li>" for p in studies)
    sections = "\n".join(_study_section(p) for p in studies)
    title = "npmrf3d studies" if len(studies) > 1 else f"npmrf3d study {studies[0].name}"
    return (f"<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{_esc(title)}</title><style>{_STYLE}</style></head><body>"
            f"<h1>{_esc(title)}</h1><p>Report written {_esc(created)} from "
            f"{_esc(pathlib.Path(results_dir).absolute())}. Self-contained: every figure is "
            f"embedded.</p><ul class='toc'>{toc}</ul>{sections}</body></html>\n")


def write_report(results_dir, out=None) -> pathlib.Path:
    """Write :func:`build_report` to ``out`` (default ``RESULTS_DIR/report.html``)."""
    from npmrf3d.io import atomic_write

    text = build_report(results_dir)
    out = pathlib.Path(results_dir) / "report.html" if out is None else pathlib.Path(out)
    if out.is_dir():
        raise ParameterError(f"report file '{out}' is a folder; give a file name")
    if not out.absolute().parent.is_dir():
        raise ParameterError(f"folder of report file '{out}' does not exist")
    return atomic_write(out, lambda tmp: tmp.write_text(text, encoding="utf-8"))
