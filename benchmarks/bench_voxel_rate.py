"""The default sampler's time per voxel against the arithmetic it has to do.

``npmrf3d.synthesize`` with its defaults (the coherent NP-MRF, 7 x 7 windows, 3 levels) from a
64 x 64 crop of the bundled grey ``gravel`` photograph, seed 0, at each ``--sizes`` (after one
run that compiles the kernels), at 1 and at 2 numba threads, the fastest of ``--repeats`` runs
(the same volume each time; the fastest is the one least disturbed by the rest of the machine).
Per size and thread count: the seconds, microseconds per voxel of the volume, and the share of
the search and of the solver (the run's ``stats``).

The floor it is compared with is the arithmetic of its candidate comparisons at this machine's
rate. Per site and view and iteration, the search projects the site's window onto the PCA basis
(``2 d D`` floating-point operations, ``d`` = 49 window values, ``D`` = the PCA dimensions) and
measures each candidate's distance in the reduced space (``2 D`` per candidate); per voxel and
iteration the solver scores its ``8`` heaviest candidates against every vote (``2`` per vote and
candidate; ``3 x 49 / g**2`` votes on average with the sites every ``g`` voxels, ``3 x 49`` at
``g = 1``). Summed over the levels' voxels and iterations and divided by the
voxels of the volume, that is the floor in operations per voxel; at the machine's float32
matrix-multiply rate (BLAS, all cores: the most this machine computes per second) it is the
floor in microseconds. The ratio says how far the kernels are from it; the target of
``docs/performance.md`` is 1.6 microseconds per voxel on 2 cores.

Writes ``figures/voxel_rate.json``.

Usage: ``python benchmarks/bench_voxel_rate.py [--sizes 64,128] [--repeats 3] [--out figures]``
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from _common import hardware, matmul_gflops

import npmrf3d
from npmrf3d import data
from npmrf3d._kernels._jit import use_threads
from npmrf3d.model.kcoherence_engine import MEDOID_CANDIDATES

#: The target of docs/performance.md, microseconds per voxel on 2 cores.
TARGET_US = 1.6


def exemplar() -> np.ndarray:
    image = npmrf3d.load_exemplar(data.path("gravel"))
    return np.ascontiguousarray(image[:64, :64], dtype=np.float32)


def floor_operations(stats: dict, channels: int = 1) -> float:
    """Floating-point operations of the run's candidate comparisons (its ``stats``): the search's
    projections and reduced distances, the solver's candidate scores."""
    total = 0.0
    for level in stats["levels"].values():
        window, iterations = level["window"], level["iterations"]
        dims = max(level["pca_dims"].values())
        d = window * window * channels
        voxels = float(np.prod(level["shape"]))
        views = len(level["pca_dims"])
        search = level["sites_per_iteration"] * (2 * d * dims + 2 * dims * level["candidates_per_site"])
        solve = voxels * 2 * MEDOID_CANDIDATES * views * window * window / level["grid"] ** 2
        total += iterations * (search + solve)
    return total


def run(image, size: int, threads: int, repeats: int = 1) -> dict:
    use_threads(threads)
    seconds, result = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        this = npmrf3d.synthesize(image, size=size, rng=0)
        took = time.perf_counter() - t0
        if took < seconds:
            seconds, result = took, this
    levels = result.stats["levels"].values()
    search = sum(level["search_seconds"] for level in levels)
    solve = sum(level["solve_seconds"] for level in levels)
    return {"seconds": seconds, "us_per_voxel": 1e6 * seconds / size ** 3, "search_share": search / seconds,
            "solve_share": solve / seconds, "operations_per_voxel": floor_operations(result.stats) / size ** 3}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="64,128", help="comma-separated volume sides")
    parser.add_argument("--repeats", type=int, default=3, help="runs per size and thread count; the fastest counts")
    parser.add_argument("--out", default="figures")
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",") if s]
    image = exemplar()
    print(hardware())
    npmrf3d.synthesize(image, size=16, levels=2, rng=0)  # compile (or load) the kernels
    rate = matmul_gflops()
    print(f"float32 matmul on this machine: {rate:.1f} GFLOP/s (the floor's rate)")
    rows = []
    print(f"{'size':>5} {'threads':>7} {'seconds':>8} {'us/voxel':>9} {'search':>7} {'solve':>6} "
          f"{'floor ops/voxel':>15} {'floor us':>9} {'ratio':>6}")
    for size in sizes:
        for threads in (1, 2):
            row = {"size": size, "threads": threads, **run(image, size, threads, args.repeats)}
            row["floor_us_per_voxel"] = row["operations_per_voxel"] / (rate * 1e3)
            row["ratio_to_floor"] = row["us_per_voxel"] / row["floor_us_per_voxel"]
            rows.append(row)
            print(f"{size:>5} {threads:>7} {row['seconds']:>8.1f} {row['us_per_voxel']:>9.1f} "
                  f"{row['search_share']:>7.0%} {row['solve_share']:>6.0%} {row['operations_per_voxel']:>15,.0f} "
                  f"{row['floor_us_per_voxel']:>9.2f} {row['ratio_to_floor']:>6.0f}")
    two = [r for r in rows if r["threads"] == 2]
    best = min(r["us_per_voxel"] for r in two)
    print(f"2 threads: {best:.1f} us per voxel at best against the target {TARGET_US:g} "
          f"({'met' if best <= TARGET_US else 'missed'})")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "voxel_rate.json"
    path.write_text(json.dumps({"hardware": hardware(), "matmul_gflops": rate, "target_us": TARGET_US,
                                "rows": rows}, indent=2) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
