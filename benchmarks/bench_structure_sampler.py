"""Does the default sampler keep the structure of structured photographs? (docs/structure.md)

The photographs of the structure judge's validation (``bench_structure_judge.PHOTOS``, the
set choices are made on) and its check set (``bench_structure_judge.CHECK``, kept out of every
choice), halved to 128 x 128 as the quality benchmark does; crop A (top-left 64 x 64) is the
exemplar, the crops B are the floor (``--crop 128``: the same crops of the full photograph, at
twice the pixels). Per photograph, variant and seed, one 64^3 volume (or
``--size``) from crop A, and:

* ``layout``: the judge's ``pyramid`` estimator per axis (:func:`npmrf3d.analysis.structure.structure_scores`,
  8 slices per axis), as a ratio to the floor's (the crops B scored the same way; 1 = as good
  as another crop), and its mean over the constrained axes (every axis, unless the variant
  constrains two views: the free axis is marked and left out of the mean);
* ``ends``: line ends per skeleton pixel of the slices' thin dark lines (black top-hat at the
  exemplar's Otsu split, :func:`npmrf3d.analysis.structure.line_features`), pooled over the
  slices, as a ratio to the exemplar's (1 = lines as long as the exemplar's; the floor's crops
  are given as ``floor ends``);
* ``ac``, ``hkl``: the quality benchmark's pooled short-lag autocorrelation error (ratio to the
  structureless control) and histogram KL (``_quality.measure``);
* ``s``: seconds of the synthesis alone (wall; the JSON rows also hold its CPU seconds, which a
  busy machine distorts less).

Variants (:data:`VARIANTS`) are the default run (``npmrf3d.synthesize``) or the default's
coherent options with fields replaced (``_quality._npmrf_coherent_with``; ``views-front-top``
and the other pairs constrain two views); ``--trace`` also
judges the volume after every level (coarse levels repeated up to the full size) and after
each iteration's search (each voxel given its front, right and top matches' texels) against
the solved volume.

Usage: ``python benchmarks/bench_structure_sampler.py [--variants default,...] [--set
validation|check|all] [--photos pave01,rock06] [--seeds 0,1,2] [--size 64] [--png DIR]
[--trace] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np
from _common import hardware
from _quality import ETR_HINT, Exemplar, measure, structureless
from bench_structure_judge import CHECK, PHOTOS

import npmrf3d
from npmrf3d.analysis import structure
from npmrf3d.analysis.metrics import view_slices
from npmrf3d.model.otsu import otsu_threshold

SETS = {"validation": PHOTOS, "check": CHECK}
AXES = (0, 1, 2)


def _default(ex, size, levels, seed):
    return npmrf3d.synthesize(ex, size=size, levels=levels, rng=seed).volume


#: name -> (exemplar, size, levels, seed) -> volume.
VARIANTS = {
    "default": _default,
}


def _with(**replaced):
    """The default's coherent options (``npmrf._coherent_options``) with ``replaced`` fields,
    run by ``coherent_synthesize`` given only the fields that differ from its own defaults."""
    def run(ex, size, levels, seed):
        from npmrf3d.methods import npmrf, npmrf_coherent, npmrf_options
        config = npmrf.make_config(size=size, levels=levels)
        per_view = {v: ex for v in config.views}
        config = npmrf_options.settle(config, per_view)
        options = npmrf._coherent_options(config, npmrf.segmented(config, per_view),
                                          replaced.get("levels", config.levels))
        options = dataclasses.replace(options, **replaced).to_dict()
        base = npmrf_coherent.DEFAULTS.to_dict()
        fields = {k: v for k, v in options.items() if k not in ("size", "seed") and v != base[k]}
        if not fields.get("t0"):
            fields = {k: v for k, v in fields.items() if k not in ("t_end", "schedule", "sampler")}
        return npmrf_coherent.coherent_synthesize(ex, size=size, rng=seed, **fields).volume
    return run


#: variant -> the axes whose slices its run constrains (absent: all three)
CONSTRAINED: dict[str, tuple[int, ...]] = {}


def add_variant(name: str, **replaced) -> None:
    """Register the default's coherent options with ``replaced`` fields as ``name`` (a
    ``views`` field leaves the other axes free: their slices are scored apart)."""
    VARIANTS[name] = _with(**replaced)
    if "views" in replaced:
        CONSTRAINED[name] = tuple(a for a in AXES if structure.AXIS_VIEWS[a] in replaced["views"])


add_variant("coherent-default")
#: the default without the line-distance channel (the sampler before it)
add_variant("colours-only", feature_weight=0.0)
add_variant("levels4", levels=4, window=(7, 7, 7, 7), iterations=(4, 4, 4, 3))
add_variant("coarse9", window=(9, 7, 7))
add_variant("coarse11", window=(11, 7, 7))
add_variant("coarse9-mid9", window=(9, 9, 7))
add_variant("k1", k=1)
add_variant("k2", k=2)
add_variant("random0", random_candidates=0)
#: every site searched and voting (the default's sparse sites: every 2nd voxel)
add_variant("grid1", grid=1)
add_variant("grid1-feat-dark-1", grid=1, feature_weight=1.0)
#: two constrained views (docs/views.md): front and top share the exemplar's row axis, so an
#: exemplar whose rows and columns differ asks for a structure that exists; the right view is free
add_variant("views-front-top", views=("front", "top"))
add_variant("views-front-right", views=("front", "right"))
add_variant("views-right-top", views=("right", "top"))


def neighbourhood_pca(grey: np.ndarray, dims: int, side: int = 5) -> np.ndarray:
    """The leading ``dims`` principal components of every pixel's ``side x side`` neighbourhood
    (reflected at the borders), ``(H, W, dims)``: Lefebvre & Hoppe 2006's appearance space."""
    from numpy.lib.stride_tricks import sliding_window_view
    r = side // 2
    padded = np.pad(grey, r, mode="reflect")
    patches = sliding_window_view(padded, (side, side)).reshape(grey.size, -1).astype(np.float64)
    patches -= patches.mean(axis=0)
    _, vecs = np.linalg.eigh(patches.T @ patches)
    return (patches @ vecs[:, ::-1][:, :dims]).reshape(*grey.shape, dims)


