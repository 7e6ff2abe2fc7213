"""Speed benchmark: Chen & Wang 2010 on the paper's job size.

128^3 colour volume from the bundled ``ihc`` exemplar (128 x 128 x 3), 3 levels, windows per
level as given (default the method's), k = 5, PCA to 20 dimensions. Prints, per level, the wall
time (search / solve), the candidates evaluated per site and view, the sites searched per
second, the thread count and the hardware. The paper: under 5-10 minutes on a 2.2 GHz CPU; the
bar here is 60 s on 2 cores.

Usage: ``python benchmarks/bench_chen_wang.py [--size 128] [--exemplar ihc] [--window 8,6,4]
[--iterations 4,4,3] [--solver medoid] [--threads 2]``

``--figure figures/chen_wang_vs_kopf.png`` instead draws Chen–Wang (its defaults) next to NP_K
(``kopf_synthesize`` defaults) on ``--figure-exemplars`` (64 x 64 top-left crops, 64^3, seed 0),
one row per method and exemplar, with the metrics relative to the structureless control in the
row labels and printed.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import hardware, matmul_gflops

import npmrf3d
from npmrf3d import data
from npmrf3d._kernels import _jit
from npmrf3d.methods.chen_wang import DEFAULTS, chen_wang_synthesize
from npmrf3d.model import kcoherence


def _ints(text):
    values = tuple(int(x) for x in text.split(","))
    return values[0] if len(values) == 1 else values


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--exemplar", default="ihc")
    parser.add_argument("--window", default=",".join(map(str, DEFAULTS.window)))
    parser.add_argument("--iterations", default=",".join(map(str, DEFAULTS.iterations)))
    parser.add_argument("--solver", default=DEFAULTS.solver)
    parser.add_argument("--threads", type=int, default=None, help="numba threads (default: all)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--save", default=None, help="also save the volume as .npy here")
    parser.add_argument("--figure", default=None, help="draw the Chen–Wang vs NP_K figure here instead")
    parser.add_argument("--figure-exemplars", default="gravel,ihc,hubble,wood")
    parser.add_argument("--figure-size", type=int, default=64)
    args = parser.parse_args(argv)
    if args.figure:
        return figure(args.figure, args.figure_exemplars.split(","), args.figure_size, args.seed)
    threads = _jit.use_threads(args.threads)
    ex = npmrf3d.load_exemplar(data.path(args.exemplar))
    window, iterations = _ints(args.window), _ints(args.iterations)
    # warm the JIT up (compiled code is cached on disk after the first run)
    chen_wang_synthesize(ex, size=16, window=4, levels=1, iterations=1, solver=args.solver, rng=0)
    print(f"hardware: {hardware()}")
    print(f"job: {args.size}^3, exemplar {args.exemplar} {ex.shape[0]}x{ex.shape[1]}x{ex.shape[2]}, "
          f"3 levels, windows {window}, iterations {iterations}, solver {args.solver}, k=5, PCA 20")
    t0 = time.perf_counter()
    res = chen_wang_synthesize(ex, size=args.size, window=window, levels=3, iterations=iterations,
                               solver=args.solver, rng=args.seed)
    wall = time.perf_counter() - t0
    for level in sorted(res.stats["levels"], reverse=True):
        st = res.stats["levels"][level]
        sec = res.timings[level]
        searched = st["sites_per_iteration"] * st["iterations"]
        print(f"{level}: {st['shape'][0]}^3, window {st['window']}, {st['iterations']} iterations, "
              f"{st['candidates_per_site']} candidates per site and view (with repeats; 8 random), PCA dims "
              f"{sorted(set(st['pca_dims'].values()))}: {sec:6.2f} s (search {st['search_seconds']:.2f} s, "
              f"{searched / st['search_seconds']:,.0f} sites/s; solve {st['solve_seconds']:.2f} s); "
              f"changed voxels {st['changed']}")
    # distinct candidates of a sample of sites of the final volume's front view
    state = res.stats["levels"]["level_0"]
    print(f"total wall time {wall:.1f} s; numba threads {threads}; bar 60 s: "
          f"{'met' if wall < 60 else 'MISSED'}; paper 5-10 min: {300 / wall:.1f}x-{600 / wall:.1f}x faster")
    print(f"exemplar pixels in use at level 0 per view: {state['exemplar_pixels_used']}")
    print(f"float32 matmul on this machine: {matmul_gflops():.1f} GFLOP/s")
    from npmrf3d.analysis.metrics import histogram_kl

    print(f"histogram KL(exemplar || volume): {histogram_kl(ex, res.volume):.4f}")
    model = kcoherence.build_level_model(ex, res.config.window[-1])
    src = np.random.default_rng(0).integers(0, ex.shape[0] * ex.shape[1], size=(8, 8, 8)).astype(np.int32)
    distinct = np.mean([len(kcoherence.candidate_set(src, "front", s, model)) for s in np.ndindex(8, 8, 8)])
    print(f"distinct candidates per site with random sources: {distinct:.1f} of {9 * (1 + 5)}")
    if args.save:
        np.save(args.save, res.volume)
    return 0


def figure(path: str, names, size: int, seed: int) -> int:
    """Chen–Wang and NP_K side by side on 64 x 64 crops of bundled exemplars (64^3, one seed)."""
    from matplotlib.figure import Figure

    from npmrf3d.analysis import metrics
    from npmrf3d.methods.kopf import kopf_synthesize
    from npmrf3d.plotting import plot_slices, save_figure, to_display

    print(f"hardware: {hardware()}")
    fig = Figure(figsize=(13, 3.1 * 2 * len(names)), layout="constrained")
    axes = fig.subplots(2 * len(names), 4)
    for e, name in enumerate(names):
        ex = npmrf3d.load_exemplar(data.path(name))[:size, :size]
        flat = ex.reshape(-1, ex.shape[2])
        control = flat[np.random.default_rng(seed).integers(0, len(flat), size=(size,) * 3)]
        base = metrics.evaluate(control, ex)["mean"]
        lo, hi = float(ex.min()), float(ex.max())
        for m, (method, run) in enumerate((("Chen–Wang", chen_wang_synthesize), ("NP_K", kopf_synthesize))):
            t0 = time.perf_counter()
            vol = run(ex, size=size, rng=seed).volume
            sec = time.perf_counter() - t0
            score = metrics.evaluate(vol, ex)["mean"]
            rel = {k: score[k] / base[k] for k in ("autocorrelation_l2", "orientation_kl", "sliced_wasserstein")}
            line = (f"{name} {method}: {sec:.0f} s, histogram KL {score['histogram_kl']:.3f}, relative to "
                    f"control: autocorrelation {rel['autocorrelation_l2']:.2f}, orientation KL "
                    f"{rel['orientation_kl']:.2f}, sliced Wasserstein {rel['sliced_wasserstein']:.2f}")
            print(line)
            row = axes[2 * e + m]
            row[0].imshow(to_display(ex, vmin=lo, vmax=hi), cmap="gray", vmin=lo, vmax=hi,
                          interpolation="nearest")
            row[0].set_xticks([])
            row[0].set_yticks([])
            row[0].set_ylabel(f"{name}: {method}", fontsize="large")
            row[0].set_xlabel(f"hist KL {score['histogram_kl']:.2f}; AC {rel['autocorrelation_l2']:.2f}, "
                              f"OKL {rel['orientation_kl']:.2f}, SW {rel['sliced_wasserstein']:.2f} x control",
                              fontsize="small")
            plot_slices(vol, axes=list(row[1:4]), vmin=lo, vmax=hi)
    fig.suptitle(f"{size}^3 volumes from {size}x{size} crops, seed {seed}: Chen–Wang (defaults) vs NP_K (defaults)")
    save_figure(fig, path)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
