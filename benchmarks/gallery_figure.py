"""The README's gallery: real exemplars beside slices and a cube of their volumes.

Each row is one bundled photograph or micrograph (its origin: ``npmrf3d/data/SOURCES.md``) and
the 64^3 volume that ``synth``'s default makes from it (seed 0): the exemplar, the three centre
slices, the cube. Writes ``--out`` (PNG) and a JSON record of the runs beside it.

Usage::

    python benchmarks/gallery_figure.py --out figures/gallery.png
"""

from __future__ import annotations

import argparse
import json
import pathlib
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

import npmrf3d
from npmrf3d.model.exemplar import named_exemplar
from npmrf3d.plotting import plot_cube, to_display

EXEMPLARS = ("gravel64", "ihc64", "brick")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--exemplars", nargs="+", default=list(EXEMPLARS), help="bundled exemplar names")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="figures/gallery.png")
    args = parser.parse_args(argv)
    rows = len(args.exemplars)
    fig = plt.figure(figsize=(10.5, 2.2 * rows))
    record = {"size": args.size, "seed": args.seed, "version": npmrf3d.__version__, "runs": {}}
    for row, name in enumerate(args.exemplars):
        exemplar = named_exemplar(name)
        t0 = time.perf_counter()
        volume = npmrf3d.synthesize(exemplar, size=args.size, rng=args.seed).volume
        record["runs"][name] = {"seconds": round(time.perf_counter() - t0, 1)}
        n = args.size // 2
        panels = [("exemplar", exemplar), ("slice across axis 0", volume[n]),
                  ("axis 1", volume[:, n]), ("axis 2", volume[:, :, n])]
        lo, hi = float(exemplar.min()), float(exemplar.max())
        for col, (title, image) in enumerate(panels):
            ax = fig.add_subplot(rows, 5, row * 5 + col + 1)
            ax.imshow(to_display(image, vmin=lo, vmax=hi), cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(title, fontsize=9)
            if col == 0:
                ax.set_ylabel(name, fontsize=9)
        cube = fig.add_subplot(rows, 5, row * 5 + 5)
        plot_cube(volume, ax=cube, vmin=lo, vmax=hi)
        cube.set_title("volume" if row == 0 else "", fontsize=9)
    fig.tight_layout()
    out = pathlib.Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=80)
    plt.close(fig)
    out.with_suffix(".json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    print(f"wrote {out} and {out.with_suffix('.json')}: " +
          ", ".join(f"{k} {v['seconds']} s" for k, v in record["runs"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
