"""Materials benchmark: synthetic microstructures against the spread of a real scan's own crops.

For every real scan built by ``benchmarks/materials_scans.py`` (``scans/<name>.npy``, float32 in
[0, 1]), the exemplar is the scan's most typical ``S^3`` crop (``S = --size``, the crop whose grey
mean and standard deviation lie nearest the crops' medians). The 2D methods (``npmrf``, the
default; ``chen-wang``; ``kopf``) see its middle slice across axis 0 -- an anisotropic scan gives
each view its own middle slice -- and ``volume-lh`` sees the crop itself. ``materials`` (by
``--methods``) is what ``npmrf3d materials`` runs on those slices: split into phases 0 and 1 by
the command's own :func:`npmrf3d.cli.materials.segment` at the threshold the benchmark judges by,
then, as :func:`npmrf3d.cli.materials.split_order` chooses, the default ``npmrf`` on the label
image (which runs its segmented preset) or on the grey slices, whose volume is split at the same
threshold (``--option materials:split=before`` or ``after`` forces one). Each output (``S^3``)
and every ``S^3`` crop of the scan (stride ``S/2``, at most ``--max-crops`` spread evenly) is
judged on the minority phase at the exemplar's threshold (0.5 for a binary scan, Otsu's for a
grey one):

* ``fraction`` -- volume fraction;
* ``surface`` -- specific surface area (marching cubes on the phase indicator, 1/voxel);
* ``diff0..2`` -- relative diffusivity of the phase along each axis, ``fraction / tau`` with
  ``tau`` TauFactor's tortuosity factor (0 when the phase does not percolate). The table gives
  it rather than ``tau`` because ``tau`` is unbounded: crops of a scan whose phase barely
  percolates read 10^6 beside 3 (``materials.json`` keeps ``tau`` too). ``--diffusivity
  finite-volume`` solves the same problem with the project's own solver
  (:func:`npmrf3d.analysis.materials.relative_diffusivity`), several times faster;
* ``odiff0..2`` -- the same for the other phase (the matrix a pore network runs through);
* ``perc`` -- whether the phase connects the two faces normal to each axis (face neighbours,
  :func:`npmrf3d.analysis.materials.percolates`), ``1 1 0`` for axes 0 and 1 only; the crops'
  spread is each axis's share of crops that percolate, and the volume is outside by the share
  of the axes it misses among those along which most crops percolate;
* ``s2`` -- error of the radial two-point correlation's shape: the L2 distance of
  ``(S2(r) - phi^2) / (phi - phi^2)``, r = 1..S/2, to the mean of the crops' curves, divided by
  that of a structureless volume (the exemplar's voxels shuffled): 0 = the scan's shape,
  1 = no structure; ``s2_axes`` the same for the per-axis curves;
* ``chord`` / ``chord_other`` -- mean chord length of the phase / of the other phase (voxels,
  all three axes, chords cut by the faces left out).

A cell is **inside** when it lies within the crops' minimum and maximum (for the errors: at
most the crops' largest, each crop judged against the mean of the others); otherwise the table
says how far outside, relative to the nearer bound. Prints a Markdown table, writes
``materials.json`` and one figure per scan (real slices, synthetic slices, S2 with the crops'
band) into ``--out``.

Usage::

    python benchmarks/materials_scans.py --sources SRC --out scans
    python benchmarks/bench_materials.py --scans scans --out figures/materials
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import npmrf3d
from npmrf3d.analysis import materials
from npmrf3d.cli.materials import phase_indices, segment, split_order
from npmrf3d.model.otsu import otsu_threshold

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from _common import hardware
from bench_volume_microct import typical_corner
from materials_scans import SCANS, by_name

METHODS = ("npmrf", "chen-wang", "kopf", "volume-lh")
#: also accepted by --methods: the coherent sampler itself, whose options the default fixes; the
#: materials command's path (its split into two phases, then the default on the label image)
EXTRA_METHODS = ("coherent", "materials")
SCALARS = ("fraction", "surface", "diff0", "diff1", "diff2", "odiff0", "odiff1", "odiff2", "chord",
           "chord_other")
ERRORS = ("s2", "s2_axes")
TAUS = ("tau0", "tau1", "tau2")
#: per axis, 1.0 where the phase connects the two faces normal to it
PERCS = ("perc0", "perc1", "perc2")
#: the table's columns, in order
COLUMNS = SCALARS + ("perc",) + ERRORS
#: how the benchmark may solve for the relative diffusivity
SOLVERS = ("taufactor", "finite-volume")


def crop_corners(shape, side: int, max_crops: int) -> list[tuple[int, int, int]]:
    """Corners of the ``side^3`` crops on the ``side // 2`` lattice, at most ``max_crops`` of them
    spread evenly."""
    step = max(side // 2, 1)
    corners = [(i, j, k) for i in range(0, shape[0] - side + 1, step)
               for j in range(0, shape[1] - side + 1, step) for k in range(0, shape[2] - side + 1, step)]
    if len(corners) > max_crops:
        corners = [corners[i] for i in np.linspace(0, len(corners) - 1, max_crops).round().astype(int)]
    return corners


def shape_curve(s2: np.ndarray, fraction: float) -> np.ndarray:
    """``(S2 - phi^2) / (phi - phi^2)`` without lag 0 (1 by construction)."""
    var = fraction - fraction ** 2
    return (s2[..., 1:] - fraction ** 2) / var if var > 0 else np.zeros_like(s2[..., 1:])


def tortuosity(ind: np.ndarray, axis: int) -> float:
    """TauFactor's tortuosity factor, ``inf`` when the phase does not percolate along ``axis``."""
    try:
        return materials.tortuosity(ind, axis=axis)
    except npmrf3d.errors.ParameterError:
        return float("inf")


