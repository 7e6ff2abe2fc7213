"""The figures and the page of ``npmrf3d materials``: each statistic of the volume (per axis)
drawn over the input's, and ``materials.html``, which shows them beside a table of the numbers
and the verdicts in words (:func:`npmrf3d.analysis.materials_compare.materials_report`)."""

from __future__ import annotations

import html
import pathlib

import numpy as np
from matplotlib.figure import Figure

from ..io.files import atomic_write
from ..plotting import save_figure

__all__ = ["FIGURES", "write_figures", "write_page"]

#: The figures, in the order the page shows them.
FIGURES = ("materials_slices.png", "materials_fractions.png", "materials_two_point.png",
           "materials_chords.png", "materials_connectivity.png")
AXIS_COLOURS = ("tab:blue", "tab:orange", "tab:green")


def _subplots(rows: int, cols: int, *, figsize, squeeze: bool = True):
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(rows, cols, squeeze=squeeze)


def _phase_image(ax, image: np.ndarray, values: list, title: str) -> None:
    ax.imshow(np.searchsorted(values, image), cmap="viridis", vmin=0, vmax=max(len(values) - 1, 1),
              interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])


def _slices(report: dict, volume: np.ndarray, inputs: dict):
    values = report["input"]["values"]
    mid = [n // 2 for n in volume.shape]
    shown = [(f"volume [:, :, {mid[2]}] (front)", volume[:, :, mid[2]]),
             (f"volume [{mid[0]}] (right)", volume[mid[0]]),
             (f"volume [:, {mid[1]}] (top)", volume[:, mid[1]])]
    if "volume" in inputs:
        crop = inputs["volume"]
        first = [("input crop: front", crop[:, :, crop.shape[2] // 2]), ("input crop: right", crop[crop.shape[0] // 2]),
                 ("input crop: top", crop[:, crop.shape[1] // 2])]
    else:
        distinct = {}
        for view, image in inputs.items():
            distinct.setdefault(id(image), (view, image))
        first = [(f"input: {'every view' if len(distinct) == 1 else view}", image)
                 for view, image in distinct.values()]
    fig, axes = _subplots(2, 3, figsize=(9, 6.8))
    for ax in axes[0]:
        ax.axis("off")
    for ax, (title, image) in zip(axes[0], first):
        ax.axis("on")
        _phase_image(ax, image, values, title)
    for ax, (title, image) in zip(axes[1], shown):
        _phase_image(ax, image, values, title)
    fig.suptitle(f"phases {', '.join(map(str, values))} (dark to light)", fontsize=10)
    fig.tight_layout()
    return fig


def _fractions(report: dict):
    phases = report["phases"]
    names = [str(p["value"]) for p in phases]
    x = np.arange(len(phases))
    fig, (left, right) = _subplots(1, 2, figsize=(10, 3.8))
    left.bar(x - 0.2, [p["input"]["fraction"] for p in phases], 0.4, color="0.6", label="input")
    left.bar(x + 0.2, [p["volume"]["fraction"] for p in phases], 0.4, color="tab:purple", label="volume")
    left.set_xticks(x, names)
    left.set_xlabel("phase")
    left.set_ylabel("volume fraction")
    left.legend(fontsize=8)
    width = 0.8 / 6
    for axis in range(3):
        ref = [p["input"]["surface_stereology"][axis] for p in phases]
        mine = [p["volume"]["surface_stereology"][axis] for p in phases]
        offset = (2 * axis - 2.5) * width
        right.bar(x + offset, [np.nan if r is None else r for r in ref], width, color=AXIS_COLOURS[axis],
                  alpha=0.35, label=f"input, axis {axis}")
        right.bar(x + offset + width, mine, width, color=AXIS_COLOURS[axis], label=f"volume, axis {axis}")
    right.set_xticks(x, names)
    right.set_xlabel("phase")
    right.set_ylabel("surface per volume, 2 P_L (1/voxel)")
    right.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def _curves(report: dict, key: str, ylabel: str, first: int):
    phases = report["phases"]
    fig, axes = _subplots(len(phases), 3, figsize=(10, 2.6 * len(phases)), squeeze=False)
    for row, p in zip(axes, phases):
        for axis, ax in enumerate(row):
            ref, mine = p["input"][key][axis], p["volume"][key][axis]
            r = np.arange(first, first + len(mine))
            if ref is not None:
                ax.plot(np.arange(first, first + len(ref)), ref, "k--", lw=1.2, label="input")
            ax.plot(r, mine, color=AXIS_COLOURS[axis], lw=1.5, label="volume")
            ax.set_title(f"phase {p['value']}, axis {axis}", fontsize=9)
            ax.set_xlabel("distance r (voxels)" if first == 0 else "chord length (voxels)", fontsize=8)
            ax.set_ylabel(ylabel, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def _connectivity(report: dict):
    phases = report["phases"]
    fig, (left, right) = _subplots(1, 2, figsize=(10, 0.8 + 0.7 * max(len(phases), 3)))
    verdicts = np.array([[{True: 1.0, False: 0.0, None: 0.5}[x] for x in p["compare"]["percolation"]["axes"]]
                         for p in phases])
    left.imshow(verdicts, cmap="RdYlGn", vmin=0, vmax=1, aspect="auto")
    for (i, a), _ in np.ndenumerate(verdicts):
        mine, ref = phases[i]["volume"]["percolates"][a], phases[i]["input"]["percolates"][a]
        left.text(a, i, f"{'yes' if mine else 'no'}\n(input: {'-' if ref is None else ('yes' if ref else 'no')})",
                  ha="center", va="center", fontsize=8)
    left.set_xticks(range(3), [f"axis {a}" for a in range(3)])
    left.set_yticks(range(len(phases)), [f"phase {p['value']}" for p in phases])
    left.set_title("connects face to face? green: as the input, red: not kept, yellow: "
               "the slices cannot tell", fontsize=9)
    x = np.arange(len(phases))
    for axis in range(3):
        right.bar(x + (axis - 1) * 0.27, [p["volume"]["diffusivity"][axis] for p in phases], 0.27,
                  color=AXIS_COLOURS[axis], label=f"volume, axis {axis}")
        if "diffusivity" in phases[0]["input"]:
            right.scatter(x + (axis - 1) * 0.27, [p["input"]["diffusivity"][axis] for p in phases],
                          marker="_", s=300, color="k", label="input crop" if axis == 0 else None)
    right.set_xticks(x, [str(p["value"]) for p in phases])
    right.set_xlabel("phase")
    right.set_ylabel("relative diffusivity D_eff / D")
    right.legend(fontsize=7)
    fig.tight_layout()
    return fig


def write_figures(out: pathlib.Path, report: dict, volume: np.ndarray, inputs: dict) -> None:
    """The PNGs of :data:`FIGURES` into ``out``."""
    figures = (_slices(report, volume, inputs), _fractions(report),
               _curves(report, "two_point", "S2(r)", 0), _curves(report, "chord_distribution", "probability", 1),
               _connectivity(report))
    for name, fig in zip(FIGURES, figures):
        save_figure(fig, out / name)


def _cells(values) -> str:
    return ", ".join("-" if v is None else (("yes" if v else "no") if isinstance(v, bool) else f"{v:.3g}")
                     for v in values)


def write_page(out: pathlib.Path, report: dict, title: str) -> None:
    """``materials.html``: the verdicts, a table of the numbers per phase and the figures."""
    rows = []
    for p in report["phases"]:
        v, i, c = p["volume"], p["input"], p["compare"]
        table = [("volume fraction", f"{i['fraction']:.3f}", f"{v['fraction']:.3f}", c["fraction"]),
                 ("surface per volume 2 P_L (1/voxel)", _cells(i["surface_stereology"]),
                  _cells(v["surface_stereology"]), c["surface"]),
                 ("surface per volume, marching cubes", _cells([i.get("surface_area")]),
                  _cells([v["surface_area"]]), None),
                 ("two-point correlation: RMS difference", "", _cells(c["two_point"]["difference"]), c["two_point"]),
                 ("mean chord (voxels)", _cells(i["mean_chord"]), _cells(v["mean_chord"]), c["chord"]),
                 ("connects face to face", _cells(i["percolates"]), _cells(v["percolates"]), c["percolation"]),
                 ("relative diffusivity", _cells(i.get("diffusivity", [None] * 3)), _cells(v["diffusivity"]),
                  c["diffusivity"])]
        body = "".join(
            f"<tr><td>{html.escape(name)}</td><td>{html.escape(a)}</td><td>{html.escape(b)}</td>"
            f"<td>{'' if verdict is None else {True: 'kept', False: '<b>not kept</b>', None: 'cannot tell'}[verdict['match']]}"
            f"</td></tr>" for name, a, b, verdict in table)
        words = "".join(f"<li>{html.escape(x['words'])}</li>" for x in c.values())
        rows.append(f"<h2>Phase {html.escape(str(p['value']))}</h2><table><tr><th>statistic</th>"
                    f"<th>input (axes 0, 1, 2)</th><th>volume (axes 0, 1, 2)</th><th>verdict</th></tr>"
                    f"{body}</table><ul>{words}</ul>")
    source = ", ".join(f"{k}: {v}" for k, v in report["input"]["sources"].items())
    figures = "".join(f'<p><img src="{name}" alt="{name}" style="max-width:100%"></p>' for name in FIGURES)
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            "<style>body{font-family:sans-serif;max-width:70em;margin:auto}table{border-collapse:collapse}"
            "td,th{border:1px solid #aaa;padding:3px 8px;text-align:left}</style></head><body>"
            f"<h1>{html.escape(title)}</h1><p>Input ({html.escape(report['input']['kind'])}): "
            f"{html.escape(source)}; phases {html.escape(report['input']['phases'])} "
            f"({html.escape(report['input']['split'])} synthesis: "
            f"{html.escape(report['input']['split_why'])}), values "
            f"{html.escape(str(report['input']['values']))} ({html.escape(report['input']['dtype'])}); method "
            f"{html.escape(report['method'])}; diffusivity by {html.escape(report['diffusivity_solver'])}.</p>"
            f"<p><b>{html.escape(report['summary'][0])}</b></p>{''.join(rows)}{figures}</body></html>\n")
    atomic_write(out / "materials.html", lambda tmp: pathlib.Path(tmp).write_text(page, encoding="utf-8"))