def augmented(features, weight: float, **replaced):
    """The default (or the default's coherent options with ``replaced`` fields) run on the
    exemplar with extra channels ``features(grey)`` (each scaled to ``weight`` times the
    colours' spread) for matching and deciding; the volume keeps the colour channels."""
    inner = _with(**replaced) if replaced else _default

    def run(ex, size, levels, seed):
        grey = ex.mean(axis=-1)
        extra = features(grey).reshape(*grey.shape, -1).astype(np.float64)
        extra = (extra - extra.mean(axis=(0, 1))) / np.maximum(extra.std(axis=(0, 1)), 1e-9)
        extra *= weight * float(ex.std())
        both = np.concatenate([ex, extra.astype(np.float32)], axis=-1)
        return inner(np.ascontiguousarray(both), size, levels, seed)[..., :ex.shape[-1]]
    return run


for _w in (0.5, 1.0, 2.0):
    add_variant(f"feat-dark-{_w:g}", feature_weight=_w)
    add_variant(f"views-front-top-feat-dark-{_w:g}", views=("front", "top"), feature_weight=_w)
    VARIANTS[f"pca2-{_w:g}"] = augmented(lambda g: neighbourhood_pca(g, 2), _w, feature_weight=0.0)


def dark_line_ends(grey_images: np.ndarray, threshold: float, width: int = 6) -> float:
    """Line ends per skeleton pixel of the thin dark lines of a stack of grey images, pooled."""
    ends = pixels = 0.0
    for grey in grey_images:
        black = structure.top_hats(grey, width)[1]
        f = structure.line_features(black, threshold)
        n = f.density * grey.size
        ends += f.ends * n
        pixels += n
    return ends / max(pixels, 1.0)


