"""Where a volume made from one slice loses its minority phase's connection: level by level.

For each scan of ``benchmarks/materials_scans.py`` named, the materials benchmark's exemplar
(``bench_materials``: the scan's most typical ``S^3`` crop, its middle slice, the command's
split) runs through the method ``materials`` runs (``npmrf``, on the phases or on the grey
values); the volume after every pyramid level (each pyramid the segmented preset runs) is
repeated up to ``S^3``, split at the benchmark's threshold (0.5 for phases), and judged on the
minority phase: fraction, percolation per axis, the share of the phase in its largest
face-connected piece (``largest``) and in pieces that touch both faces normal to some axis
(``spanning``), and the finite-volume relative diffusivity per axis. The real crop,
box-averaged over the same ``2^level`` blocks and split at the same threshold, is the
reference of each level.

Usage::

    python benchmarks/trace_connection.py --scans scans --names berea bone3155 polymer --seeds 7
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).parent))
import bench_materials as bm  # noqa: E402
from bench_volume_microct import typical_corner  # noqa: E402
from materials_scans import by_name  # noqa: E402

import npmrf3d  # noqa: E402
from npmrf3d.analysis import materials  # noqa: E402
from npmrf3d.model import kcoherence_engine  # noqa: E402
from npmrf3d.model.otsu import otsu_threshold  # noqa: E402


def connection(ind: np.ndarray, diffusivity: bool = True) -> dict:
    """The minority phase's connection statistics of an indicator (see the module docstring)."""
    labels = materials._face_labels(ind)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    total = max(int(ind.sum()), 1)
    spanning = np.unique(np.concatenate([materials._spanning(labels, a) for a in range(3)]))
    out = {"fraction": float(ind.mean()), "perc": [bool(materials._spanning(labels, a).size) for a in range(3)],
           "pieces": int((sizes > 0).sum()), "largest": float(sizes.max()) / total,
           "spanning": float(sizes[spanning].sum()) / total}
    out["diff"] = [materials.relative_diffusivity(ind, axis=a) if diffusivity else float("nan") for a in range(3)]
    return out


def up(volume: np.ndarray, side: int) -> np.ndarray:
    """A coarse level's volume with each voxel repeated up to ``side^3``."""
    f = side // volume.shape[0]
    return np.repeat(np.repeat(np.repeat(volume, f, 0), f, 1), f, 2)


def box(volume: np.ndarray, level: int) -> np.ndarray:
    """The mean over ``2^level``-voxel cubes (the exemplars' down-sampling, in 3D)."""
    f = 2 ** level
    n = volume.shape[0] // f
    return volume[:n * f, :n * f, :n * f].reshape(n, f, n, f, n, f).mean(axis=(1, 3, 5))


def row(label: str, c: dict) -> str:
    return (f"| {label} | {c['fraction']:.3f} | {' '.join(str(int(p)) for p in c['perc'])} | {c['pieces']} | "
            f"{c['largest']:.3f} | {c['spanning']:.3f} | " + " / ".join(f"{d:.3f}" for d in c["diff"]) + " |")


def trace(name: str, folder: pathlib.Path, side: int, seed: int, options: dict, split: str,
          save: pathlib.Path | None = None) -> None:
    scan = by_name(name)
    volume = np.load(folder / f"{name}.npy").astype(np.float32)
    a, b, c = typical_corner(volume, side // 2, side)
    crop = volume[a:a + side, b:b + side, c:c + side]
    threshold = 0.5 if scan.binary else float(otsu_threshold(crop))
    above = float((crop > threshold).mean()) <= 0.5
    phase = (lambda v: v > threshold) if above else (lambda v: v <= threshold)
    captured = []
    original = kcoherence_engine.KCoherenceLevels.after_level

    def after_level(self, level, state, rng):
        captured.append((self.levels, level, self.colours(state.volume)[..., 0].copy()))
        return original(self, level, state, rng)

    kcoherence_engine.KCoherenceLevels.after_level = after_level
    try:
        exemplar, views = bm.exemplars_for(crop, scan.isotropic)
        exemplar, views, values, order = bm.as_phases(exemplar, views, threshold, split)
        result = npmrf3d.synthesize(None if views else exemplar, method="npmrf", size=side, rng=seed,
                                    **views, **options)
    finally:
        kcoherence_engine.KCoherenceLevels.after_level = original
    cut = threshold if order == "after" else 0.5  # the phases 0/1 (averaged at coarse levels) split at 0.5
    kept = result.stats.get("levels_kept")
    print(f"\n{name} seed {seed}: split {order}, threshold {threshold:.3f}, levels run "
          f"{sorted({c[0] for c in captured}, reverse=True)}, kept {kept}; options {options}")
    print("| volume | fraction | perc | pieces | largest | spanning | diffusivity 0 / 1 / 2 |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for level in range(max(c[1] for c in captured), -1, -1):
        ref = box(crop, level) > threshold if above else box(crop, level) <= threshold
        print(row(f"real crop, {2 ** level}-voxel blocks", connection(up(ref, side))), flush=True)
    for levels, level, vol in captured:
        ind = vol > cut if above else vol <= cut  # phase 1: above the threshold
        print(row(f"pyramid of {levels}, level {level} ({vol.shape[0]}^3)", connection(up(ind, side))), flush=True)
    final = result.volume[..., 0]
    ind = phase(values[(final > threshold).astype(np.int64)] if order == "after" else
                values[np.rint(final).astype(np.int64)])
    print(row("volume kept, as judged", connection(ind)), flush=True)
    if save is not None:  # every level's volume, repeated up to size^3, in the order of the rows
        save.mkdir(parents=True, exist_ok=True)
        np.save(save / f"{name}-{seed}.npy", np.array([up(v, side).astype(np.float32) for _, _, v in captured]))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scans", default="scans")
    p.add_argument("--names", nargs="+", default=["berea", "bone3155", "polymer"])
    p.add_argument("--seeds", type=int, nargs="+", default=[7])
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--split", default="auto", choices=("auto", "before", "after"))
    p.add_argument("--option", action="append", default=[], metavar="KEY=VALUE",
                   help="an option of npmrf's configuration (repeatable)")
    p.add_argument("--save", default=None, help="folder for every level's volume (NAME-SEED.npy)")
    args = p.parse_args(argv)
    options = bm.method_options([f"npmrf:{o}" for o in args.option]).get("npmrf", {})
    for name in args.names:
        for seed in args.seeds:
            trace(name, pathlib.Path(args.scans), args.size, seed, options, args.split,
                  None if args.save is None else pathlib.Path(args.save))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
