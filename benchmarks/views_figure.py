"""Which views to constrain: three views against two on anisotropic exemplars (docs/views.md).

For each bundled exemplar (``brick``, ``wood``: layers and lines with a direction) ``synth``'s
default makes a volume with every view constrained and one with ``--views front,top`` (the
right view free), same size and seed. Each figure row is one run: the exemplar, then a centre
slice of each view oriented like the exemplar, titled with the structure judge's ``pyramid``
score as a ratio to the floor (``npmrf3d metrics --structure``: 1 = as good as another crop of
the exemplar, lower is better). Writes ``OUT/views_<exemplar>.png`` and ``OUT/views_judge.json``
(every score, the floors, the run times) and prints a table.

Needs the structure extra (``pip install 'npmrf3d[structure]'``).

Usage::

    python benchmarks/views_figure.py                            # 64^3, brick and wood
    python benchmarks/views_figure.py --size 48 --exemplars brick
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
from npmrf3d.analysis.metrics import layout, view_slices
from npmrf3d.analysis.structure import check_installed
from npmrf3d.model.exemplar import named_exemplar
from npmrf3d.model.neighbourhood import VIEWS
from npmrf3d.plotting import to_display

EXEMPLARS = ("brick", "wood")
#: The view sets compared: every view, and the two that share the exemplar's row axis.
VIEW_SETS = {"three views": ("front", "right", "top"), "front, top": ("front", "top")}


def judge(volume, exemplar, floor, seed: int) -> dict:
    """The structure judge on every view of ``volume`` (constrained or not), ratios to ``floor``."""
    return layout.view_scores(volume, {v: exemplar for v in VIEWS}, {v: floor for v in VIEWS},
                              rng=seed)


def draw(name: str, exemplar, runs: dict, out: pathlib.Path) -> pathlib.Path:
    """One row per view set: the exemplar and each view's centre slice with its judge score."""
    fig, axes = plt.subplots(len(runs), 1 + len(VIEWS), figsize=(2.3 * (1 + len(VIEWS)), 2.5 * len(runs)),
                             squeeze=False, layout="constrained")
    lo, hi = float(exemplar.min()), float(exemplar.max())
    for row, (label, run) in zip(axes, runs.items()):
        panels = [(exemplar, f"exemplar\n{label}")]
        for view in VIEWS:
            stack = view_slices(run["volume"], view)
            state = "constrained" if view in run["views"] else "FREE"
            score = run["judge"]["per_view"][view]["to_floor"]["pyramid"]
            panels.append((stack[len(stack) // 2], f"{view} ({state})\npyramid {score:.2f} x floor"))
        for ax, (image, title) in zip(row, panels):
            ax.imshow(to_display(image, vmin=lo, vmax=hi), cmap="gray", vmin=lo, vmax=hi,
                      interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(title, fontsize=9)
    size = next(iter(runs.values()))["volume"].shape[0]
    fig.suptitle(f"{name}: {size}^3, synth's default, seed {next(iter(runs.values()))['seed']}; "
                 "slices oriented like the exemplar", fontsize=10)
    path = out / f"views_{name}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--size", type=int, default=64, help="side of the volumes")
    parser.add_argument("--exemplars", nargs="+", default=list(EXEMPLARS), help="bundled exemplar names")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="figures/views", help="folder of the figures and the record")
    args = parser.parse_args(argv)
    check_installed()
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    record = {"size": args.size, "seed": args.seed, "version": npmrf3d.__version__,
              "estimator": "pyramid (continuity in the record)", "exemplars": {}}
    print(f"structure judge, pyramid, ratio to the floor ({args.size}^3, seed {args.seed})")
    print(f"{'exemplar':9s} {'views':12s} " + " ".join(f"{v:>18s}" for v in VIEWS) + f" {'sec':>6s}")
    for name in args.exemplars:
        exemplar = named_exemplar(name)
        floor = layout.half_floor(exemplar, rng=args.seed)
        runs = {}
        for label, views in VIEW_SETS.items():
            t0 = time.perf_counter()
            volume = npmrf3d.synthesize(exemplar, size=args.size, views=views, rng=args.seed).volume
            seconds = time.perf_counter() - t0
            runs[label] = {"volume": volume, "views": views, "seed": args.seed, "seconds": seconds,
                           "judge": judge(volume, exemplar, floor, args.seed)}
            cells = " ".join(f"{runs[label]['judge']['per_view'][v]['to_floor']['pyramid']:7.2f} "
                             f"{'constrained' if v in views else 'free':>10s}" for v in VIEWS)
            print(f"{name:9s} {label:12s} {cells} {seconds:6.1f}", flush=True)
        print(f"  wrote {draw(name, exemplar, runs, out)}")
        record["exemplars"][name] = {
            "floor": floor,
            "runs": {label: {"views": list(run["views"]), "seconds": round(run["seconds"], 1),
                             "judge": run["judge"]} for label, run in runs.items()}}
    (out / "views_judge.json").write_text(json.dumps(record, indent=1))
    print(f"  wrote {out / 'views_judge.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