def slices_of(volume: np.ndarray, count: int = 8) -> dict[int, np.ndarray]:
    """``count`` evenly spaced grey slices perpendicular to each axis."""
    out = {}
    for axis in AXES:
        stack = view_slices(volume, structure.AXIS_VIEWS[axis])
        picks = np.linspace(0, len(stack) - 1, count).round().astype(int)
        out[axis] = stack[picks].mean(axis=-1)
    return out


class Photo:
    """Crop A, the crops B and what the scores compare with, computed once."""

    def __init__(self, name: str, side: int = 64):
        # 64: crops of the photograph halved to 128 x 128; 128: the same crops of the full
        # 256 x 256 photograph (the same content at twice the pixels, crops B still apart)
        scale = 1 if side <= 64 else 2
        photo = Exemplar(name, f"etr:{name}", "structured", held_out=True, half=scale == 1,
                         crops_b=tuple((r * scale, c * scale) for r, c in {**PHOTOS, **CHECK}[name]))
        self.name = name
        self.a, crops_b = photo.crops(side)
        self.floor = np.stack(crops_b)
        grey = self.a.mean(axis=-1)
        self.threshold = otsu_threshold(structure.top_hats(grey, 6)[1])
        self.ends_a = dark_line_ends(grey[None], self.threshold)
        self.ends_floor = dark_line_ends(self.floor.mean(axis=-1), self.threshold) / self.ends_a
        self.control = {}

    def control_measure(self, size: int) -> dict:
        if size not in self.control:
            self.control[size] = measure(self.a, structureless(self.a, size, np.random.default_rng(0)))
        return self.control[size]

    def score(self, volume: np.ndarray, seed: int, pooled: bool = True,
              constrained: tuple[int, ...] | None = None) -> dict:
        """The table's scores of one volume; ``layout_mean`` over the ``constrained`` axes
        (default all three), the others kept apart as ``free``."""
        s = structure.structure_scores(volume, self.a, floor=self.floor, rng=seed)
        layout = {a: s.ratio[a]["pyramid"] / s.floor["pyramid"] for a in AXES}
        grey = slices_of(volume)
        ends = dark_line_ends(np.concatenate(list(grey.values())), self.threshold) / self.ends_a
        constrained = AXES if constrained is None else constrained
        row = {"layout": layout, "layout_mean": float(np.mean([layout[a] for a in constrained])), "ends": ends}
        if constrained != AXES:
            row["free"] = {a: layout[a] for a in AXES if a not in constrained}
        if pooled:
            m = measure(self.a, volume)
            row.update(ac=m["ac"] / self.control_measure(volume.shape[0])["ac"], hkl=m["hist_kl"])
        return row


def run_variant(photo: Photo, variant: str, size: int, levels: int,
                seed: int) -> tuple[np.ndarray, float, float]:
    t0, c0 = time.perf_counter(), time.process_time()
    volume = np.asarray(VARIANTS[variant](photo.a, size, levels, seed), dtype=np.float32)
    return volume, time.perf_counter() - t0, time.process_time() - c0


