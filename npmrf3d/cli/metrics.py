"""``npmrf3d metrics EXEMPLAR VOLUME``: compare a volume with its exemplars (docs/metrics.md).

Prints a table (one row per view plus the mean, one column per metric of
:data:`npmrf3d.analysis.metrics.METRICS`) and writes ``histograms.png`` and ``metrics.json`` (last) into
the output folder, each atomically and only after every number was computed, so a user error
leaves no file behind. See ``docs/metrics.md`` for the definitions.

Besides ``.npy`` and TIFF files it reads a Zarr volume folder (``--out VOL.zarr`` of the
commands that make volumes), refusing one whose blocks are not all made or whose made blocks'
chunk files are gone. Each metric is also reported as a ratio to the structureless control,
beside the floor (:mod:`npmrf3d.analysis.metrics.references`). ``--structure`` adds the
slice-by-slice structure judge per view as ratios to its floor
(:mod:`npmrf3d.analysis.metrics.layout`); the views the volume's run constrained are named
when its ``run.json`` (or the Zarr volume's record) says which.

A run folder it reads or writes (one holding a run's files), or a Zarr volume it reads, is
locked for the whole command
(:class:`npmrf3d.io.runs.OutputLock`, the lock every run takes on its ``--out``): a run that
is writing or ``--overwrite``-replacing the folder makes the command refuse at once, and no run
can replace the folder while the metrics of its volume are computed and written.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import pathlib
import shutil
from datetime import datetime, timezone
from typing import Any

import numpy as np
import zarr
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from .. import _validation as check
from .. import io
from ..analysis import metrics, structure
from ..analysis.metrics import METRICS, layout
from ..analysis.metrics.volume_files import read_volume
from ..analysis.metrics.references import RATIO_METRICS, against_controls, floor
from ..errors import ParameterError
from ..io.runs import RUN_FILES, OutputLock
from ..model.exemplar import BUNDLED_PREFIX, exemplar_source, load_exemplar
from ..model.neighbourhood import VIEWS
from ..plotting import save_figure
from ._common import PROG, check_out, say

__all__ = ["OUT_FILES", "register"]

#: Files written by the command, in the order they are written (``metrics.json`` last).
OUT_FILES = ("histograms.png", "metrics.json")
_CHANNEL_COLOURS = ("tab:red", "tab:green", "tab:blue")


def register(commands: argparse._SubParsersAction, formatter_class: type) -> None:
    """Add the ``metrics`` sub-command; its handler is ``handler(args, argv) -> exit code``."""
    parser = commands.add_parser(
        "metrics",
        help="compare a volume's slices with the exemplar(s): histogram KL, autocorrelation, "
             "orientation, sliced Wasserstein",
        description=(
            "Compare each constrained view's exemplar with all the volume's slices orthogonal\n"
            "to that view (pooled) and print one row per view plus the mean. Lower is better;\n"
            "0 = indistinguishable by that measure. Each metric is also given as a ratio to a\n"
            "structureless control (the exemplar's pixels drawn independently, in the volume's\n"
            "shape: 1 = no structure), beside the floor (the exemplar's right half measured\n"
            "against its left half: another crop of the same texture, about what a perfect volume\n"
            "scores). Definitions and settings: docs/metrics.md.\n"
            "--structure adds the structure judge: each view's sampled slices compared one by\n"
            "one with the exemplar (docs/structure.md), per view and for the worst view, as\n"
            "ratios to its floor, the same two halves (1 = as good as another crop).\n"
            "When the volume's run.json (or the Zarr volume's record) names the views the run\n"
            "constrained, the output says which were constrained and which free.\n"
            f"Writes {' and '.join(OUT_FILES)} into the output folder.\n\n"
            "Integer images are scaled as synth does (uint8 / 255, uint16 / 65535), so a\n"
            "float volume written by synth compares with the 8-bit exemplar it came from.\n\n"
            "examples:\n"
            "  npmrf3d metrics bundled:gravel64 npmrf3d-out/volume.npy\n"
            "  npmrf3d metrics bundled:gravel64 big.zarr\n"
            "  npmrf3d metrics bundled:brick layered/volume.npy --structure\n"
            "  npmrf3d metrics wood.png wood/volume.tif --views front,top --out wood/metrics"
        ),
        formatter_class=formatter_class,
    )
    parser.add_argument(
        "exemplar", metavar="EXEMPLAR",
        help="2D exemplar image (.png, .jpg, .bmp, .gif, .tif or .npy) compared with every view, "
             f"or '{BUNDLED_PREFIX}NAME' for a bundled one",
    )
    parser.add_argument(
        "volume", metavar="VOLUME",
        help="the volume: a .npy array (N1,N2,N3) or (N1,N2,N3,C), a .tif written by synth, or a "
             "Zarr volume (a .zarr folder) made with --out VOL.zarr",
    )
    parser.add_argument(
        "--views", default=",".join(VIEWS), metavar="V[,V...]",
        help=f"comma-separated views to compare, 1 to 3 distinct names of {', '.join(VIEWS)}",
    )
    for view in VIEWS:
        parser.add_argument(
            f"--exemplar-{view}", default=None, metavar="PATH",
            help=f"a different exemplar file (or {BUNDLED_PREFIX}NAME) for the {view} view "
                 f"(default: none = EXEMPLAR)",
        )
    parser.add_argument(
        "--structure", action="store_true",
        help="add the slice-by-slice structure judge per view and its worst view, as ratios to "
             "the floor (needs the extra: pip install 'npmrf3d[structure]')",
    )
    parser.add_argument(
        "--out", default=None, metavar="DIR",
        help="folder for metrics.json and histograms.png; created if missing "
             "(default: the folder holding VOLUME)",
    )
    parser.add_argument(
        "--overwrite", action="store_true",
        help="replace metrics.json and histograms.png already in --out instead of refusing",
    )
    parser.set_defaults(handler=run)


# --------------------------------------------------------------------------- checks and inputs


def _read_exemplars(args: argparse.Namespace, views: tuple[str, ...]
                    ) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    extra = [v for v in VIEWS if getattr(args, f"exemplar_{v}") is not None and v not in views]
    if extra:
        raise ParameterError(
            f"--exemplar-{extra[0]} is given but {extra[0]} is not among --views "
            f"({','.join(views)})"
        )
    arrays: dict[str, np.ndarray] = {}
    sources: dict[str, str] = {}
    cache: dict[str, np.ndarray] = {}
    for view in views:
        own = getattr(args, f"exemplar_{view}")
        path, name = exemplar_source(own if own is not None else args.exemplar)
        if name not in cache:
            label = f"exemplar for view {view}" if own is not None else "exemplar"
            cache[name] = load_exemplar(path, name=label)
        arrays[view], sources[view] = cache[name], name
    return arrays, sources


# --------------------------------------------------------------------------- outputs


def _row(name: str, values: dict[str, float], names, width: int) -> str:
    return f"{name:<{width}}  " + "  ".join(
        f"{values[m]:>{max(len(m), 10)}.4g}" if m in values else f"{'-':>{max(len(m), 10)}}"
        for m in names)


def _table(result: dict[str, Any], references: dict[str, Any]) -> str:
    """The raw metrics per view, their mean, the control's and the floor's; then the ratios to
    the control, one row per metric; then what the control and the floor are."""
    floor = references["floor"]
    rows = [*result["per_view"].items(), ("mean", result["mean"]),
            ("control", references["control"]["mean"])]
    if floor is not None:
        rows.append(("floor", floor["raw"]))
    width = max(len(name) for name, _ in rows)
    head = f"{'view':<{width}}  " + "  ".join(f"{m:>{max(len(m), 10)}}" for m in METRICS)
    lines = [head, *(_row(name, values, METRICS, width) for name, values in rows), ""]
    ratio = references["ratio"]
    columns = {**ratio["per_view"], "mean": ratio["mean"]}
    if floor is not None:
        columns["floor"] = floor["ratio"]
    title = "ratio to the control"
    width = max(len(title), *(len(m) for m in METRICS))
    lines.append(f"{title:<{width}}  " + "  ".join(f"{c:>7}" for c in columns))
    for m in RATIO_METRICS:
        lines.append(f"{m:<{width}}  " + "  ".join(f"{v[m]:>7.3f}" for v in columns.values()))
    lines.append(f"{'histogram_kl':<{width}}  raw only (the control has the exemplar's histogram)")
    lines.append("")
    lines.append("control: the exemplar's pixels drawn independently, in the volume's shape "
                 "(1 = no structure; lower is better)")
    if floor is None:
        lines.append("floor: none (the exemplar is too small to split in two halves of at least "
                     f"{metrics.MIN_SIDE} pixels)")
    else:
        h, w = floor["half_shape"]
        lines.append(f"floor: another crop of the same texture, {floor['exemplar']} right half "
                     f"against its left half ({h}x{w} pixels each; about what a perfect volume scores)")
    return "\n".join(lines)


def _run_views(text: str) -> dict[str, Any] | None:
    """The views the volume's run constrained and those it left free, from the ``run.json``
    beside a run folder's volume file or a Zarr volume's record; None when neither says."""
    path = pathlib.Path(text)
    try:
        if path.is_dir():
            source = f"the record of '{path}'"
            record = zarr.open_array(path, mode="r").attrs.get("npmrf3d_record")
        elif path.name in RUN_FILES:
            source = str(path.parent / "run.json")
            record = json.loads((path.parent / "run.json").read_text(encoding="utf-8"))
        else:
            return None
        named = record["config"]["views"]
    except Exception:  # no record, or not one of a run: nothing to say
        return None
    if not isinstance(named, list) or not named or not set(named) <= set(VIEWS):
        return None
    return {"constrained": [v for v in VIEWS if v in named],
            "free": [v for v in VIEWS if v not in named], "source": source}


def _views_line(run_views: dict[str, Any]) -> str:
    free = run_views["free"]
    said = f"; {', '.join(free)} {'was' if len(free) == 1 else 'were'} free" if free else ""
    return (f"views: the run constrained {', '.join(run_views['constrained'])}{said} "
            f"({run_views['source']})")


def _layout(volume: np.ndarray, exemplars: dict[str, np.ndarray]) -> dict[str, Any]:
    """The structure judge per view as ratios to the floor of each view's exemplar (its right
    half against its left half), :func:`npmrf3d.analysis.metrics.layout.view_scores`."""
    seed = metrics.DEFAULT_SETTINGS.seed
    floors: dict[int, dict[str, float]] = {}
    for view, e in exemplars.items():
        if id(e) not in floors:
            try:
                floors[id(e)] = layout.half_floor(e, rng=seed)
            except ValueError:
                raise ParameterError(
                    f"--structure needs exemplars at least 16 pixels wide and 8 high (its floor is "
                    f"the right half against the left half); the {view} view's is "
                    f"{e.shape[0]} x {e.shape[1]}") from None
    return layout.view_scores(volume, exemplars, {v: floors[id(e)] for v, e in exemplars.items()},
                              rng=seed)


def _structure_table(judged: dict[str, Any], run_views: dict[str, Any] | None) -> str:
    """The judge's ratios to the floor per view and the worst view, then the floor's ratios to
    the control, then what they are."""
    views = list(judged["per_view"])
    free = set(run_views["free"]) if run_views else set()
    heads = [f"{v} (free)" if v in free else v for v in views]
    title = "structure judge, ratio to the floor"
    cells = [max(len(h), 8) for h in heads]
    lines = [f"{title}  " + "  ".join(f"{h:>{n}}" for h, n in zip(heads, cells)) + "     worst"]
    for k in ("pyramid", "continuity"):
        values = "  ".join(f"{judged['per_view'][v]['to_floor'][k]:>{n}.3f}" for v, n in zip(views, cells))
        lines.append(f"{k:<{len(title)}}  {values}  {judged['worst'][k]:>8.3f} "
                     f"{judged['worst_view'][k]}")
    floors = {json.dumps(f, sort_keys=True): f for f in judged["floor"].values()}
    for view, f in judged["floor"].items():
        if len(floors) == 1 and view != views[0]:
            break
        whose = "the exemplar's" if len(floors) == 1 else f"the {view} view's exemplar's"
        lines.append(f"floor, ratio to the control: pyramid {f['pyramid']:.3f}, continuity "
                     f"{f['continuity']:.3f} ({whose} right half against its left half)")
    lines.append(f"structure judge: {judged['settings']['slices']} slices a view, each compared with "
                 "the exemplar on its own (docs/structure.md); 1 = as good as another crop, lower "
                 "is better; pyramid is the estimator to judge by")
    return "\n".join(lines)


def _figure(histograms: dict[str, dict[str, Any]], result: dict[str, Any], title: str):
    views = list(histograms)
    fig = Figure(figsize=(4.2 * len(views), 6.6))  # fixed margins: a layout engine is slow
    axes = fig.subplots(2, len(views), squeeze=False,
                        gridspec_kw=dict(left=0.8 / (4.2 * len(views)), right=0.98, bottom=0.08,
                                         top=0.9, wspace=0.35, hspace=0.45))
    for col, view in enumerate(views):
        h, scores = histograms[view], result["per_view"][view]
        ax = axes[0, col]
        values = h["values"]
        channels = len(values["exemplar"])
        handles = [Line2D([], [], color="k", lw=1.6, label="exemplar"),
                   Line2D([], [], color="k", lw=1.2, ls="--", label="volume")]
        for c in range(channels):
            colour = (_CHANNEL_COLOURS[c] if channels == 3 else f"C{c}") if channels > 1 else "k"
            edges = values["edges"][c]
            ax.stairs(values["exemplar"][c], edges, color=colour, lw=1.6)
            ax.stairs(values["volume"][c], edges, color=colour, lw=1.2, ls="--")
            if channels > 1:
                handles.append(Line2D([], [], color=colour, lw=4, label=f"channel {c}"))
        ax.set_title(f"{view}: values, KL {scores['histogram_kl']:.3g}")
        ax.set_xlabel("value" if channels == 1 else "channel value")
        ax.set_ylabel("probability")
        ax.legend(handles=handles, fontsize="x-small")
        ax = axes[1, col]
        o = h["orientation"]
        degrees = np.degrees(o["edges"])
        ax.stairs(o["exemplar"], degrees, color="k", lw=1.6, label="exemplar")
        ax.stairs(o["volume"], degrees, color="tab:orange", lw=1.2, ls="--", label="volume")
        ax.set_title(f"{view}: orientation, KL {scores['orientation_kl']:.3g}")
        ax.set_xlabel("gradient angle (degrees from the column axis)")
        ax.set_ylabel("weighted share")
        ax.set_xlim(0, 180)
        ax.legend(fontsize="x-small")
    fig.suptitle(title)
    return fig


def _references(result: dict[str, Any], shape, exemplars: dict[str, np.ndarray],
                sources: dict[str, str]) -> dict[str, Any]:
    """The control and the ratios to it (:func:`~npmrf3d.analysis.metrics.references.against_controls`),
    and the floor of the first view's exemplar (None if it is too small to split)."""
    out = against_controls(result, shape, exemplars)
    view = next(iter(exemplars))
    out["floor"] = floor(exemplars[view])
    if out["floor"] is not None:
        out["floor"]["exemplar"] = (f"the {view} view's exemplar's" if len(set(sources.values())) > 1
                                    else "the exemplar's")
    return out


