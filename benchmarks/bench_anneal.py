"""Speed benchmark: the paper's slowest job, colour annealing.

64^3 colour volume, 64x64 colour exemplar (the bundled ``ihc64`` micrograph, all of its
distinct colours, no palette unless ``--palette`` is given), 11x11 windows, 3 levels, simulated
annealing, ML_H2b. Two annealers (``--variant``):

* ``coherent`` (default; docs/model.md, section 8): annealing over the coherent candidates -- each voxel
  draws among the texels voted by its neighbourhoods' coherent matches with probability
  proportional to ``exp(score / T)``, ``T`` from ``t0`` to ``t_end`` over each level's iterations.
  Prints the wall time per level and the solver's voxel updates per second.
* ``sharp`` / ``literal`` (the paper's full-Parzen annealer): 8/8 up-sampling, ``--proposals``
  per voxel and level, ``--sampler`` metropolis or heat-bath. Prints proposals per second, the
  neighbour-distance FLOP rate and its ratio to a float32 matrix multiply measured in the same
  run.

Both print the ratio to the paper's ~48 hours and the structure of the result: the
autocorrelation error, histogram KL and orientation KL as ratios to the structureless control
(voxels drawn independently from the exemplar; the target is an autocorrelation ratio <= 0.6),
and the histogram KL itself.
Targets: under 2 minutes on 2 cores with structure.

Usage: ``python benchmarks/bench_anneal.py [--variant coherent|sharp] [--size 64]
[--proposals 10] [--sampler metropolis] [--palette K] [--out DIR]`` (``--out`` writes a preview).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from _common import hardware, matmul_gflops
from _quality import measure, ratios, structureless

import npmrf3d
from npmrf3d import data
from npmrf3d.plotting import preview_figure, save_figure

PAPER_SECONDS = 48 * 3600


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--variant", default="coherent", choices=("coherent", "sharp", "literal"),
                        help="annealer: over coherent candidates, or the paper's full-Parzen one")
    parser.add_argument("--t0", type=float, default=1.0, help="first temperature of each level")
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
    coherent = args.variant == "coherent"
    if coherent:  # JIT warm-up (cached on disk)
        npmrf3d.synthesize(ex[:32, :32], size=16, window=3, levels=1, relaxation="anneal",
                           variant="coherent", rng=0)
    else:
        npmrf3d.synthesize(ex[:16, :16], size=8, window=3, levels=1, relaxation="anneal",
                           variant=args.variant, sampler=args.sampler, proposals=1, rng=0)
    print(f"hardware: {hardware()}")
    n_colours = len(np.unique(ex.reshape(-1, ex.shape[2]), axis=0))
    labels = f"palette of {args.palette}" if args.palette else f"all {n_colours} distinct colours"
    how = (f"over coherent candidates, t0 {args.t0}" if coherent else
           f"({args.sampler}), 8/8, {args.proposals} proposals per voxel and level")
    print(f"job: {args.size}^3 colour, exemplar {args.exemplar} {ex.shape[0]}x{ex.shape[1]}x"
          f"{ex.shape[2]} ({labels}), {args.window}x{args.window}, 3 levels, ML_H2b, anneal {how}")
    t0 = time.perf_counter()
    options = {} if coherent else {"sampler": args.sampler, "proposals": args.proposals, "upsample": "8/8"}
    res = npmrf3d.synthesize(ex, size=args.size, window=args.window, levels=3, heuristic="ML_H2b",
                             relaxation="anneal", variant=args.variant, t0=args.t0,
                             palette=args.palette, rng=args.seed, **options)
    wall = time.perf_counter() - t0
    if coherent:
        _coherent_report(res, wall)
    else:
        _parzen_report(res, wall, ex, args)
    control = measure(ex, structureless(ex, args.size, np.random.default_rng(args.seed)))
    raw = measure(ex, res.volume)
    got = ratios(raw, control)
    print(f"structure (ratio to the structureless control): autocorrelation {got['ac']:.3f} "
          f"(target <= 0.6), orientation KL {got['orient_kl']:.3f}; histogram KL {raw['hist_kl']:.4f} "
          f"(the control's is ~0: it copies the exemplar's pixels)")
    print(f"total wall time {wall:.1f} s ({wall / 60:.1f} min; target < 2 min); "
          f"versus the paper's ~48 h: {PAPER_SECONDS / wall:,.0f}x faster")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        name = args.variant if coherent else f"{args.variant}_{args.sampler}"
        fig = preview_figure(res.volume, {"front": ex}, title=f"{args.exemplar} anneal {name}")
        print(f"preview: {save_figure(fig, out / f'anneal_{args.exemplar}_{name}.png')}")
    return 0


def _coherent_report(res, wall: float) -> None:
    """Per level: iterations, their temperatures, seconds and solver updates per second."""
    for level in sorted(res.stats["levels"], reverse=True):
        st = res.stats["levels"][level]
        n_vox = int(np.prod(st["shape"]))
        sec = res.timings[level]
        print(f"{level}: {st['shape'][0]}^3, {st['iterations']} iterations, {sec:7.1f} s "
              f"(search {st['search_seconds']:.1f} s, solve {st['solve_seconds']:.1f} s), "
              f"{st['iterations'] * n_vox / st['solve_seconds']:,.0f} voxel updates/s")


def _parzen_report(res, wall: float, ex, args) -> None:
    """Per level: sweeps, proposals per second, acceptance; the distance stage's FLOP rate."""
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
    print(f"{proposals / wall:,.0f} proposals/s; {len(res.labels)} labels")
    print(f"kernel {rate:.1f} GFLOP/s (neighbour distances) vs float32 matmul {ref:.1f} GFLOP/s: "
          f"ratio {rate / ref:.3f}")


if __name__ == "__main__":
    raise SystemExit(main())