def save_png(path: Path, exemplar: np.ndarray, volume: np.ndarray) -> None:
    """Exemplar and the volume's three central slices side by side (each scaled 3x)."""
    from PIL import Image
    n = volume.shape[0] // 2
    panels = [exemplar] + [view_slices(volume, structure.AXIS_VIEWS[a])[n] for a in AXES]
    lo, hi = float(exemplar.min()), float(exemplar.max())
    gap = np.full((panels[0].shape[0], 4, exemplar.shape[-1]), hi, dtype=np.float32)
    row = np.concatenate([x for p in panels for x in (p, gap)][:-1], axis=1)
    image = np.clip((row - lo) / max(hi - lo, 1e-6) * 255, 0, 255).astype(np.uint8)
    if image.shape[-1] == 1:
        image = image[..., 0]
    Image.fromarray(image).resize((image.shape[1] * 3, image.shape[0] * 3), Image.NEAREST).save(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--variants", default="default")
    parser.add_argument("--set", choices=(*SETS, "all"), default="validation")
    parser.add_argument("--photos", help="comma-separated names instead of --set")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--size", type=int, default=64)
    parser.add_argument("--crop", type=int, default=64,
                        help="exemplar side: 64 (of the photograph halved to 128 x 128) or 128 (of the "
                             "full 256 x 256 photograph: the same content at twice the pixels)")
    parser.add_argument("--levels", type=int, help="pyramid levels (default: the sampler's own, "
                                                   "from the exemplar's and the volume's size)")
    parser.add_argument("--png", type=Path, help="write exemplar + central slices per run here")
    parser.add_argument("--json", type=Path, help="append every row to this JSON-lines file")
    parser.add_argument("--trace", action="store_true", help="judge every level and the search")
    args = parser.parse_args()
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"unknown variants {', '.join(unknown)}; known: {', '.join(VARIANTS)}")
    if not Exemplar("x", "etr:pave01", "structured").available():
        raise SystemExit(ETR_HINT)
    sets = {"all": SETS}.get(args.set, {args.set: SETS.get(args.set)})
    if args.photos:
        sets = {"photos": [n.strip() for n in args.photos.split(",")]}
    seeds = [int(s) for s in args.seeds.split(",")]
    print(f"# structure of the sampler's volumes; {hardware()}; {args.size}^3 from "
          f"{args.crop}x{args.crop}, {args.levels or 'the default'} levels, seeds {seeds}")
    if args.png:
        args.png.mkdir(parents=True, exist_ok=True)
    for set_name, names in sets.items():
        print(f"\n## {set_name}\n")
        report(list(names), variants, seeds, args)


