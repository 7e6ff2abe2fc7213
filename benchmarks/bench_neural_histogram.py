"""Quality of the neural method's value-histogram loss term and calibration map.

For each exemplar (top-left ``--crop`` pixels) and each ``--weights`` value of
``histogram_weight``, trains the paper's generator for ``--steps`` steps (seed 0, same slice
positions for every weight), generates a ``--size``^3 volume and measures it with
:func:`npmrf3d.analysis.metrics.evaluate` (histogram KL, autocorrelation L2, orientation KL, patch
sliced Wasserstein; lower is better), with NP_K (:func:`npmrf3d.kopf_synthesize`, seed 0, 2
levels, window 8) on the same exemplar and size as the reference. Every trained model is measured
twice: its raw output (``neural w=X``) and through its calibration map (``neural w=X calibrated``,
the default: the same network, values mapped onto the exemplar's quantiles along the principal
components of its colours, one component of a grey exemplar). Writes ``OUT.json`` (numbers,
timings, value ranges) and ``OUT.png`` (each exemplar, then the middle front slice of every
volume).

Usage: ``OMP_NUM_THREADS=1 python benchmarks/bench_neural_histogram.py [--exemplars gravel64 lawn
grass] [--weights 0 1] [--steps 100] [--size 32] [--levels 2] [--out figures/neural_histogram]``
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402
from _common import hardware  # noqa: E402

from npmrf3d import kopf_synthesize
from npmrf3d.analysis import metrics
from npmrf3d.methods import neural  # noqa: E402
from npmrf3d.model.exemplar import named_exemplar  # noqa: E402


def _scores(volume, exemplar) -> dict:
    views = ("front", "right", "top")
    return metrics.evaluate(volume, {v: exemplar for v in views}, views=list(views))["mean"]


def _figure(report, pictures, args, out) -> None:
    columns = ["exemplar", "NP_K", *[f"neural w={w:g}{c}" for w in args.weights for c in ("", " calibrated")]]
    fig, axes = plt.subplots(len(list(pictures)), len(columns), squeeze=False,
                             figsize=(2.2 * len(columns), 2.4 * len(list(pictures))))
    for r, name in enumerate(list(pictures)):
        for c, label in enumerate(columns):
            image = pictures[name][label]
            if label != "exemplar":
                image = image[:, :, image.shape[2] // 2]  # a front (i, j) slice
            ax = axes[r, c]
            ax.imshow(np.clip(image[..., 0] if image.shape[-1] == 1 else image, 0, 1),
                      cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            kl = "" if label == "exemplar" else f"\nhist KL {report['runs'][name][label]['histogram_kl']:.3f}"
            ax.set_title(f"{name}: {label}{kl}" if c == 0 else f"{label}{kl}", fontsize=7)
    fig.tight_layout()
    fig.savefig(f"{out}.png", dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--exemplars", nargs="+", default=["gravel64", "lawn", "grass"])
    parser.add_argument("--weights", nargs="+", type=float, default=[0.0, 1.0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--crop", type=int, default=64)
    parser.add_argument("--size", type=int, default=32)
    parser.add_argument("--levels", type=int, default=2, help="NP_K's pyramid levels")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", default="figures/neural_histogram")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    report = {"hardware": hardware(), "torch": torch.__version__, "threads": torch.get_num_threads(),
              "load_average_start": os.getloadavg()[0], "steps": args.steps, "crop": args.crop,
              "size": args.size, "levels": args.levels, "runs": {}}
    pictures = {}
    for name in args.exemplars:
        exemplar = named_exemplar(name, args.crop)
        pictures[name] = {"exemplar": exemplar}
        t0 = time.perf_counter()
        npk = kopf_synthesize(exemplar, size=args.size, levels=args.levels, window=8, rng=0).volume
        entry = {"NP_K": {**_scores(npk, exemplar), "seconds": time.perf_counter() - t0,
                          "range": [float(npk.min()), float(npk.max())]}}
        pictures[name]["NP_K"] = npk
        for weight in args.weights:
            t0 = time.perf_counter()
            model = neural.train(exemplar, iterations=args.steps, rng=0, seed=0, histogram_weight=weight)
            train_seconds = time.perf_counter() - t0
            calibration, model.calibration = model.calibration, None
            for suffix in ("", " calibrated"):
                t1 = time.perf_counter()
                volume = neural.generate(model, (0, 0, 0), args.size)
                t2 = time.perf_counter()
                label = f"neural w={weight:g}{suffix}"
                entry[label] = {**_scores(volume, exemplar), "train_seconds": train_seconds,
                                "generate_seconds": t2 - t1, "loss_first": model.history[0],
                                "loss_last": float(np.mean(model.history[-10:])),
                                "range": [float(volume.min()), float(volume.max())]}
                pictures[name][label] = volume
                print(name, label, json.dumps(entry[label]), flush=True)
                model.calibration = calibration
        entry["exemplar_range"] = [float(exemplar.min()), float(exemplar.max())]
        print(name, "NP_K", json.dumps(entry["NP_K"]), flush=True)
        report["runs"][name] = entry
        pathlib.Path(f"{out}.json").write_text(json.dumps(report, indent=1))
        _figure(report, pictures, args, out)  # after every exemplar: an interrupted run keeps its pictures
    report["load_average_end"] = os.getloadavg()[0]
    pathlib.Path(f"{out}.json").write_text(json.dumps(report, indent=1))

    _figure(report, pictures, args, out)
    print(f"wrote {out}.json and {out}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
