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
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

import npmrf3d
from npmrf3d import data, metrics
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
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--variant", action="append", help="variants to run (repeatable)")
    parser.add_argument("--suite", choices=("variants", "anneal"), default="variants",
                        help="variants: the --variant presets with --set overrides; anneal: "
                             "the annealing samplers and proposal counts of ANNEAL_SUITE")
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


if __name__ == "__main__":
    raise SystemExit(main())
