"""Scaling benchmark: time per voxel against volume size and exemplar size.

Methods: the full-Parzen NP-MRF sampler (``variant="sharp"``, ICM, ML_H2b, 7x7), the default
sampler (``npmrf3d.synthesize`` with its defaults: the coherent NP-MRF), and the baselines NP_K
(``kopf``) and Chen-Wang, each with its own defaults otherwise. Volume sides 32, 64, 128 with a
64x64 exemplar; exemplar sides 32, 64, 128 at a 32^3 volume. Exemplars are top-left crops of
the bundled 128x128 grey ``gravel`` photograph; seed 0; levels 3 (``--quick``: sides 16 and 32,
exemplars 32 and 64, levels 2).

A run whose time, extrapolated from the same method's previous size (x8 per doubled side, or
x4 per doubled exemplar side), exceeds ``--budget`` seconds is skipped and printed as such, so
the full grid finishes on a small machine; raise the budget to measure everything.

Writes ``figures/scaling.png`` (log-log, time per voxel against voxels and against exemplar
pixels) and ``figures/scaling.json`` (the numbers, hardware, threads, load and version) side by
side, and prints the table with the hardware and thread count.

Usage: ``python benchmarks/bench_scaling.py [--quick] [--budget 600] [--out figures]``
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from _common import hardware

import npmrf3d
from npmrf3d import data
from npmrf3d.errors import ParameterError
from npmrf3d.methods.chen_wang import chen_wang_synthesize
from npmrf3d.methods.kopf import kopf_synthesize
from npmrf3d.plotting import save_figure

METHODS = ("full-Parzen (sharp)", "default (coherent)", "NP_K (kopf)", "Chen-Wang")


def run(method: str, exemplar: np.ndarray, size: int, levels: int):
    """One synthesis of ``method``; returns the result."""
    if method.startswith("full-Parzen"):
        return npmrf3d.synthesize(exemplar, size=size, levels=levels, variant="sharp", rng=0)
    if method.startswith("default"):
        return npmrf3d.synthesize(exemplar, size=size, levels=levels, rng=0)
    if method.startswith("NP_K"):
        return kopf_synthesize(exemplar, size=size, levels=levels, rng=0)
    return chen_wang_synthesize(exemplar, size=size, levels=levels, window=(8, 6, 4)[-levels:],
                                iterations=(4, 4, 3)[-levels:], rng=0)


def measure(grid, *, levels: int, budget: float, previous_factor: float, done: dict):
    """Time every (method, size, exemplar side) of ``grid`` in order; skip by extrapolation.
    ``done`` maps (method, size, side) to rows already measured (reused, and filled)."""
    ex_full = npmrf3d.load_exemplar(data.path("gravel"))
    rows = []
    for method in METHODS:
        last = None
        for size, side in grid:
            if (method, size, side) in done and not done[method, size, side]["skipped"]:
                rows.append(done[method, size, side])
                last = rows[-1]["wall_s"]
                continue
            if last is not None and last * previous_factor > budget:  # extrapolated
                rows.append({"method": method, "size": size, "exemplar": side, "skipped": True,
                             "estimate_s": last * previous_factor})
                print(f"{method:22s} {size:4d}^3  exemplar {side:3d}  skipped (about "
                      f"{last * previous_factor:,.0f} s > budget {budget:,.0f} s)")
                last *= previous_factor
                continue
            exemplar = np.ascontiguousarray(ex_full[:side, :side])
            load = os.getloadavg()[0]
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                run(method, exemplar, size, levels)
            except ParameterError as err:  # e.g. Chen-Wang's 8x8 window on a 32x32 exemplar
                rows.append({"method": method, "size": size, "exemplar": side, "skipped": True,
                             "reason": str(err)})
                print(f"{method:22s} {size:4d}^3  exemplar {side:3d}  not possible: {err}")
                continue
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            last = wall
            per_voxel = wall / size**3 * 1e6
            rows.append({"method": method, "size": size, "exemplar": side, "skipped": False,
                         "wall_s": wall, "cpu_s": cpu, "us_per_voxel": per_voxel, "load": load})
            done[method, size, side] = rows[-1]
            print(f"{method:22s} {size:4d}^3  exemplar {side:3d}  wall {wall:8.1f} s  CPU "
                  f"{cpu:8.1f} s  {per_voxel:9.2f} us/voxel  (load {load:.1f})")
    return rows


def figure(by_size, by_exemplar, path: Path, titles: tuple[str, str]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, rows, key, xlabel in ((axes[0], by_size, "size", "voxels"),
                                  (axes[1], by_exemplar, "exemplar", "exemplar pixels")):
        for method in METHODS:
            done = [r for r in rows if r["method"] == method and not r["skipped"]]
            if not done:
                continue
            x = [r[key] ** (3 if key == "size" else 2) for r in done]
            ax.loglog(x, [r["us_per_voxel"] for r in done], "o-", label=method)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("wall time per voxel (us)")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title(titles[0])
    axes[1].set_title(titles[1])
    axes[0].legend(fontsize=8)
    fig.suptitle(hardware(), fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="sides 16, 32; exemplars 32, 64")
    parser.add_argument("--budget", type=float, default=600.0, help="seconds per run, extrapolated")
    parser.add_argument("--out", default="figures", help="folder for scaling.png and scaling.json")
    args = parser.parse_args(argv)
    sizes, sides, levels = ((16, 32), (32, 64), 2) if args.quick else ((32, 64, 128), (32, 64, 128), 3)
    small = 32
    ex = npmrf3d.load_exemplar(data.path("gravel"))[:32, :32]
    for method in METHODS:  # JIT warm-up (compiled code is cached on disk after the first run)
        run(method, ex, 16, 2)
    print(f"hardware: {hardware()}")
    print(f"volume sides {sizes} (exemplar 64), exemplar sides {sides} (volume {small}^3), "
          f"levels {levels}, seed 0")
    done: dict = {}
    by_size = measure([(s, 64) for s in sizes], levels=levels, budget=args.budget,
                      previous_factor=8.0, done=done)
    by_exemplar = measure([(small, s) for s in sides], levels=levels, budget=args.budget,
                          previous_factor=4.0, done=done)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    titles = (f"volume side {sizes[0]}..{sizes[-1]}, 64x64 exemplar",
              f"exemplar side {sides[0]}..{sides[-1]}, {small}^3 volume")
    png = figure(by_size, by_exemplar, out / "scaling.png", titles)
    record = {"hardware": hardware(), "version": npmrf3d.__version__, "levels": levels,
              "quick": args.quick, "budget_s": args.budget, "by_size": by_size,
              "by_exemplar": by_exemplar}
    (out / "scaling.json").write_text(json.dumps(record, indent=1))
    print(f"wrote {png} and {out / 'scaling.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