def _write(out: pathlib.Path, fig, record: dict[str, Any]) -> None:
    """Write the two files atomically; on failure remove what this call created."""
    missing = []
    folder = out.absolute()
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    new = [out / name for name in OUT_FILES if not (out / name).exists()]
    try:
        out.mkdir(parents=True, exist_ok=True)
        save_figure(fig, out / OUT_FILES[0])
        io.write_json(out / OUT_FILES[1], record)
    except BaseException:
        if missing:  # the folder is ours: remove it whole
            shutil.rmtree(missing[-1], ignore_errors=True)
        else:
            for path in new:
                path.unlink(missing_ok=True)
        raise


def _run_folders(*folders: pathlib.Path) -> list[pathlib.Path]:
    """The distinct folders among ``folders`` that hold a run's files (what a run may replace)."""
    found = {}
    for folder in folders:
        if folder.is_dir() and any((folder / name).exists() for name in RUN_FILES):
            found.setdefault(folder.resolve(), folder)
    return [found[key] for key in sorted(found)]


def run(args: argparse.Namespace, argv: list[str]) -> int:
    """Handler of ``npmrf3d metrics``; returns the exit code (errors raise ParameterError)."""
    views = check.views(args.views, VIEWS)
    if args.structure:
        structure.check_installed()
    if args.out is not None and not args.out.strip():
        raise ParameterError("--out must name a folder; got an empty string")
    if not args.volume.strip():
        raise ParameterError("volume file name is empty")
    out = pathlib.Path(args.out) if args.out is not None else pathlib.Path(args.volume).parent
    check_out(out, args.overwrite, files=OUT_FILES, what="metrics")
    with contextlib.ExitStack() as locks:
        advice = "wait for that run to finish, then run npmrf3d metrics again"
        for folder in _run_folders(pathlib.Path(args.volume).parent, out):
            locks.enter_context(OutputLock(folder, what="run folder", advice=advice))
        if pathlib.Path(args.volume).is_dir():  # a Zarr volume: its run holds the same lock
            locks.enter_context(OutputLock(args.volume, what="Zarr volume", advice=advice))
        check_out(out, args.overwrite, files=OUT_FILES, what="metrics")  # again, under the lock
        return _measure(args, argv, views, out)


