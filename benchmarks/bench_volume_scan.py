"""From a real 3D scan: ``volume-lh`` makes 128^3 from the 64^3 Colin27 block,
judged against the spread of the template's own 64^3 crops.

The exemplar is the block of ``benchmarks/scan_volume.py`` (the Colin27 T1 MRI template, 1 mm,
min-max normalised). The real spread: every 64^3 crop of the whole template at 1 mm (stride 16),
normalised the same way, whose background share (below the block's Otsu threshold) lies within
±0.1 of the block's. Each volume and crop is judged at two thresholds: the block's Otsu threshold
(background | tissue) and the Otsu threshold of its tissue (grey | white matter): volume
fraction, specific surface area and radial two-point correlation S2(r), r = 0..16. A statistic
is "inside" when it lies within the crops' min-max.

Usage::

    apt-get install mricron-data && pip install nibabel
    python benchmarks/bench_volume_scan.py --usage 0 1 --start random tiled --out figures/volume3d

Prints one row per (usage, start, seed) and writes ``NAME.json`` and ``NAME.png`` into ``--out``
(``--name``, default ``colin27``); ``--corner`` takes another block of the template.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import platform
import sys
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from npmrf3d.analysis import materials  # noqa: E402
from npmrf3d.methods.volume_lh import STARTS, VolumeConfig, volume_synthesize  # noqa: E402
from npmrf3d.model.otsu import otsu_threshold  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from scan_volume import CORNER, TEMPLATE  # noqa: E402

MAX_R = 16


def normalised(block: np.ndarray) -> np.ndarray:
    return (block - block.min()) / max(float(np.ptp(block)), 1e-6)


def statistics(volume: np.ndarray, thresholds: dict[str, float]) -> dict:
    out = {}
    for name, t in thresholds.items():
        ind = volume > t
        out[name] = {"fraction": float(ind.mean()),
                     "surface_area": float(materials.specific_surface_area(ind)),
                     "s2": materials.radial_two_point(ind, max_distance=MAX_R).tolist()}
    return out


def inside(value, low, high) -> bool:
    return bool(np.all((np.asarray(value) >= np.asarray(low) - 1e-12) & (np.asarray(value) <= np.asarray(high) + 1e-12)))


def block_mean(volume: np.ndarray, factor: int) -> np.ndarray:
    """The mean of every ``factor^3`` block (the sides cut to multiples of ``factor``)."""
    if factor == 1:
        return volume
    s = [n // factor * factor for n in volume.shape]
    return volume[:s[0], :s[1], :s[2]].reshape(s[0] // factor, factor, s[1] // factor, factor,
                                               s[2] // factor, factor).mean(axis=(1, 3, 5))


def crops_of(volume: np.ndarray, stride: int, side: int = 64):
    """Every ``side^3`` crop of ``volume`` whose corner lies on the ``stride`` lattice."""
    n0, n1, n2 = volume.shape
    for i in range(0, n0 - side + 1, stride):
        for j in range(0, n1 - side + 1, stride):
            for k in range(0, n2 - side + 1, stride):
                yield volume[i:i + side, j:j + side, k:k + side]


def spread_of(crops: list[dict]) -> dict:
    """Per threshold and statistic, the crops' ``[min, max]`` (elementwise for S2)."""
    return {name: {key: [np.min([c[name][key] for c in crops], axis=0).tolist(),
                         np.max([c[name][key] for c in crops], axis=0).tolist()]
                   for key in ("fraction", "surface_area", "s2")} for name in crops[0]}


def print_spread(spread: dict) -> None:
    for name, sp in spread.items():
        print(f"  crops, {name}: fraction {sp['fraction'][0]:.3f}-{sp['fraction'][1]:.3f}, "
              f"surface area {sp['surface_area'][0]:.4f}-{sp['surface_area'][1]:.4f}")


