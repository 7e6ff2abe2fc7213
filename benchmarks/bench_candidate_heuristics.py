"""The coherent NP-MRF sampler's decision rules at the paper's scale (docs/model.md, sections 3 and 5).

64^3 volumes, 3 levels, one seed (7), from three photographs: the bundled ``gravel64`` (grey)
and two held-out terrain photographs of Debian's extremetuxracer-data (``etr_pebbles04``,
``etr_rock06``: crop A of the quality benchmark, :data:`_quality.BY_NAME`). Runs: the four
heuristics over the candidates with ICM (ML_H2b, ML_H2a, ML_H1a, ML_H1b), and ML_H2b annealed
from ``t0 = 1.0`` with the heat-bath draw and with the Metropolis step. Measured as the
quality benchmark does (:func:`_quality.measure`, :func:`_quality.ratios`): the histogram KL,
the sliced Wasserstein distance and the autocorrelation error as ratios to the structureless
control (voxels drawn independently from the exemplar; 1.0 = no structure), and the histogram
KL itself.

Usage: ``python benchmarks/bench_candidate_heuristics.py [--out figures/heuristics_coherent]
[--exemplars gravel64,etr_pebbles04,etr_rock06]``; writes one preview PNG per run to ``--out``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from _quality import BY_NAME, ETR_HINT, measure, ratios, structureless

import npmrf3d
from npmrf3d.plotting import preview_figure, save_figure
from npmrf3d.studies.catalog import load_exemplar

SIZE, LEVELS, SEED = 64, 3, 7
RUNS = (("ML_H2b", {}), ("ML_H2a", {}), ("ML_H1a", {}), ("ML_H1b", {}),
        ("ML_H2b heat-bath t0=1", {"t0": 1.0, "sampler": "heat-bath"}),
        ("ML_H2b metropolis t0=1", {"t0": 1.0, "sampler": "metropolis"}))


def exemplar(name: str) -> np.ndarray:
    """``gravel64`` as bundled, an ``etr_*`` name as the quality benchmark's crop A."""
    if name in BY_NAME:
        if not BY_NAME[name].available():
            raise SystemExit(ETR_HINT)
        return BY_NAME[name].crops()[0]
    return np.ascontiguousarray(load_exemplar(name), dtype=np.float32)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default="figures/heuristics_coherent", help="folder for the preview PNGs")
    parser.add_argument("--exemplars", default="gravel64,etr_pebbles04,etr_rock06")
    args = parser.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"{'rule':<24} {'exemplar':<14} {'hist KL':>8} {'KL/ctl':>7} {'SW/ctl':>7} {'ac/ctl':>7} {'seconds':>8}")
    for name in args.exemplars.split(","):
        ex = exemplar(name)
        control = measure(ex, structureless(ex, SIZE, np.random.default_rng(SEED)))
        for label, options in RUNS:
            heuristic = label.split()[0]
            t = time.perf_counter()
            res = npmrf3d.coherent_synthesize(ex, size=SIZE, levels=LEVELS, heuristic=heuristic, rng=SEED,
                                              **options)
            seconds = time.perf_counter() - t
            row = measure(ex, res.volume)
            ratio = ratios(row, control)
            print(f"{label:<24} {name:<14} {row['hist_kl']:8.4f} {ratio['hist_kl']:7.2f} {ratio['sw']:7.2f} "
                  f"{ratio['ac']:7.2f} {seconds:8.1f}", flush=True)
            slug = label.replace(" ", "_").replace("=", "")
            fig = preview_figure(res.volume, {"front": ex}, title=f"{name}: coherent {label}")
            save_figure(fig, out / f"{name}_{slug}.png")


if __name__ == "__main__":
    main()