def diffusivities(ind: np.ndarray, solver: str) -> tuple[list[float], list[float]]:
    """Per axis, the phase's tortuosity factor and relative diffusivity by ``solver``
    (``inf`` and 0 where it does not percolate)."""
    if solver == "taufactor":
        taus = [tortuosity(ind, a) for a in range(3)]
        return taus, [float(ind.mean()) / t for t in taus]
    diffs = [materials.relative_diffusivity(ind, axis=a) for a in range(3)]
    return [float(ind.mean()) / d if d > 0 else float("inf") for d in diffs], diffs


def statistics(ind: np.ndarray, *, tau: bool = True, solver: str = "taufactor") -> dict:
    """The benchmark's statistics of one phase indicator (see the module docstring); without
    ``tau`` no diffusivity (NaN)."""
    r = min(ind.shape) // 2
    fraction = float(ind.mean())
    radial = materials.radial_two_point(ind, max_distance=r, periodic=False)
    axes = materials.two_point_correlation(ind, True, max_distance=r, periodic=False)
    chords = np.concatenate([materials.chord_lengths(ind, a) for a in range(3)])
    others = np.concatenate([materials.chord_lengths(~ind, a) for a in range(3)])
    out = {"fraction": fraction, "surface": materials.specific_surface_area(ind),
           "chord": float(chords.mean()) if len(chords) else 0.0,
           "chord_other": float(others.mean()) if len(others) else 0.0,
           "radial": shape_curve(radial, fraction), "axes": shape_curve(axes, fraction)}
    nan = [float("nan")] * 3
    taus, diffs = diffusivities(ind, solver) if tau else (nan, nan)
    others = diffusivities(~ind, solver)[1] if tau else nan
    for a, percolating in enumerate(materials.percolates(ind)):
        out[f"tau{a}"], out[f"diff{a}"], out[f"odiff{a}"] = taus[a], diffs[a], others[a]
        out[f"perc{a}"] = float(percolating)
    return out


