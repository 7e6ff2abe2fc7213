"""The neural method's picture and numbers: ``figures/neural_gravel64.png`` / ``.json``.

Generates 64^3 at the origin from a trained model, draws it beside the exemplar (centre slices
and cube), computes the metrics of :func:`npmrf3d.analysis.metrics.evaluate` for it and for NP_K
(``kopf_synthesize``, seed 0, 64^3, same exemplar), and writes four 48x48 blocks generated
apart at coordinate 10^6, put side by side, as ``*_blocks.png`` (a seam would show there).

Usage: ``npmrf3d neural train bundled:gravel64 --iterations 250 --out gravel64.pt``, then
``python benchmarks/neural_figure.py gravel64.pt --out figures/neural_gravel64``
"""

from __future__ import annotations

import argparse
import json
import time

import imageio.v3 as iio
import matplotlib
import numpy as np
import torch

matplotlib.use("Agg")

from npmrf3d import __version__
from npmrf3d.analysis import metrics
from npmrf3d.methods import neural  # noqa: E402
from npmrf3d.methods.kopf import kopf_synthesize  # noqa: E402
from npmrf3d.model.exemplar import named_exemplar  # noqa: E402
from npmrf3d.plotting import preview_figure, save_figure  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("model")
    parser.add_argument("--exemplar", default="gravel64")
    parser.add_argument("--out", default="figures/neural_gravel64")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    exemplar = named_exemplar(args.exemplar)
    model = neural.load_model(args.model)
    t0 = time.perf_counter()
    volume = neural.generate(model, (0, 0, 0), 64)
    seconds = time.perf_counter() - t0
    kopf = kopf_synthesize(exemplar, size=64, rng=0).volume
    record = {"model": {"steps": len(model.history), "loss_last": model.history[-1],
                        "train_seconds": model.timings["train"], "config": model.config.to_dict()},
              "generate_64_seconds": seconds, "npmrf3d": __version__,
              "neural": metrics.evaluate(volume, exemplar)["mean"],
              "kopf_seed0": metrics.evaluate(kopf, exemplar)["mean"],
              "value_range": {"neural": [float(volume.min()), float(volume.max())],
                              "exemplar": [float(exemplar.min()), float(exemplar.max())]}}
    with open(args.out + ".json", "w", encoding="utf-8") as handle:
        json.dump(record, handle, indent=1)
    print(json.dumps(record, indent=1))
    views = {"front": exemplar, "right": exemplar, "top": exemplar}
    title = f"neural, {len(model.history)} steps, seed {model.config.seed}"
    save_figure(preview_figure(volume, views, title=title), args.out + ".png")
    parts = [[neural.generate(model, (10**6 + i, -5000 + j, 77), (48, 48, 1))[:, :, 0, 0]
              for j in (0, 48)] for i in (0, 48)]
    far = np.kron(np.block(parts), np.ones((3, 3)))
    iio.imwrite(args.out + "_blocks.png", (np.clip(far, 0, 1) * 255).astype(np.uint8))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
