"""Speed benchmark: the paper's slowest job, colour annealing.

64^3 colour volume, 64x64 colour exemplar (the bundled ``ihc64`` micrograph, all of its
distinct colours as labels unless ``--palette`` is given), 11x11 windows, 3 levels, simulated
annealing, ML_H2b, 8/8 up-sampling, a stated number of proposals per voxel and level. Prints
the wall time per level, proposals per second, the ratio to the paper's ~48 hours, the
neighbour-distance FLOP rate and its ratio to a float32 matrix multiply measured in the same
run, and the hardware. First bar: under 15 minutes on 2 cores (>= 200x the paper).

Usage: ``python benchmarks/bench_anneal.py [--size 64] [--proposals 10] [--sampler metropolis]
[--palette K] [--out DIR]`` (``--out`` also writes the run folder: volume, preview, run.json).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import npmrf3d
from npmrf3d import data
from npmrf3d.plotting import preview_figure, save_figure

from _common import hardware, matmul_gflops

PAPER_SECONDS = 48 * 3600


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--window", type=int, default=11)
    parser.add_argument("--proposals", type=int, default=10, help="proposals per voxel and level")
    parser.add_argument("--sampler", default="metropolis")
    parser.add_argument("--palette", type=int, default=None, help="k-means colours (default: all)")
    parser.add_argument("--exemplar", default="ihc64")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="folder for a preview PNG")
    args = parser.parse_args(argv)
    ex = npmrf3d.load_exemplar(data.path(args.exemplar))
    npmrf3d.synthesize(ex[:16, :16], size=8, window=3, levels=1, relaxation="anneal",
                       sampler=args.sampler, proposals=1, rng=0)  # JIT warm-up (cached on disk)
    print(f"hardware: {hardware()}")
    n_colours = len(np.unique(ex.reshape(-1, ex.shape[2]), axis=0))
    labels = f"palette of {args.palette}" if args.palette else f"all {n_colours} distinct colours"
    print(f"job: {args.size}^3 colour, exemplar {args.exemplar} {ex.shape[0]}x{ex.shape[1]}x"
          f"{ex.shape[2]} ({labels}), {args.window}x{args.window}, 3 levels, anneal "
          f"({args.sampler}), ML_H2b, 8/8, {args.proposals} proposals per voxel and level")
    t0 = time.perf_counter()
    res = npmrf3d.synthesize(ex, size=args.size, window=args.window, levels=3,
                             heuristic="ML_H2b", relaxation="anneal", sampler=args.sampler,
                             proposals=args.proposals, upsample="8/8", palette=args.palette,
                             rng=args.seed)
    wall = time.perf_counter() - t0
    m = args.window * args.window - 1
    flops, proposals = 0.0, 0
    for level in sorted(res.stats["levels"], reverse=True):
        st = res.stats["levels"][level]
        n = np.mean([v["n"] for v in st["views"].values()])
        # distances are computed for every update whose proposal differs from the current label
        flops += 3.0 * st["changed_or_evaluated"] * n * m * ex.shape[2] if "changed_or_evaluated" in st \
            else 3.0 * st["evaluations"] * n * m * ex.shape[2]
        proposals += st["updates"]
        sec = res.timings[level]
        accept = np.mean(st["acceptance"])
        print(f"{level}: {st['shape'][0]}^3, {st['sweeps']} sweeps, {st['updates']:,} proposals, "
              f"{sec:7.1f} s, {st['updates'] / sec:,.0f} proposals/s, mean acceptance {accept:.3f}")
    ref = matmul_gflops()
    rate = flops / wall / 1e9
    print(f"total wall time {wall:.1f} s ({wall / 60:.1f} min); {proposals / wall:,.0f} proposals/s; "
          f"{len(res.labels)} labels")
    print(f"versus the paper's ~48 h: {PAPER_SECONDS / wall:,.0f}x faster")
    print(f"kernel {rate:.1f} GFLOP/s (neighbour distances) vs float32 matmul {ref:.1f} GFLOP/s: "
          f"ratio {rate / ref:.3f}")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        fig = preview_figure(res.volume, {"front": ex},
                             title=f"{args.exemplar} anneal {args.sampler} P={args.proposals}")
        print(f"preview: {save_figure(fig, out / f'anneal_{args.exemplar}_{args.sampler}.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
