"""The coherent NP-MRF sampler's fixed iterations against ICM with per-voxel temperatures.

64^3 volumes, 3 levels, seed 7, from three photographs: the bundled gravel crop
(``bundled:gravel64``) and crop A of two held-out Extreme Tux Racer terrains (``etr_pebbles04``,
``etr_rock06``; see benchmarks/_quality.py). Every run is judged by _quality.py's measures as
ratios to the structureless control (1.0 = no better than noise, lower is better): ``ac``
(autocorrelation), ``sw`` (sliced Wasserstein); ``hist_kl`` raw (the control's, drawn from the
exemplar's pixels, is ~0). The runs: today's iterations
(``icm=False``) and ICM with ``xi`` -1 and -3, ``upsample`` 8/8 and 1/8, ``stop`` 0.95 and 1.0.
Per run the seconds, the sweeps per level and the search's seconds per sweep (ICM's search is
the trust-weighted full-dimensional distance, the iterations' the PCA one). A preview PNG per run
goes to figures/icm_coherent/, the numbers to figures/icm_coherent/results.json (finished runs
are kept and skipped when the script runs again).

Usage: ``python benchmarks/bench_coherent_icm.py [--only gravel64] [--runs iterations,icm_xi1]``
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path

import numpy as np
from _quality import BY_NAME, measure, ratios, structureless

import npmrf3d
from npmrf3d.plotting import preview_figure, save_figure
from npmrf3d.studies.catalog import load_exemplar

OUT = Path(__file__).resolve().parents[1] / "figures" / "icm_coherent"
SIZE, LEVELS, SEED = 64, 3, 7
RUNS = {
    "iterations": {"icm": False},
    "icm_xi1": {"icm": True, "xi": -1.0},
    "icm_xi3": {"icm": True, "xi": -3.0},
    "icm_xi1_up18": {"icm": True, "xi": -1.0, "upsample": "1/8"},
    "icm_xi3_up18": {"icm": True, "xi": -3.0, "upsample": "1/8"},
    "icm_xi1_stop1": {"icm": True, "xi": -1.0, "stop": 1.0},
}


def exemplars() -> dict[str, np.ndarray]:
    out = {"gravel64": np.ascontiguousarray(load_exemplar("gravel64"), dtype=np.float32)}
    for name in ("etr_pebbles04", "etr_rock06"):
        out[name] = BY_NAME[name].crops()[0]
    return out


def one_run(name: str, ex: np.ndarray, run: str, control: dict) -> dict:
    t = time.perf_counter()
    res = npmrf3d.coherent_synthesize(ex, size=SIZE, levels=LEVELS, rng=SEED, **RUNS[run])
    seconds = time.perf_counter() - t
    levels = res.stats["levels"]
    row = {"seconds": seconds, "ratio": ratios(measure(ex, res.volume), control),
           "sweeps": {k: v["iterations"] for k, v in levels.items()},
           "search_per_sweep": {k: v["search_seconds"] / max(1, v["iterations"]) for k, v in levels.items()},
           "solve_per_sweep": {k: v["solve_seconds"] / max(1, v["iterations"]) for k, v in levels.items()},
           "digest": hashlib.sha256(res.volume.tobytes()).hexdigest()[:16]}
    if "temperature" in levels.get("level_0", {}):
        row["temperature"] = {k: [round(x / v["temperature"][0], 3) if v["temperature"][0] else 0.0
                                  for x in v["temperature"]] for k, v in levels.items()}
    title = f"{name} {run}: " + ", ".join(f"{m} {row['ratio'][m]:.3f}" for m in ("ac", "sw")) + f", {seconds:.0f} s"
    save_figure(preview_figure(res.volume, {"front": ex}, title=title), OUT / f"{name}_{run}.png")
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", default=None, help="comma-separated exemplar names")
    parser.add_argument("--runs", default=",".join(RUNS), help="comma-separated run names")
    args = parser.parse_args(argv)
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / "results.json"
    results = json.loads(path.read_text()) if path.exists() else {}
    for name, ex in exemplars().items():
        if args.only and name not in args.only.split(","):
            continue
        control = measure(ex, structureless(ex, SIZE, np.random.default_rng(SEED)))
        for run in args.runs.split(","):
            key = f"{name}|{run}"
            if key not in results:
                results[key] = one_run(name, ex, run, control)
                path.write_text(json.dumps(results, indent=1))
            row = results[key]
            kl = row["ratio"]["hist_kl"] * max(control["hist_kl"], 1e-12)  # the control's is ~0: raw
            print(f"{name:14s} {run:14s} " + " ".join(f"{m} {row['ratio'][m]:.3f}" for m in ("ac", "sw"))
                  + f" hist_kl(raw) {kl:.4f}"
                  + f"  {row['seconds']:6.1f} s  sweeps {list(row['sweeps'].values())}"
                  + f"  search/sweep {[round(x, 2) for x in row['search_per_sweep'].values()]}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