def report(out: pathlib.Path, name: str, record: dict, runs: list[dict], exemplar_slice: np.ndarray,
           exemplar_title: str, slice_title, curve_label, crop_label: str) -> None:
    """Write ``NAME.json`` (``record`` plus the runs without their slices, threads, machine) and
    ``NAME.png`` (the exemplar's slice, each run's centre slice, and per threshold the runs' S2
    over the crops' band) into ``out``; ``slice_title(run)`` and ``curve_label(run)`` name them."""
    out.mkdir(parents=True, exist_ok=True)
    record = dict(record, runs=[{k: v for k, v in r.items() if k != "slice"} for r in runs],
                  threads=os.environ.get("NUMBA_NUM_THREADS", "all cores"),
                  machine=platform.platform(), processor=platform.processor())
    (out / f"{name}.json").write_text(json.dumps(record, indent=2))
    names = list(record["spread"])
    fig, ax = plt.subplots(1, 1 + len(runs) + len(names), figsize=(3.2 * (1 + len(runs) + len(names)), 3.4))
    ax[0].imshow(exemplar_slice, cmap="gray", vmin=0, vmax=1)
    ax[0].set_title(exemplar_title, fontsize=9)
    for i, r in enumerate(runs):
        ax[1 + i].imshow(r["slice"], cmap="gray", vmin=0, vmax=1)
        ax[1 + i].set_title(slice_title(r), fontsize=9)
    for a_ in ax[:1 + len(runs)]:
        a_.axis("off")
    rr = np.arange(MAX_R + 1)
    for a_, key in zip(ax[1 + len(runs):], names):
        a_.fill_between(rr, *record["spread"][key]["s2"], color="0.8", label=crop_label)
        for r in runs:
            a_.plot(rr, r["statistics"][key]["s2"], label=curve_label(r))
        a_.set_title(f"S2(r), {key}")
        a_.set_xlabel("r (voxels)")
        a_.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / f"{name}.png", dpi=80)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--template", default=str(TEMPLATE), help="the Colin27 NIfTI file")
    p.add_argument("--usage", type=float, nargs="+", default=[1.0],
                   help="position-histogram strengths to run (0: the paper's rule)")
    p.add_argument("--start", nargs="+", default=[VolumeConfig.start], choices=STARTS,
                   help="coarsest-level starts to run")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--stride", type=int, default=16, help="stride of the template's crops")
    p.add_argument("--corner", default=",".join(map(str, CORNER)),
                   help="corner of the 128^3 block at 0.5 mm (another block: a held-out exemplar)")
    p.add_argument("--name", default="colin27", help="name of the JSON and PNG written")
    p.add_argument("--out", default="figures/volume3d")
    args = p.parse_args(argv)
    try:
        import nibabel
    except ImportError:
        print("bench_volume_scan: error: needs nibabel (pip install nibabel)", file=sys.stderr)
        return 2
    if not pathlib.Path(args.template).is_file():
        print(f"bench_volume_scan: error: {args.template} not found: apt-get install mricron-data",
              file=sys.stderr)
        return 2
    data = np.asarray(nibabel.load(args.template).dataobj, dtype=np.float32)
    corner = tuple(int(x) for x in args.corner.split(","))
    a, b, c = corner
    block = normalised(block_mean(data[a:a + 128, b:b + 128, c:c + 128], 2))
    mm = block_mean(data, 2)
    t_bg = otsu_threshold(block)
    t_wm = otsu_threshold(block[block > t_bg])
    thresholds = {"background|tissue": t_bg, "grey|white": t_wm}
    share = float(np.mean(block <= t_bg))
    crops = []
    for raw in crops_of(mm, args.stride):
        crop = normalised(raw)
        if np.ptp(raw) > 0 and abs(float(np.mean(crop <= t_bg)) - share) <= 0.1:
            crops.append(statistics(crop, thresholds))
    spread = spread_of(crops)
    print(f"exemplar: the Colin27 block ({block.shape}, background share {share:.3f}); "
          f"{len(crops)} template crops; thresholds {t_bg:.3f} (background|tissue), {t_wm:.3f} (grey|white)")
    print_spread(spread)
    runs = []
    variants = [(usage, start) for usage in args.usage for start in args.start]
    for usage, start in variants:
        for seed in args.seeds:
            t0 = time.perf_counter()
            res = volume_synthesize(block[..., None].astype(np.float32), size=args.size, rng=seed,
                                    usage=usage, start=start)
            seconds = time.perf_counter() - t0
            vol = res.volume[..., 0]
            st = statistics(vol, thresholds)
            verdict = {name: {key: inside(st[name][key], *spread[name][key])
                              for key in ("fraction", "surface_area", "s2")} for name in thresholds}
            runs.append({"usage": usage, "start": start, "seed": seed, "seconds": round(seconds, 1), "statistics": st,
                         "inside": verdict, "slice": vol[:, :, args.size // 2]})
            parts = [f"{name}: fraction {st[name]['fraction']:.3f}{'' if verdict[name]['fraction'] else ' (out)'}, "
                     f"surface {st[name]['surface_area']:.4f}{'' if verdict[name]['surface_area'] else ' (out)'}, "
                     f"S2 {'inside' if verdict[name]['s2'] else 'out'}" for name in thresholds]
            print(f"usage {usage:g} start {start} seed {seed}: {seconds:.1f} s; " + "; ".join(parts),
                  flush=True)
    record = {"exemplar": f"Colin27 block at {corner} (0.5 mm, averaged to 1 mm), 64^3",
              "size": args.size, "crops": len(crops), "thresholds": thresholds, "spread": spread}
    report(pathlib.Path(args.out), args.name, record, runs, block[:, :, 32],
           f"exemplar: Colin27 block at {corner}",
           lambda r: f"{args.size}³, usage {r['usage']:g}, {r['start']}",
           lambda r: f"usage {r['usage']:g}, {r['start']}, seed {r['seed']}", f"{len(crops)} template crops")
    out = pathlib.Path(args.out)
    print(f"wrote {out / (args.name + '.json')} and {out / (args.name + '.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
