"""Quality benchmark: does a variant make texture, not noise, a blur or a flat block?

Runs NP-MRF variants at 32^3 on real photographs (the bundled scikit-image crops) and prints,
per exemplar and view:

* ``ac``: autocorrelation error of the view's slices relative to a structureless control
  (voxels drawn independently from the exemplar): 1.0 = no structure, lower is better;
* ``floor``: the same measure for exact crops of the exemplar put in place of every slice
  (the best a method can hope for at this size);
* ``kl``: histogram KL(exemplar || volume);
* ``top``: share of voxels holding the most common value (1.0 = constant volume).

It saves a preview PNG per run in ``figures/quality/`` (look at them) and the numbers in
``figures/quality/quality.json``.

Usage::

    python benchmarks/bench_quality.py                       # default and literal variants
    python benchmarks/bench_quality.py --variant default --set adaptive=0.1 --tag a01
    python benchmarks/bench_quality.py --suite anneal   # annealing samplers and proposal counts,
                                                        # colour and grey exemplars

The ``anneal`` suite runs on :data:`ANNEAL_EXEMPLARS` with a 64-colour palette (colour
exemplars have thousands of distinct colours; the heat-bath sampler evaluates every label).

The ``paper`` suite is the paper-scale benchmark (``benchmarks/_quality.py`` describes the
measures, the controls, the exemplar set and how to add a method)::

    python benchmarks/bench_quality.py --suite paper --quick               # 32^3, 4 exemplars
    python benchmarks/bench_quality.py --suite paper --methods npk,npmrf-default
    python benchmarks/bench_quality.py --suite paper --methods npmrf-default --palette 64
    python benchmarks/bench_quality.py --suite paper --seeds 7,8,9 --exemplars gravel,hubble

It needs ``apt-get install -y extremetuxracer-data`` for its held-out photographs (the
``etr_*`` exemplars; missing ones are skipped with a note). Results are cached per
(method, exemplar, seed, size) in ``figures/quality_paper/results.json`` (volumes in
``~/.cache/npmrf3d/quality_paper``): a re-run only computes the missing cells
(``--recompute`` for all). Pictures: ``figures/quality_paper/<method>/<exemplar>.png`` and a
contact sheet per method, ``figures/quality_paper/sheet_<method>.png``, and the methods side
by side, ``figures/quality_paper/sheet_compare.png``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import npmrf3d
from npmrf3d import data
from npmrf3d.analysis import metrics
from npmrf3d.plotting import preview_figure, save_figure

EXEMPLARS = ("gravel64", "brick", "grass")
ANNEAL_EXEMPLARS = ("ihc64", "hubble", "gravel64")
#: The ``anneal`` suite: (label, variant, overrides of synthesize).
ANNEAL_SUITE = tuple(
    (f"{sampler}-P{p}", "default",
     {"relaxation": "anneal", "sampler": sampler, "proposals": p, "palette": 64})
    for sampler, counts in (("heat-bath", (4, 8, 16)), ("metropolis", (8, 32)))
    for p in counts
) + (("metropolis-literal-P8", "literal",
      {"relaxation": "anneal", "sampler": "metropolis", "proposals": 8, "palette": 64,
       "histogram_weight": 8.0}),)
VIEWS = ("front", "right", "top")


def exemplar_crop(name: str, side: int = 64) -> np.ndarray:
    image = npmrf3d.load_exemplar(data.path(name))
    return np.ascontiguousarray(image[:side, :side])


def control_and_floor(exemplar: np.ndarray, size: int, max_lag: int, rng: np.random.Generator):
    """Autocorrelation errors of the structureless control and of exact exemplar crops."""
    h, w, c = exemplar.shape
    flat = exemplar.reshape(-1, c)
    control = flat[rng.integers(0, len(flat), size=size**3)].reshape(size, size, size, c)
    crops = np.stack([exemplar[a:a + size, b:b + size]
                      for a, b in zip(rng.integers(0, h - size + 1, size),
                                      rng.integers(0, w - size + 1, size))])
    floor_volume = np.moveaxis(crops, 0, 2)  # front slices volume[:, :, k] are the crops
    ctrl = metrics.autocorrelation_error(exemplar, control, "front", max_lag)
    floor = metrics.autocorrelation_error(exemplar, floor_volume, "front", max_lag)
    return ctrl, floor


def parse_overrides(items: list[str]) -> dict:
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        for kind in (int, float, str):
            try:
                out[key] = kind(value)
                break
            except ValueError:
                continue
    return out


def main(argv=None) -> int:
    first = argparse.ArgumentParser(add_help=False)
    first.add_argument("--suite")
    known, rest = first.parse_known_args(argv)
    if known.suite == "paper":  # its own options (--suite paper --help lists them)
        return paper_main(rest)
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--variant", action="append", help="variants to run (repeatable)")
    parser.add_argument("--suite", choices=("variants", "anneal", "paper"), default="variants",
                        help="variants: the --variant presets with --set overrides; anneal: "
                             "the annealing samplers and proposal counts of ANNEAL_SUITE; "
                             "paper: the paper-scale benchmark (see --suite paper --help)")
    parser.add_argument("--set", action="append", default=[], help="override key=value of the rule")
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--levels", type=int, default=2)
    parser.add_argument("--window", type=int, default=7)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--exemplar", action="append", help=f"bundled names (default: {EXEMPLARS})")
    parser.add_argument("--tag", default="", help="suffix for the picture names")
    parser.add_argument("--out", default="figures/quality")
    args = parser.parse_args(argv)
    overrides = parse_overrides(args.set)
    if args.suite == "anneal":
        runs = [(label, variant, {**extra, **overrides}) for label, variant, extra in ANNEAL_SUITE]
        names = args.exemplar or list(ANNEAL_EXEMPLARS)
    else:
        runs = [(v + args.tag, v, overrides) for v in (args.variant or ["default", "literal"])]
        names = args.exemplar or list(EXEMPLARS)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    max_lag = min(8, args.size // 2 - 1)
    print(f"npmrf3d {npmrf3d.__version__}; size {args.size}^3, window {args.window}, "
          f"levels {args.levels}, seed {args.seed}, autocorrelation lags up to {max_lag}")
    print(f"{'exemplar':10s} {'variant':14s} {'view':6s} {'ac':>6s} {'floor':>6s} {'kl':>6s} {'top':>6s} {'sec':>6s}")
    records = []
    for name in names:
        ex = exemplar_crop(name)
        ctrl, floor = control_and_floor(ex, args.size, max_lag, np.random.default_rng(args.seed))
        for label, variant, run_overrides in runs:
            t0 = time.perf_counter()
            res = npmrf3d.synthesize(ex, size=args.size, window=args.window, levels=args.levels,
                                     variant=variant, rng=args.seed, **run_overrides)
            sec = time.perf_counter() - t0
            top = metrics.largest_value_share(res.volume)
            kl = metrics.histogram_kl(ex, res.volume)
            for view in VIEWS:
                ac = metrics.autocorrelation_error(ex, res.volume, view, max_lag) / ctrl
                records.append({"exemplar": name, "variant": label, "view": view, "ac": ac,
                                "floor": floor / ctrl, "kl": kl, "top": top, "seconds": sec,
                                "overrides": run_overrides})
                print(f"{name:10s} {label:14s} {view:6s} {ac:6.3f} {floor / ctrl:6.3f} {kl:6.3f} "
                      f"{top:6.3f} {sec:6.1f}", flush=True)
            fig = preview_figure(res.volume, {"front": ex}, title=f"{name} {label}")
            save_figure(fig, out / f"{name}_{label}.png")
    summary = {}
    for variant in {r["variant"] for r in records}:
        rows = [r for r in records if r["variant"] == variant]
        summary[variant] = {k: float(np.mean([r[k] for r in rows])) for k in ("ac", "floor", "kl", "top")}
        s = summary[variant]
        print(f"mean {variant:14s} ac {s['ac']:.3f} (floor {s['floor']:.3f}) kl {s['kl']:.3f} top {s['top']:.3f}")
    path = out / f"quality{'_anneal' if args.suite == 'anneal' else ''}{args.tag}.json"
    path.write_text(json.dumps({"records": records, "summary": summary}, indent=2))
    return 0


# --------------------------------------------------------------------------- the paper suite


def _draw_run(q, out: Path, method: str, name: str, volume: np.ndarray, run: dict) -> None:
    a, _ = q.BY_NAME[name].crops()
    r = run["ratio"]
    layout = run.get("layout", {}).get("layout", float("nan"))
    title = (f"{name} {method} seed {run['seed']}: ac {r['ac']:.2f} sw {r['sw']:.2f} "
             f"orient {r['orient_kl']:.2f} (x control), layout {layout:.2f} (x floor), "
             f"hist KL {run['raw']['hist_kl']:.2f}"
             + (f", palette {run['palette']}" if run["palette"] else ""))
    fig = preview_figure(volume, {"front": a}, title=title)
    (out / method).mkdir(parents=True, exist_ok=True)
    save_figure(fig, out / method / f"{name}.png")


def _panel(ax, image, vmin, vmax, title) -> None:
    from npmrf3d.plotting import to_display

    ax.imshow(to_display(image, vmin=vmin, vmax=vmax), cmap="gray", vmin=vmin, vmax=vmax,
              interpolation="nearest")
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=8)


def _contact_sheet(q, out: Path, method: str, items: list) -> None:
    """Two exemplars a row, each: crop A (exemplar), a crop B (floor), front, right, top."""
    from matplotlib.figure import Figure

    rows = -(-len(items) // 2)
    fig = Figure(figsize=(20, 2.2 * rows), layout="constrained")
    axes = np.atleast_2d(fig.subplots(rows, 10))
    for ax in axes.flat:
        ax.set_axis_off()
    for index, (name, volume, run) in enumerate(items):
        a, b = q.BY_NAME[name].crops()
        n = volume.shape[0]
        vmin, vmax = float(a.min()), float(a.max())
        r = run["ratio"]
        row = axes[index // 2, 5 * (index % 2): 5 * (index % 2) + 5]
        held = " (held out)" if q.BY_NAME[name].held_out else ""
        panels = ((a, f"{name}{held}"), (b[0], "a crop B (floor)"),
                  (volume[:, :, n // 2], f"front; ac {r['ac']:.2f} sw {r['sw']:.2f}"),
                  (volume[n // 2], f"right; hkl {run['raw']['hist_kl']:.2f}"),
                  (volume[:, n // 2], f"top; okl {r['orient_kl']:.2f}"))
        for ax, (image, title) in zip(row, panels):
            ax.set_axis_on()
            _panel(ax, image, vmin, vmax, title)
    fig.suptitle(f"{method}: {n}^3 from 64 x 64 crops, seed {items[0][2]['seed']} "
                 f"(ac, sw, okl: ratio to the structureless control; hkl: histogram KL)")
    save_figure(fig, out / f"sheet_{method}.png")


def _compare_sheet(q, out: Path, by_method: dict) -> None:
    """Rows: exemplars; columns: crop A, then each method's front and top centre slices."""
    from matplotlib.figure import Figure

    names = [n for n in q.BY_NAME if any(n in items for items in by_method.values())]
    methods = list(by_method)
    fig = Figure(figsize=(2 * (1 + 2 * len(methods)), 2.1 * len(names)), layout="constrained")
    axes = np.atleast_2d(fig.subplots(len(names), 1 + 2 * len(methods)))
    for ax in axes.flat:
        ax.set_axis_off()
    for row, name in zip(axes, names):
        a, _ = q.BY_NAME[name].crops()
        vmin, vmax = float(a.min()), float(a.max())
        row[0].set_axis_on()
        _panel(row[0], a, vmin, vmax, name + (" (held out)" if q.BY_NAME[name].held_out else ""))
        for m, method in enumerate(methods):
            if name not in by_method[method]:
                continue
            volume, run = by_method[method][name]
            n = volume.shape[0]
            for k, (image, view) in enumerate(((volume[:, :, n // 2], "front"),
                                                (volume[:, n // 2], "top"))):
                ax = row[1 + 2 * m + k]
                ax.set_axis_on()
                _panel(ax, image, vmin, vmax, f"{method} {view}"
                       + (f" ac {run['ratio']['ac']:.2f}" if k == 0 else ""))
    save_figure(fig, out / "sheet_compare.png")


def paper_main(argv: list[str]) -> int:
    import _quality as q
    from _common import hardware

    from npmrf3d.analysis.structure import check_installed
    from npmrf3d.errors import ParameterError

    try:
        check_installed()   # the layout columns need the structure judge's extra
    except ParameterError as exc:
        print(f"bench_quality.py: {exc}")
        return 2

    parser = argparse.ArgumentParser(prog="bench_quality.py --suite paper",
                                     description=q.__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--methods", default="npk,npmrf-default",
                        help=f"comma-separated, from {', '.join(q.METHODS)}")
    parser.add_argument("--exemplars", default=None,
                        help=f"comma-separated (default all): {', '.join(q.BY_NAME)}")
    parser.add_argument("--seeds", default="7", help="comma-separated seeds")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--levels", type=int, default=3)
    parser.add_argument("--palette", type=int, default=None,
                        help="colour exemplars: a palette of this many colours for the methods "
                             "that take one (recorded with the run)")
    parser.add_argument("--quick", action="store_true",
                        help=f"smoke run: 32^3 and the exemplars {', '.join(q.QUICK)}")
    parser.add_argument("--jobs", type=int, default=1, help="runs in parallel processes")
    parser.add_argument("--recompute", action="store_true", help="ignore the cached runs")
    parser.add_argument("--remeasure", action="store_true",
                        help="recompute the measures of the cached runs from their saved volumes")
    parser.add_argument("--cached-only", action="store_true",
                        help="compute nothing: summarise and draw the cached runs (a missing "
                             "cell is left out of the summary, which says how many it holds)")
    parser.add_argument("--no-figures", action="store_true")
    parser.add_argument("--out", default="figures/quality_paper")
    parser.add_argument("--cache-dir", default=str(Path.home() / ".cache/npmrf3d/quality_paper"))
    args = parser.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    unknown = [m for m in methods if m not in q.METHODS]
    if unknown:
        parser.error(f"unknown method(s) {', '.join(unknown)}; known: {', '.join(q.METHODS)}")
    size = 32 if args.quick and args.size == 64 else args.size
    names = (args.exemplars.split(",") if args.exemplars
             else list(q.QUICK) if args.quick else list(q.BY_NAME))
    unknown = [n for n in names if n not in q.BY_NAME]
    if unknown:
        parser.error(f"unknown exemplar(s) {', '.join(unknown)}; known: {', '.join(q.BY_NAME)}")
    missing = [n for n in names if not q.BY_NAME[n].available()]
    if missing:
        print(f"note: skipping {', '.join(missing)}: {q.ETR_HINT}")
        names = [n for n in names if n not in missing]
    seeds = [int(s) for s in args.seeds.split(",")]
    out, cache = Path(args.out), Path(args.cache_dir)
    out.mkdir(parents=True, exist_ok=True)
    cache.mkdir(parents=True, exist_ok=True)
    path = out / "results.json"
    results = json.loads(path.read_text()) if path.is_file() else {}
    results.setdefault("runs", {})
    results.setdefault("references", {})
    print(f"npmrf3d {q._version()}; {hardware()}")
    print(f"{size}^3 from {q.CROP}x{q.CROP} crops, {args.levels} levels, seeds {seeds}; "
          f"autocorrelation lags <= {q.MAX_LAG}; sliced Wasserstein {q.SW_PATCH}x{q.SW_PATCH} "
          f"patches at scales {q.SW_SCALES}")
    print("references (ratio to the structureless control): floor = crop B as the slices, "
          "blurred = control smoothed to the exemplar's grain; judge = the structure judge's "
          "pyramid ratio of the crops B against crop A (the floor of the layout), layout = "
          "the blurred control's, a ratio to that floor")
    for name in names:
        for seed in seeds:
            key = f"{name}|seed{seed}|size{size}"
            ref = results["references"].get(key)
            if args.recompute or ref is None or ref.get("version") != q.REFERENCE_VERSION:
                ref = results["references"][key] = q.references(q.BY_NAME[name], size, seed)
            f, bl = ref["floor"], ref["blurred"]
            print(f"  {name:18s} seed {seed}: floor ac {f['ratio']['ac']:.3f} sw "
                  f"{f['ratio']['sw']:.3f} orient {f['ratio']['orient_kl']:.3f} hist_kl "
                  f"{f['raw']['hist_kl']:.3f} judge {f['judge']['pyramid']:.3f} | blurred ac "
                  f"{bl['ratio']['ac']:.3f} sw {bl['ratio']['sw']:.3f} orient "
                  f"{bl['ratio']['orient_kl']:.3f} layout {bl['layout']['layout']:.2f}")
    q.save_json(path, results)

    def echo(line):
        print(line, flush=True)
        q.save_json(path, results)

    if args.remeasure and not args.recompute:
        keys = [q.run_key(m, n, s, size, q._effective_palette(m, q.BY_NAME[n].crops()[0],
                                                               args.palette))
                for m in methods for n in names for s in seeds]
        q.remeasure(results, cache, [k for k in keys if k in results["runs"]], size, echo=echo)
    if not args.cached_only:
        q.run_all(methods, names, seeds, size, args.levels, args.palette, results, cache,
                  jobs=args.jobs, recompute=args.recompute, echo=echo)
    summary = q.summarise(results, methods, names, seeds, size, args.palette)
    results["summary"] = {"size": size, "seeds": seeds, "levels": args.levels,
                          "palette": args.palette, "sets": summary}
    q.save_json(path, results)
    print(q.format_summary(summary))
    if not args.no_figures:
        by_method = {}
        for method in methods:
            items = []
            for name in names:
                a, _ = q.BY_NAME[name].crops()
                key = q.run_key(method, name, seeds[0], size,
                                q._effective_palette(method, a, args.palette))
                volume = q.load_volume(cache, key)
                if volume is None:
                    print(f"note: no cached volume for {key}; its picture is not drawn")
                    continue
                _draw_run(q, out, method, name, volume, results["runs"][key])
                items.append((name, volume, results["runs"][key]))
            if items:
                _contact_sheet(q, out, method, items)
                by_method[method] = {name: (volume, run) for name, volume, run in items}
        if len(by_method) > 1:
            _compare_sheet(q, out, by_method)
        print(f"pictures in {out}/<method>/ and {out}/sheet_<method>.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