def report(names, variants, seeds, args) -> None:
    print("layout = judge pyramid / floor's (per axis 0 1 2, mean over the constrained axes: a free "
          "axis's slices are the cross-section the constrained views imply, not the exemplar); ends = dark-line ends per "
          "skeleton pixel / exemplar's; ac = pooled ac / control's; hkl raw; mean over seeds "
          "(layout mean: min-max)\n")
    print("| photograph | variant | layout 0 / 1 / 2 | layout mean (min-max) | ends (floor) | ac | hkl | s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    totals = {v: [] for v in variants}
    for name in names:
        photo = Photo(name, args.crop)
        for variant in variants:
            rows = []
            for seed in seeds:
                volume, sec, cpu = run_variant(photo, variant, args.size, args.levels, seed)
                row = {**photo.score(volume, seed, constrained=CONSTRAINED.get(variant)), "s": sec, "cpu": cpu, "photo": name, "variant": variant,
                       "seed": seed, "size": args.size}
                rows.append(row)
                if args.png:
                    save_png(args.png / f"{name}_{variant}_s{seed}.png", photo.a, volume)
                if args.json:
                    with open(args.json, "a") as fh:
                        fh.write(json.dumps({**row, "layout": list(row["layout"].values())}) + "\n")
                if args.trace:
                    trace(photo, variant, args, seed)
            totals[variant].extend(rows)
            lay = np.mean([[r["layout"][a] for a in AXES] for r in rows], axis=0)
            means = [r["layout_mean"] for r in rows]
            free = set(AXES) - set(CONSTRAINED.get(variant, AXES))
            print(f"| {name} | {variant} | {' / '.join(f'{x:.2f}' + ' free' * (a in free) for a, x in enumerate(lay))} | {np.mean(means):.2f} "
                  f"({min(means):.2f}-{max(means):.2f}) | {np.mean([r['ends'] for r in rows]):.2f} "
                  f"({photo.ends_floor:.2f}) | {np.mean([r['ac'] for r in rows]):.3f} | "
                  f"{np.mean([r['hkl'] for r in rows]):.4f} | {np.mean([r['s'] for r in rows]):.1f} |",
                  flush=True)
    print("\n| variant | layout mean | worst photo (mean over seeds) | photos above 1.25 | ends mean | ac mean | hkl mean | s mean |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for variant, rows in totals.items():
        per_photo = {}
        for r in rows:
            per_photo.setdefault(r["photo"], []).append(r["layout_mean"])
        photo_means = {p: float(np.mean(v)) for p, v in per_photo.items()}
        worst = max(photo_means, key=photo_means.get)
        print(f"| {variant} | {np.mean(list(photo_means.values())):.3f} | {worst} {photo_means[worst]:.2f} | "
              f"{sum(v > 1.25 for v in photo_means.values())} | {np.mean([r['ends'] for r in rows]):.2f} | "
              f"{np.mean([r['ac'] for r in rows]):.3f} | {np.mean([r['hkl'] for r in rows]):.4f} | "
              f"{np.mean([r['s'] for r in rows]):.1f} |", flush=True)


def trace(photo: Photo, variant: str, args, seed: int) -> None:
    """Judge the volume after every level and every iteration's search (default options)."""
    from npmrf3d.model import kcoherence_engine, kcoherence_pass
    captured = []
    original_relax, original_iterate = kcoherence_engine.KCoherenceLevels.relax, kcoherence_pass.LevelPass.iterate

    def iterate(self, rng, it):
        original_iterate(self, rng, it)
        searched = search_volume(self)
        captured.append((f"L{self.engine.config.levels - 1 - self.li} it{it} search", searched))
        captured.append((f"L{self.engine.config.levels - 1 - self.li} it{it} solved", self.state.volume.copy()))

    kcoherence_pass.LevelPass.iterate = iterate
    try:
        run_variant(photo, variant, args.size, args.levels, seed)
    finally:
        kcoherence_pass.LevelPass.iterate, kcoherence_engine.KCoherenceLevels.relax = original_iterate, original_relax
    for label, volume in captured:
        f = args.size // volume.shape[0]
        full = np.repeat(np.repeat(np.repeat(volume, f, 0), f, 1), f, 2)
        row = photo.score(full, seed, pooled=False)
        per_axis = " / ".join(f"{row['layout'][a]:.2f}" for a in AXES)
        print(f"    trace {photo.name} seed {seed} {label}: layout {per_axis} mean "
              f"{row['layout_mean']:.2f}, ends {row['ends']:.2f}", flush=True)


def search_volume(level_pass) -> np.ndarray:
    """Each voxel's texel as the last search's matches put it: per view, the site of the nearest
    searched window that holds the voxel proposes its match's texel at the voxel's offset; the
    voxel takes the views' central texel (:func:`npmrf3d.model.kcoherence_engine.initial_colours`)."""
    from npmrf3d.model.kcoherence_engine import initial_colours
    from npmrf3d.model.neighbourhood import VIEW_AXES
    srcs = []
    for vi, model in enumerate(level_pass.vmodels):
        assign = level_pass.assign[vi]
        ra, ca = VIEW_AXES[level_pass.engine.views[vi]]
        h, w = model.exemplar.shape[:2]
        shape = assign.shape
        grid = np.indices(shape)
        site = [g.copy() for g in grid]
        g = level_pass.config.grid
        site[ra] = (grid[ra] // g) * g
        site[ca] = (grid[ca] // g) * g
        centre = assign[tuple(site)]
        dr, dc = grid[ra] - site[ra], grid[ca] - site[ca]
        row = np.clip(centre // w + dr, 0, h - 1)
        col = np.clip(centre % w + dc, 0, w - 1)
        srcs.append((row * w + col).astype(np.int32))
    return initial_colours(np.stack(srcs), [m.exemplar for m in level_pass.vmodels])


if __name__ == "__main__":
    main()
