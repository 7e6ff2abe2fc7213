"""Speed benchmark of the full-Parzen distance stage as matrix products.

Part 1, the distance stage alone, on the shapes of the paper's Figure-4 job at level 0 (64^3
grey volume, the 64x64 gravel crop, 7x7 windows: n = 3,364 patches, d = C (w^2 - 1) = 48, three
views) for one colour class of sites (4,096): the batched path (``gemm``: one float32 sgemm per
block of 256 sites and view) and the per-site direct sum (``direct``), for fully trusted
neighbours (annealing, cooled regions) and for neighbours at random temperatures (ICM). Rates
count the floor ``2 n d`` FLOP per voxel-view, whatever a path executes; the ratio is to a float32
1024^2 matrix multiply measured in the same run with the same number of threads.

Part 2 (skipped with ``--no-job``): the Figure-4 job itself (ICM, ML_H2b, 8/8, resynth,
xi = -3, stop at 95 %, variant ``sharp``), wall and CPU time, with each distance path.

Prints the hardware, the numba and BLAS threads and the load average next to every figure.
Usage: ``python benchmarks/bench_parzen_blas.py [--size 64] [--no-job] [--paths gemm,direct]
[--exemplar ihc64 --window 11]`` (the last two: the distance stage of the colour annealing job)
"""

from __future__ import annotations

import argparse
import functools
import os
import time

import numpy as np
from _common import hardware, matmul_gflops

import npmrf3d
from npmrf3d import data
from npmrf3d._kernels._jit import single_threaded_blas, thread_count
from npmrf3d._kernels.gemm import make_gemm_operands, sites_best_distances
from npmrf3d.config import PRESETS
from npmrf3d.model.exemplar import make_labels
from npmrf3d.model.neighbourhood import colour_classes
from npmrf3d.model.parzen import build_view_models
from npmrf3d.model.relax import RELAXATIONS, Relaxation

VIEWS = ("front", "right", "top")


def load() -> str:
    return "load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg())


def best_of(fn, repeats: int) -> tuple[float, float]:
    """(wall, CPU) seconds of the run with the least CPU time (CPU: all threads of the process,
    which a loaded machine disturbs far less than the wall time)."""
    fn()
    best = (np.inf, np.inf)
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        run = (time.perf_counter() - t0, time.process_time() - c0)
        best = min(best, run, key=lambda x: x[1])
    return best


def sgemm_cpu_gflops(n: int = 1024, repeats: int = 5) -> float:
    """float32 ``n x n`` matrix multiply on one BLAS thread, per CPU second (one core's rate)."""
    return matmul_gflops(n, repeats, clock=time.thread_time, blas=single_threaded_blas)


def distance_stage(size: int, repeats: int, exemplar: str, window: int, palette: int | None) -> None:
    ex = npmrf3d.load_exemplar(data.path(exemplar))
    rng = np.random.default_rng(0)
    labels, images = make_labels([ex], palette=palette, rng=rng)
    models, info = build_view_models({v: images[0] for v in VIEWS}, labels, window=window, level=0,
                                     rule=PRESETS["tuned"])
    ops = make_gemm_operands(models.patches_t, models.n_patches, labels.shape[1])
    n, d = info["front"]["n"], labels.shape[1] * (window * window - 1)
    shape = (size,) * 3
    grid = np.indices(shape)
    image = labels[images[0]]
    # every view sees exemplar-like content: voxel (i, j, k) = exemplar (i + k, j + 2k)
    volume = image[(grid[0] + grid[2]) % image.shape[0], (grid[1] + 2 * grid[2]) % image.shape[1]]
    volume = np.ascontiguousarray(volume, dtype=np.float32)
    sites = colour_classes(shape, window)[0]
    out = np.empty((len(sites), len(VIEWS)), dtype=np.float32)
    ref = matmul_gflops()
    ref_core = sgemm_cpu_gflops()
    floor = 2.0 * n * d * len(sites) * len(VIEWS)
    print(f"distance stage: exemplar {exemplar} ({len(labels)} labels), {window}x{window}, "
          f"{len(sites):,} sites x {len(VIEWS)} views, n = {n:,}, d = {d}; floor "
          f"2 n d = {2 * n * d / 1e3:,.0f} kFLOP per voxel-view; {load()}")
    print(f"float32 matmul 1024^2: {ref:.1f} GFLOP/s wall ({thread_count()} threads); "
          f"{ref_core:.1f} GFLOP/s per CPU second on one thread")
    for regime in ("trusted", "random"):
        temps = (np.zeros(shape, np.float32) if regime == "trusted"
                 else rng.random(shape).astype(np.float32))
        with single_threaded_blas():
            t_gemm = best_of(lambda: sites_best_distances(volume, temps, sites, models, ops, out),
                             repeats)
        t_direct = best_of(lambda: sites_best_distances(volume, temps, sites, models, None, out),
                           repeats)
        for name, (wall, cpu) in (("gemm", t_gemm), ("direct", t_direct)):
            rate, rate_cpu = floor / wall / 1e9, floor / cpu / 1e9
            print(f"  {regime:8s} {name:6s} wall {wall * 1e3:7.1f} ms {rate:6.1f} GFLOP/s, ratio "
                  f"{rate / ref:.3f} | CPU {cpu * 1e3:7.1f} ms {rate_cpu:6.1f} GFLOP/s per CPU "
                  f"second, ratio {rate_cpu / ref_core:.3f}")
        print(f"  {regime:8s} gemm speed-up over direct: wall {t_direct[0] / t_gemm[0]:.2f}x, "
              f"CPU {t_direct[1] / t_gemm[1]:.2f}x")


def figure4(size: int, paths: list[str]) -> None:
    ex = npmrf3d.load_exemplar(data.path("gravel64"))
    npmrf3d.synthesize(ex, size=8, window=3, levels=1, variant="sharp", rng=0)  # JIT warm-up
    original = RELAXATIONS["icm"]
    try:
        for path in paths:
            RELAXATIONS["icm"] = Relaxation(functools.partial(original.run, distances=path),
                                            original.options)
            before = load()
            t0, c0 = time.perf_counter(), time.process_time()
            res = npmrf3d.synthesize(ex, size=size, window=7, levels=3, heuristic="ML_H2b",
                                     upsample="8/8", inherit="resynth", xi=-3.0, stop=0.95,
                                     variant="sharp", rng=0)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            evaluations = sum(st["evaluations"] for st in res.stats["levels"].values())
            levels = ", ".join(f"{res.timings[k]:.1f}" for k in sorted(res.stats["levels"], reverse=True))
            print(f"Figure-4 job {size}^3, distances={path}: wall {wall:.1f} s (levels {levels} s), "
                  f"CPU {cpu:.1f} s, {evaluations:,} voxel-view evaluations, "
                  f"{res.stats['threads']} threads; before: {before}; after: {load()}")
    finally:
        RELAXATIONS["icm"] = original


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--size", type=int, default=64, help="side of the Figure-4 volume")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-job", action="store_true", help="only the distance stage")
    parser.add_argument("--paths", default="gemm,direct", help="distance paths for the job")
    parser.add_argument("--exemplar", default="gravel64", help="of the distance stage")
    parser.add_argument("--window", type=int, default=7, help="of the distance stage")
    parser.add_argument("--palette", type=int, default=None, help="of the distance stage")
    args = parser.parse_args(argv)
    print(f"hardware: {hardware()}")
    distance_stage(64, args.repeats, args.exemplar, args.window, args.palette)
    if not args.no_job:
        figure4(args.size, [p for p in args.paths.split(",") if p])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