def _measure(args: argparse.Namespace, argv: list[str], views: tuple[str, ...], out: pathlib.Path) -> int:
    """Read, compare, write: the body of :func:`run`, under the locks of the run folders."""
    volume, stored = read_volume(args.volume)
    exemplars, sources = _read_exemplars(args, views)
    run_views = _run_views(args.volume)
    judged = _layout(volume, exemplars) if args.structure else None
    result = metrics.evaluate(volume, exemplars, views=views)
    references = _references(result, volume.shape, exemplars, sources)
    histograms = {view: metrics.view_histograms(volume, exemplars[view], view) for view in views}
    title = f"{pathlib.Path(args.volume).name} versus {', '.join(sorted(set(sources.values())))}"
    fig = _figure(histograms, result, title)
    record = {
        "command": "metrics",
        "argv": [PROG, *argv],
        "inputs": {
            "volume": args.volume,
            "volume_shape": list(volume.shape),
            "volume_dtype": stored,
            "exemplars": sources,
            "exemplar_shapes": {view: list(a.shape) for view, a in exemplars.items()},
        },
        "views": list(views),
        "metrics": list(metrics.METRICS),
        "per_view": result["per_view"],
        "mean": result["mean"],
        "control": references["control"],
        "ratio": references["ratio"],
        "floor": references["floor"],
        "structure": judged,
        "run_views": run_views,
        "settings": result["settings"],
        "details": result["details"],
        "versions": io.package_versions(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    try:
        _write(out, fig, record)
    except OSError as exc:
        raise ParameterError(
            f"cannot write into output folder '{out}': {exc.strerror or exc}") from exc
    say(_table(result, references))
    if judged is not None:
        say("\n" + _structure_table(judged, run_views))
    if run_views is not None:
        say(_views_line(run_views))
    say(f"wrote {out}{os.sep}: {', '.join(OUT_FILES)}")
    return 0
