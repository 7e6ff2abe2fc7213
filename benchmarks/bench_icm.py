"""Speed benchmark: the paper's Figure-4 ICM job.

64^3 grey volume, 64x64 exemplar (the bundled gravel crop), 7x7 windows, 3 levels, ICM,
ML_H2b, 8/8 up-sampling, resynth, xi = -3, stop at 95 %. Prints the wall time per level,
voxel-view LCPDF evaluations per second, the neighbour-distance FLOP rate of the kernel and its
ratio to a float32 matrix multiply measured in the same run, and the hardware.
The paper's C++ took hours for such jobs; the first bar here is under 2 minutes on 2 cores.

Usage: ``python benchmarks/bench_icm.py [--size 64] [--variant default]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import hardware, matmul_gflops

import npmrf3d
from npmrf3d import data


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--preset", default="tuned", choices=sorted(npmrf3d.PRESETS),
                        help="the full-Parzen support's decision rule; the "
                             "coherent sampler, synth's default, is timed by `npmrf3d synth "
                             "--size 64` and benchmarks/bench_scaling.py")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    ex = npmrf3d.load_exemplar(data.path("gravel64"))
    # warm the JIT up (compiled code is cached on disk after the first run)
    npmrf3d.synthesize(ex, size=8, window=3, levels=1, rng=0)
    print(f"hardware: {hardware()}")
    print(f"job: {args.size}^3 grey, exemplar {ex.shape[0]}x{ex.shape[1]}, 7x7, 3 levels, ICM, "
          f"ML_H2b, 8/8, resynth, xi=-3, stop at 95 %, preset {args.preset}")
    t0 = time.perf_counter()
    res = npmrf3d.synthesize(ex, size=args.size, window=7, levels=3, heuristic="ML_H2b",
                             upsample="8/8", inherit="resynth", xi=-3.0, stop=0.95,
                             support="full", preset=args.preset, rng=args.seed)
    wall = time.perf_counter() - t0
    flops = 0.0
    evaluations = 0
    m = 7 * 7 - 1
    for level in sorted(res.stats["levels"], reverse=True):
        st = res.stats["levels"][level]
        n = np.mean([v["n"] for v in st["views"].values()])
        level_flops = 3.0 * st["evaluations"] * n * m * ex.shape[2]
        flops += level_flops
        evaluations += st["evaluations"]
        sec = res.timings[level]
        print(f"{level}: {st['shape'][0]}^3, {st['sweeps']} sweeps, {st['evaluations']:,} evaluations, "
              f"{sec:7.2f} s, {st['evaluations'] / sec:,.0f} evaluations/s")
    ref = matmul_gflops()
    rate = flops / wall / 1e9
    print(f"total wall time {wall:.1f} s; {evaluations / wall:,.0f} voxel-view evaluations/s")
    print(f"kernel {rate:.1f} GFLOP/s (neighbour distances) vs float32 matmul {ref:.1f} GFLOP/s: "
          f"ratio {rate / ref:.3f}")
    print(f"versus the paper's ~48 h for its slowest job: {48 * 3600 / wall:,.0f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