def l2(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def percolation_verdict(values, shares) -> float:
    """The share of the axes along which most crops percolate (``shares``: per axis, the crops'
    share) that the volume (``values``: 1.0 or 0.0 per axis) does not connect; 0 when it
    connects them all.

    >>> percolation_verdict([1.0, 1.0, 0.0], [1.0, 0.9, 0.6]), percolation_verdict([1, 0, 0], [1, 0.2, 0])
    (0.3333333333333333, 0.0)
    """
    needed = [v for v, share in zip(values, shares) if share >= 0.5]
    return sum(v < 0.5 for v in needed) / len(needed) if needed else 0.0


def percolation_text(values) -> str:
    """``1 1 0``: per axis, whether the phase percolates; a crops' share reads ``.93``."""
    return " ".join(f"{v:.0f}" if v in (0.0, 1.0) else f"{v:.2f}".lstrip("0") for v in values)


def verdict(value: float, low: float, high: float) -> float:
    """0 inside ``[low, high]``; else the relative distance to the nearer bound (signed: + above);
    NaN for a statistic not measured."""
    if np.isnan(value) or np.isnan(low):
        return float("nan")
    if low - 1e-12 <= value <= high + 1e-12:
        return 0.0
    if not np.isfinite(value):
        return float("inf")
    bound = high if value > high else low
    return (value - bound) / max(abs(bound), 1e-12)


class Judge:
    """The crops of one scan: their statistics, spread and mean S2 shape curves."""

    def __init__(self, crops: list[dict], control: dict):
        self.crops = crops
        self.radial = np.mean([c["radial"] for c in crops], axis=0)
        self.axes = np.mean([c["axes"] for c in crops], axis=0)
        self.control = {"s2": l2(control["radial"], self.radial), "s2_axes": l2(control["axes"], self.axes)}
        n = len(crops)
        errors = []
        for i, c in enumerate(crops):  # each crop against the mean of the others
            rest_r = (self.radial * n - c["radial"]) / (n - 1)
            rest_a = (self.axes * n - c["axes"]) / (n - 1)
            errors.append({"s2": l2(c["radial"], rest_r) / self.control["s2"],
                           "s2_axes": l2(c["axes"], rest_a) / self.control["s2_axes"]})
        self.spread = {k: (float(np.min([c[k] for c in crops])), float(np.max([c[k] for c in crops])))
                       for k in SCALARS + TAUS}
        self.spread.update({k: (0.0, float(np.max([e[k] for e in errors]))) for k in ERRORS})
        self.spread["perc"] = tuple(float(np.mean([c[k] for c in crops])) for k in PERCS)

    def judge(self, stats: dict) -> dict:
        values = {k: stats[k] for k in SCALARS + TAUS}
        values["s2"] = l2(stats["radial"], self.radial) / self.control["s2"]
        values["s2_axes"] = l2(stats["axes"], self.axes) / self.control["s2_axes"]
        out = {k: {"value": float(v), "outside": verdict(float(v), *self.spread[k])} for k, v in values.items()}
        axes = [stats[k] for k in PERCS]
        out["perc"] = {"value": percolation_text(axes), "outside": percolation_verdict(axes, self.spread["perc"])}
        return out


def exemplars_for(crop: np.ndarray, isotropic: bool) -> tuple[np.ndarray, dict]:
    """The 2D exemplar of a crop, its middle slice across axis 0, and the options that give an
    anisotropic scan's views each their own middle slice."""
    n = crop.shape[0] // 2
    views = {} if isotropic else {"exemplars": {"front": crop[:, :, n][..., None], "right": crop[n][..., None],
                                                "top": crop[:, n][..., None]}}
    return crop[n][..., None], views


def as_phases(exemplar: np.ndarray, views: dict, threshold: float,
              split: str = "auto") -> tuple[np.ndarray, dict, np.ndarray, str]:
    """The 2D exemplar and views as ``npmrf3d materials`` hands them to its method: split by
    :func:`npmrf3d.cli.materials.segment` at ``threshold`` (pooled over the slices the method
    sees) into phases 0 and 1, or left grey when :func:`~npmrf3d.cli.materials.split_order`
    (``split``) splits after synthesis; the phases' values; and that order."""
    slices = dict(views["exemplars"]) if views else {"exemplar": exemplar}
    labels, values, _ = segment([s[..., 0] for s in slices.values()], threshold=repr(threshold))
    order, _ = split_order(labels, True, split)
    if order == "after":
        return exemplar, views, values, order
    phases = dict(zip(slices, (phase_indices(a, values) for a in labels)))
    if views:
        return exemplar, {"exemplars": phases}, values, order
    return phases["exemplar"], {}, values, order


def synthesize(method: str, crop: np.ndarray, isotropic: bool, size: int, seed: int,
               options: dict, threshold: float) -> tuple[np.ndarray, float]:
    """One method's ``size^3`` volume from ``crop`` (``materials``: the phases' values,
    ``threshold`` its split) and the seconds it took."""
    t0 = time.perf_counter()
    values = order = None
    if method == "volume-lh":
        exemplar, views = crop[..., None], {}
    else:
        exemplar, views = exemplars_for(crop, isotropic)
    if method == "materials":
        options = dict(options)
        exemplar, views, values, order = as_phases(exemplar, views, threshold, options.pop("split", "auto"))
    result = npmrf3d.synthesize(None if views else exemplar, method="npmrf" if method == "materials" else method,
                                size=size, rng=seed, **views, **options)
    volume = result.volume[..., 0]
    if order == "after":  # as the command splits the grey volume at the input's threshold
        volume = values[(volume > threshold).astype(np.int64)].astype(np.float32)
    elif values is not None:  # as the command maps the method's phases back to the input's values
        volume = values[np.rint(volume).astype(np.int64)].astype(np.float32)
    return volume, time.perf_counter() - t0


def cell(j: dict) -> str:
    o = j["outside"]
    v = j["value"]
    if isinstance(v, str):
        return v if o == 0 else f"{v} ({o:+.0%})"
    if np.isnan(v):
        return "–"
    text = "inf" if not np.isfinite(v) else (f"{v:.3f}" if abs(v) < 10 else f"{v:.3g}")
    if o == 0:
        return text
    return f"{text} ({'out' if not np.isfinite(o) else (f'{o:+.0%}' if abs(o) < 10 else '>10x')})"


def method_options(items: list[str]) -> dict:
    """``METHOD:KEY=VALUE`` items -> {method: {key: value}} (values read as JSON when they parse)."""
    out: dict = {}
    for item in items:
        try:
            method, rest = item.split(":", 1)
            key, value = rest.split("=", 1)
        except ValueError:
            raise SystemExit(f"bench_materials: error: --option takes METHOD:KEY=VALUE; got {item!r}") from None
        try:
            value = json.loads(value)
        except json.JSONDecodeError:
            pass
        out.setdefault(method, {})[key] = value
    return out


def figure(path: pathlib.Path, name: str, crop: np.ndarray, volumes: dict, judge: Judge, runs: dict) -> None:
    cols = 1 + len(volumes)
    fig, ax = plt.subplots(4, cols, figsize=(2.1 * cols, 8.6))
    n = crop.shape[0] // 2
    for c, (label, vol) in enumerate([("real crop", crop)] + list(volumes.items())):
        for row, sl in enumerate((vol[n], vol[:, n], vol[:, :, n])):
            ax[row, c].imshow(sl, cmap="gray", vmin=0, vmax=1)
            ax[row, c].set_xticks([])
            ax[row, c].set_yticks([])
        ax[0, c].set_title(label, fontsize=8)
    for row, axis_label in enumerate(("slice across axis 0", "axis 1", "axis 2")):
        ax[row, 0].set_ylabel(axis_label, fontsize=8)
    gs = ax[3, 0].get_gridspec()
    for a in ax[3]:
        a.remove()
    curve = fig.add_subplot(gs[3, :])
    r = np.arange(1, len(judge.radial) + 1)
    band = np.array([c["radial"] for c in judge.crops])
    curve.fill_between(r, band.min(axis=0), band.max(axis=0), color="0.8", label=f"{len(judge.crops)} real crops")
    curve.plot(r, judge.radial, "k-", lw=1.5, label="crops' mean")
    for label in volumes:
        curve.plot(r, runs[label]["radial"], lw=1, label=f"{label} ({runs[label]['judged']['s2']['value']:.2f})")
    curve.axhline(0, color="0.5", lw=0.5)
    curve.set_xlabel("r (voxels)")
    curve.set_ylabel("(S2 - phi^2) / (phi - phi^2)")
    curve.legend(fontsize=7, ncol=3)
    fig.suptitle(f"{name}: middle slices of a real crop and of each method's volume; radial S2 shape",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def run_scan(name: str, path: pathlib.Path, args) -> dict:
    scan = by_name(name)
    volume = np.load(path).astype(np.float32)
    side = args.size
    corners = crop_corners(volume.shape, side, args.max_crops)
    a, b, c = typical_corner(volume, side // 2, side)
    crop = volume[a:a + side, b:b + side, c:c + side]
    threshold = 0.5 if scan.binary else float(otsu_threshold(crop))
    above = float((crop > threshold).mean())
    minority = (lambda v: v > threshold) if above <= 0.5 else (lambda v: v <= threshold)
    t0 = time.perf_counter()
    solver = "no-tau" if args.no_tau else args.diffusivity
    cache = pathlib.Path(args.out) / "crops" / f"{name}-{side}-{len(corners)}-{solver}-perc.npz"
    if cache.is_file():  # the crops' statistics depend only on the scan, the size and the corners
        with np.load(cache, allow_pickle=False) as saved:
            crops = [{k: (saved[k][n] if saved[k].ndim > 1 else float(saved[k][n])) for k in saved.files}
                     for n in range(len(corners))]
    else:
        crops = [statistics(minority(volume[i:i + side, j:j + side, k:k + side]), tau=not args.no_tau,
                            solver=args.diffusivity) for i, j, k in corners]
        cache.parent.mkdir(parents=True, exist_ok=True)
        np.savez(cache, **{k: np.array([c[k] for c in crops]) for k in crops[0]})
    shuffled = np.random.default_rng(0).permutation(crop.ravel()).reshape(crop.shape)
    judge = Judge(crops, statistics(minority(shuffled), tau=False))
    print(f"{name}: {volume.shape}, {len(corners)} crops of {side}^3 ({time.perf_counter() - t0:.0f} s), "
          f"exemplar crop at {(a, b, c)}, threshold {threshold:.3f}, phase "
          f"{'above' if above <= 0.5 else 'at or below'} it", flush=True)
    runs, volumes = {}, {}
    for method in args.methods:
        for seed in args.seeds:
            vol, seconds = synthesize(method, crop, scan.isotropic, side, seed, args.options.get(method, {}),
                                      threshold)
            stats = statistics(minority(vol), tau=not args.no_tau, solver=args.diffusivity)
            label = method if len(args.seeds) == 1 else f"{method} s{seed}"
            runs[label] = {"method": method, "seed": seed, "seconds": round(seconds, 1),
                           "judged": judge.judge(stats), "radial": stats["radial"]}
            volumes[label] = vol
            j = runs[label]["judged"]
            print(f"  {label}: {seconds:.1f} s; " + ", ".join(f"{k} {cell(j[k])}" for k in COLUMNS), flush=True)
    out = pathlib.Path(args.out)
    figure(out / f"{name}.png", name, crop, volumes, judge, runs)
    return {"scan": name, "shape": list(volume.shape), "isotropic": scan.isotropic, "held_out": scan.held_out,
            "binary": scan.binary, "threshold": threshold, "corner": [a, b, c], "crops": len(corners),
            "spread": judge.spread, "control": judge.control,
            "runs": {k: {kk: vv for kk, vv in v.items() if kk != "radial"} for k, v in runs.items()}}


def spread_text(key: str, spread) -> str:
    """The crops' spread of one column as the table gives it."""
    if key == "perc":
        return percolation_text(spread)
    lo, hi = spread
    return f"{lo:.3g}–{hi:.3g}" if key in SCALARS else f"≤ {hi:.3f}"


def outside_values(cells: dict) -> list[float]:
    """The verdicts of one run's judged cells (the table's columns measured)."""
    return [cells[k]["outside"] for k in COLUMNS if not np.isnan(cells[k]["outside"])]


def table(records: list[dict]) -> str:
    keys = COLUMNS
    lines = ["| scan | method | " + " | ".join(keys) + " | inside | time (s) |",
             "|---" * (len(keys) + 4) + "|"]
    for rec in records:
        spread = " | ".join(spread_text(k, rec["spread"][k]) for k in keys)
        lines.append(f"| **{rec['scan']}**{'' if rec['held_out'] else ' (tuning)'}"
                     f"{'' if rec['isotropic'] else ', 3 slices'} | crops' spread | {spread} | | |")
        for label, run in rec["runs"].items():
            j = run["judged"]
            outs = outside_values(j)
            lines.append(f"| | {label} | " + " | ".join(cell(j[k]) for k in keys)
                         + f" | {sum(o == 0 for o in outs)}/{len(outs)} | {run['seconds']:.0f} |")
    return "\n".join(lines)


def summary(records: list[dict]) -> str:
    """Per method and group: share of cells inside, worst miss, mean S2 ratio."""
    lines = []
    for group, keep in (("held-out", True), ("tuning", False)):
        for iso in (True, False):
            recs = [r for r in records if r["held_out"] == keep and r["isotropic"] == iso]
            if not recs:
                continue
            methods = sorted({run["method"] for r in recs for run in r["runs"].values()},
                             key=(METHODS + EXTRA_METHODS).index)
            for method in methods:
                cells = [run["judged"] for r in recs for run in r["runs"].values() if run["method"] == method]
                outs = [o for c in cells for o in outside_values(c)]
                inside = np.mean([o == 0 for o in outs])
                worst = max(abs(o) for o in outs)
                s2 = np.mean([c["s2"]["value"] for c in cells])
                lines.append(f"{group:8s} {'isotropic' if iso else 'anisotropic':11s} {method:10s}: "
                             f"{inside:.0%} of cells inside, worst {worst:.0%} outside, S2 ratio {s2:.3f}")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--scans", default="scans", help="folder of the scans' .npy files")
    p.add_argument("--names", nargs="+", default=[s.name for s in SCANS], help="which scans")
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS + EXTRA_METHODS)
    p.add_argument("--seeds", type=int, nargs="+", default=[7])
    p.add_argument("--size", type=int, default=64, help="side of the crops and of the volumes made")
    p.add_argument("--max-crops", type=int, default=27)
    p.add_argument("--no-tau", action="store_true", help="skip the diffusivities (no taufactor)")
    p.add_argument("--diffusivity", choices=SOLVERS, default="taufactor",
                   help="how to solve for the relative diffusivities: TauFactor or the project's own "
                        "finite-volume solver (the same problem, several times faster)")
    p.add_argument("--option", action="append", default=[], metavar="METHOD:KEY=VALUE",
                   help="an option of one method's configuration, e.g. npmrf:levels=4 (repeatable)")
    p.add_argument("--out", default="figures/materials")
    args = p.parse_args(argv)
    args.options = method_options(args.option)
    folder = pathlib.Path(args.scans)
    missing = [n for n in args.names if not (folder / f"{n}.npy").is_file()]
    if len(missing) == len(args.names):
        print(f"bench_materials: error: no scan in {folder}; build them with benchmarks/materials_scans.py",
              file=sys.stderr)
        return 2
    for n in missing:
        print(f"bench_materials: {n}: {folder / (n + '.npy')} not found, left out", file=sys.stderr)
    pathlib.Path(args.out).mkdir(parents=True, exist_ok=True)
    records = [run_scan(n, folder / f"{n}.npy", args) for n in args.names if n not in missing]
    print()
    print(table(records))
    print()
    print(summary(records))
    record = {"hardware": hardware(), "size": args.size, "seeds": args.seeds, "methods": args.methods,
              "options": args.options, "diffusivity": None if args.no_tau else args.diffusivity,
              "scans": records}
    with open(pathlib.Path(args.out) / "materials.json", "w") as fh:
        json.dump(record, fh, indent=1, default=float)
    command = "python benchmarks/bench_materials.py " + " ".join(argv if argv is not None else sys.argv[1:])
    (pathlib.Path(args.out) / "table.md").write_text(
        f"Made by `{command}` on {record['hardware']}.\n\n{table(records)}\n\n```\n{summary(records)}\n```\n",
        encoding="utf-8")
    print(f"wrote {args.out}/materials.json, table.md and one PNG per scan")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
