"""Study figures, each written with the numbers behind it.

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
"""

from __future__ import annotations

import json
import pathlib
from collections import defaultdict

import numpy as np
from matplotlib.figure import Figure

from ..analysis.metrics import view_slices
from ..io import read_volume
from ..model.exemplar import named_exemplar
from ..plotting import save_figure, to_display
from .groundtruth import exemplar_slices
from .table import metric_columns, summarise, unique, write_csv

__all__ = ["make_figures"]

_MAX_SLICE_ROWS = 16


def _metrics_figure(study_dir, rows):

    columns = metric_columns(rows)
    if not columns:
        return []
    exemplars = unique(r["exemplar"] for r in rows)
    methods = unique(r["method"] for r in rows)
    summary = summarise(rows)
    write_csv(study_dir / "metrics_summary.csv", summary)
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
    slices = view_slices(volume, view)
    return slices[len(slices) // 2]


def _slices_figure(study, study_dir, specs, rows):
    status = {r["run_id"]: r["status"] for r in rows}
    exemplars = unique(s.exemplar for s in specs)[:_MAX_SLICE_ROWS]
    methods = unique(s.method for s in specs)
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
    data = to_display(image, vmin=lo, vmax=hi)
    if data.ndim == 2:
        ax.imshow(data, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
    else:
        ax.imshow(data, interpolation="nearest")


def _exemplar_image(spec):
    try:
        if spec.reference is not None:
            real = read_volume(spec.reference)
            return exemplar_slices(real, spec.slices, spec.slice_axis, spec.slice_index)["front"]
        return named_exemplar(spec.exemplar, spec.crop)
    except Exception:  # the exemplar may be gone (e.g. a report on another machine)
        return None


def _run_json(study_dir, spec, name="run.json"):
    path = study_dir / spec.run_id / name
    if not path.is_file():
        return None
    return json.loads(path.read_text(encoding="utf-8"))


def _temperatures(record) -> list:
    """A run's global temperature after each sweep, one list per level, coarse first: the
    coherent support records it in each level's statistics, the full support's history is it."""
    if not record:
        return []
    levels = ((record.get("stats") or {}).get("levels") or {})
    if levels and all("temperature" in v for v in levels.values()):
        order = sorted(levels, key=lambda k: -int(k.rsplit("_", 1)[-1]))
        return [levels[k]["temperature"] for k in order]
    config = record.get("config") or {}
    return (record.get("history") or []) if config.get("support") == "full" else []


def _temperature_figure(study_dir, specs, rows):
    """Each method's global temperature after each sweep (its first seed; every seed in the
    CSV), as a share of the level's first value so that levels of every size read alike."""
    done = {r["run_id"] for r in rows if r["status"] != "failed"}
    exemplars = unique(s.exemplar for s in specs)
    table, curves = [], defaultdict(list)
    for s in specs:
        record = _run_json(study_dir, s) if s.run_id in done else None
        history = _temperatures(record)
        xs, ys, sweep = [], [], 0
        for level_index, level in enumerate(history):
            start = level[0] if level and level[0] > 0 else 1.0
            for k, t in enumerate(level):
                table.append({"run_id": s.run_id, "exemplar": s.exemplar, "method": s.method,
                              "seed": s.seed, "level": level_index, "sweep": k, "temperature": t})
                xs.append(sweep + k)
                ys.append(t / start)
            sweep += len(level)
        if xs and s.seed == min(x.seed for x in specs if x.method == s.method):
            curves[s.exemplar].append((s.method, s.seed, xs, ys))
    if not table:
        return []
    write_csv(study_dir / "temperature.csv", table)
    fig = Figure(figsize=(5.0 * len(exemplars), 3.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(exemplars), squeeze=False)[0])
    for ax, e in zip(axes, exemplars):
        for method, seed, xs, ys in curves.get(e, []):
            ax.plot(xs, ys, marker=".", label=f"{method} (seed {seed})")
        ax.set_title(e)
        ax.set_xlabel("sweep (levels one after the other, coarse first)")
        ax.set_ylabel("global temperature / the level's first")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    return [save_figure(fig, study_dir / "temperature.png")]


def _two_point_figure(study_dir, specs, rows):

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
    write_csv(study_dir / "two_point.csv", table)
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


