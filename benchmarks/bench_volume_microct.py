"""From a real micro-CT scan: ``volume-lh`` makes 128^3 from a 64^3 crop,
judged against the spread of the scan's own held-out 64^3 crops.

The scan is any segmented (two-phase) volume as ``.npy`` or a TIFF stack, read as
``npmrf3d volume`` reads it. The ones measured here are not bundled (see ``docs/volume.md``,
"Real micro-CT scans"): the Imperial College Berea sandstone (400^3) and Ketton limestone (256^3)
segmented micro-CT images, as ``berea.tif`` and ``ketton.tif`` in
``data/<name>/original/raw/<name>.zip`` of github.com/LukasMosser/PorousMediaGan.

The scan is split along axis 0: the exemplar is the 64^3 crop at ``--corner`` of the first half
(``typical``: of the first half's crops at ``--stride``, the one whose grey mean and standard
deviation lie nearest the medians of those crops', in units of their spread, chosen without
looking at any result: a corner crop can be unlike the rest of a scan, as the polymer's and the
weave's are)
(``--downsample`` 2 averages 2^3 voxels first, for coarse-grained rock in a 64^3 crop), and the
real spread is every 64^3 crop of the second half (stride ``--stride``), which no run has seen.
Each volume and crop is judged at the scan's threshold (``--threshold``: 0.5 of the scaled
values by default, so the phase is the bright one, a rock's grain; several values judge each
interface of a multi-phase scan; ``otsu`` takes Otsu's threshold of the exemplar crop, for a grey
scan): volume fraction, specific surface area (marching cubes) and radial two-point correlation
S2(r), r = 0..16, each "inside" when it lies within the crops' min-max; and the volume's copy
repetition (:func:`npmrf3d.analysis.repetition.copy_repetition`: the largest share of voxels whose exemplar
coordinate recurs at one shift of 16 voxels or more), which those statistics do not see.

Usage::

    python benchmarks/bench_volume_microct.py --scan berea.tif --downsample 2 --name berea \
        --write-block berea_d2_block.npy
    npmrf3d study groundtruth --volume berea_d2_block.npy --slice-axis 0   # the 2D -> 3D part

Prints one row per (balance, start, seed) and writes ``NAME.json`` and ``NAME.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import time

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402

from npmrf3d.errors import ParameterError  # noqa: E402
from npmrf3d.methods.volume_lh import STARTS, VolumeConfig, volume_synthesize  # noqa: E402
from npmrf3d.model.exemplar3d import load_volume_exemplar  # noqa: E402
from npmrf3d.model.otsu import otsu_threshold  # noqa: E402

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from bench_volume_scan import block_mean, crops_of, inside, print_spread, report, spread_of, statistics  # noqa: E402

DEFAULT_THRESHOLD = "0.5"


def typical_corner(half: np.ndarray, stride: int, side: int = 64) -> tuple[int, int, int]:
    """The corner of the ``side^3`` crop of ``half`` (corners on the ``stride`` lattice) whose
    grey mean and standard deviation lie nearest the crops' medians, each in units of the crops'
    interquartile range (of the standard deviation, when that range is 0)."""
    corners = [(i, j, k) for i in range(0, half.shape[0] - side + 1, stride)
               for j in range(0, half.shape[1] - side + 1, stride)
               for k in range(0, half.shape[2] - side + 1, stride)]
    if not corners:
        raise ParameterError(f"the first half ({' x '.join(map(str, half.shape))}) holds no {side}^3 crop")
    moments = np.array([[float(c.mean()), float(c.std())] for c in
                        (half[i:i + side, j:j + side, k:k + side] for i, j, k in corners)])
    q1, med, q3 = np.percentile(moments, [25, 50, 75], axis=0)
    scale = np.where(q3 - q1 > 0, q3 - q1, np.maximum(moments.std(axis=0), 1e-12))
    return corners[int(np.argmin((((moments - med) / scale) ** 2).sum(axis=1)))]


def thresholds_of(spec: list[str], exemplar: np.ndarray) -> dict[str, float]:
    """Name -> threshold: ``0.5`` is "grain|pore" (the published runs' name), another number
    "above X", ``otsu`` "otsu (X)" at the exemplar's Otsu threshold."""
    out = {}
    for item in spec:
        if item == "otsu":
            t = otsu_threshold(exemplar)
            out[f"otsu ({t:.3f})"] = t
        else:
            try:
                t = float(item)
            except ValueError:
                raise ParameterError(f"--threshold takes numbers in (0, 1) or 'otsu'; got {item!r}") from None
            if not 0.0 < t < 1.0:
                raise ParameterError(f"--threshold takes numbers in (0, 1) or 'otsu'; got {item!r}")
            out["grain|pore" if item == DEFAULT_THRESHOLD else f"above {t:g}"] = t
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--scan", required=True, help="the segmented scan (.npy or TIFF stack)")
    p.add_argument("--downsample", type=int, default=1, choices=(1, 2, 4),
                   help="average this many voxels per side before cutting crops")
    p.add_argument("--corner", default="0,0,0",
                   help="corner of the exemplar crop in the first half, or 'typical' (the crop nearest the "
                        "first half's median grey mean and standard deviation)")
    p.add_argument("--stride", type=int, default=32, help="stride of the held-out crops")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--balance", type=float, nargs="+", default=[VolumeConfig.balance],
                   help="phase-histogram strengths to run (0: the phase fractions are left free)")
    p.add_argument("--start", nargs="+", default=[VolumeConfig.start], choices=STARTS,
                   help="how the coarsest level starts (volume-lh's --start)")
    p.add_argument("--threshold", nargs="+", default=[DEFAULT_THRESHOLD],
                   help="thresholds of the scaled values to judge at (numbers in (0, 1)), or 'otsu'")
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--name", default="microct", help="name of the JSON and PNG written")
    p.add_argument("--out", default="figures/volume3d")
    p.add_argument("--write-block", default=None, metavar="PATH.npy",
                   help="also save the 64^3 exemplar crop (float32 in [0, 1]) here, for "
                        "'npmrf3d study groundtruth --volume PATH.npy'")
    args = p.parse_args(argv)
    try:
        scan = load_volume_exemplar(args.scan, exemplar_kind="volume")[..., 0]
    except ParameterError as exc:
        print(f"bench_volume_microct: error: {exc}", file=sys.stderr)
        return 2
    f = args.downsample
    scan = block_mean(scan, f)
    half = scan.shape[0] // 2
    if args.corner == "typical":
        a, b, c = typical_corner(scan[:half], args.stride)
    else:
        try:
            a, b, c = (int(x) for x in args.corner.split(","))
        except ValueError:
            print(f"bench_volume_microct: error: --corner takes 'A,B,C' or 'typical'; got {args.corner!r}",
                  file=sys.stderr)
            return 2
    if a + 64 > half or b + 64 > scan.shape[1] or c + 64 > scan.shape[2]:
        print(f"bench_volume_microct: error: the 64^3 crop at {args.corner} does not fit in the first half "
              f"({half} x {scan.shape[1]} x {scan.shape[2]})", file=sys.stderr)
        return 2
    exemplar = scan[a:a + 64, b:b + 64, c:c + 64]
    try:
        thresholds = thresholds_of(args.threshold, exemplar)
    except ParameterError as exc:
        print(f"bench_volume_microct: error: {exc}", file=sys.stderr)
        return 2
    if args.write_block:
        np.save(args.write_block, exemplar.astype(np.float32))
        print(f"wrote the exemplar crop to {args.write_block}")
    crops = [statistics(crop, thresholds) for crop in crops_of(scan[half:], args.stride)]
    if len(crops) < 2:
        print("bench_volume_microct: error: the second half holds fewer than two 64^3 crops", file=sys.stderr)
        return 2
    spread = spread_of(crops)
    ex_stats = statistics(exemplar, thresholds)
    print(f"exemplar: {args.scan} crop at {(a, b, c)} (downsample {f}), " + "; ".join(
          f"{n}: fraction {ex_stats[n]['fraction']:.3f}, surface {ex_stats[n]['surface_area']:.4f}" for n in thresholds)
          + f"; {len(crops)} held-out crops")
    print_spread(spread)
    runs = []
    for balance, start, seed in [(b, t, s_) for b in args.balance for t in args.start for s_ in args.seeds]:
        t0 = time.perf_counter()
        res = volume_synthesize(exemplar[..., None], size=args.size, rng=seed, balance=balance, start=start)
        seconds = time.perf_counter() - t0
        vol = res.volume[..., 0]
        st = statistics(vol, thresholds)
        verdict = {name: {key: inside(st[name][key], *spread[name][key])
                          for key in ("fraction", "surface_area", "s2")} for name in thresholds}
        repetition = res.stats["repetition"]
        runs.append({"balance": balance, "start": start, "seed": seed, "repetition": repetition,
                     "seconds": round(seconds, 1), "statistics": st, "inside": verdict,
                     "slice": vol[:, :, args.size // 2]})
        parts = [f"fraction {st[n]['fraction']:.3f}{'' if verdict[n]['fraction'] else ' (out)'}, "
                 f"surface {st[n]['surface_area']:.4f}{'' if verdict[n]['surface_area'] else ' (out)'}, "
                 f"S2 {'inside' if verdict[n]['s2'] else 'out'}" for n in thresholds]
        print(f"balance {balance:g} start {start} seed {seed}: {seconds:.1f} s; " + "; ".join(parts)
              + f"; repetition {repetition['share']:.3f} at {repetition['shift']}", flush=True)
    out = pathlib.Path(args.out)
    record = {"scan": str(args.scan), "downsample": f, "corner": [a, b, c], "size": args.size,
              "thresholds": thresholds,
              "crops": len(crops), "stride": args.stride, "exemplar_statistics": ex_stats, "spread": spread}
    report(out, args.name, record, runs, exemplar[:, :, 32], f"exemplar: {pathlib.Path(args.scan).stem} 64³",
           lambda r: f"volume-lh {args.size}³, balance {r['balance']:g}, {r['start']}, seed {r['seed']}",
           lambda r: f"balance {r['balance']:g}, {r['start']}, seed {r['seed']}", f"{len(crops)} held-out crops")
    print(f"wrote {out / (args.name + '.json')} and {out / (args.name + '.png')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
