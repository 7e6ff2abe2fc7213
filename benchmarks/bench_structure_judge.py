"""Validation of the slice-by-slice structure judge (npmrf3d.analysis.structure, docs/structure.md).

Ten structured terrain photographs of Debian's extremetuxracer-data (GPL-2+, not in the
repository; ``apt-get install -y extremetuxracer-data``): block walls, bricks, cobbles, cracks,
veins, scratches and ridges, each halved to 128 x 128 as the quality benchmark does
(``_quality.Exemplar``). Crop A (top-left 64 x 64) is the exemplar; each row below is a set of
64 x 64 images scored by :func:`npmrf3d.analysis.structure.image_scores` against it, as ratios to
the structureless control (the exemplar's pixels drawn independently; 1 = no structure):

* ``floor``: the crops B (other 64 x 64 crops of the photograph, none overlapping A);
* ``B-tiles 16`` / ``B-tiles 8``: each crop B cut into 16 x 16 / 8 x 8 tiles, shuffled: the same
  content as the floor with its layout broken;
* ``A-tiles 16`` / ``A-tiles 8``: the exemplar itself cut into shuffled tiles (three shuffles):
  broken layout, but every tile is the exemplar's own content;
* ``blurred``: three slices of the quality benchmark's blurred control (the structureless
  control smoothed to the exemplar's grain, ``_quality.blurred``);
* ``structureless``: three fresh draws of the control.

The pooled metrics of the quality benchmark (``_quality.measure``: ``ac``, ``sw``, front view,
as ratios to a structureless volume) are printed for the same sets beside them. Last, the
judge's volume call, :func:`~npmrf3d.analysis.structure.structure_scores` with the crops B as
the floor, on the 64^3 blurred and structureless control volumes, timed.

The same tables for eight more terrain photographs (:data:`CHECK`: grainier, fewer lines),
which checked the choices made on the ten. About 5 minutes on 2 cores.

Usage: ``python benchmarks/bench_structure_judge.py [--set validation|check|all]
[--photos pave01,rock06] [--seed 0]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _common import hardware
from _quality import ETR_HINT, Exemplar, blurred, floor_volume, measure, ratios, structureless

from npmrf3d.analysis import structure
from npmrf3d.analysis.structure import shuffled_tiles

#: name -> top-left corners of the crops B (pave02 repeats every 64 rows: (64, 0) is crop A).
PHOTOS = {
    "pave01": ((64, 64), (0, 64), (64, 0)),
    "pave02": ((0, 64), (24, 64), (48, 64)),
    "icy_pave01": ((64, 64), (0, 64), (64, 0)),
    "icy_pave05": ((64, 64), (0, 64), (64, 0)),
    "pebbles01": ((64, 64), (0, 64), (64, 0)),
    "rock06": ((64, 64), (0, 64), (64, 0)),
    "rock01": ((64, 64), (0, 64), (64, 0)),
    "ice": ((64, 64), (0, 64), (64, 0)),
    "ice02": ((64, 64), (0, 64), (64, 0)),
    "rock": ((64, 64), (0, 64), (64, 0)),
}
#: Eight more terrain photographs (grainier, fewer lines), crops B as in the quality benchmark:
#: the check of the choices made on :data:`PHOTOS` (docs/structure.md, "How it was chosen").
CHECK = {name: ((64, 64), (0, 64), (64, 0)) for name in (
    "icy_pave04", "icy_rock06", "snowy_rock06", "rock02", "rock04", "rock05", "rock07", "ice01")}
SETS = {"validation": PHOTOS, "check": CHECK}
ROWS = ("floor", "B-tiles 16", "B-tiles 8", "A-tiles 16", "A-tiles 8", "blurred", "structureless")
POOLED_ROWS = ("floor", "B-tiles 16", "A-tiles 16", "A-tiles 8", "blurred")


def image_sets(a: np.ndarray, crops_b: list[np.ndarray], control: np.ndarray,
               rng: np.random.Generator) -> dict[str, list[np.ndarray]]:
    """The rows' images, each (64, 64, C)."""
    smooth = blurred(a, control)
    return {
        "floor": crops_b,
        "B-tiles 16": [shuffled_tiles(b, 16, rng) for b in crops_b],
        "B-tiles 8": [shuffled_tiles(b, 8, rng) for b in crops_b],
        "A-tiles 16": [shuffled_tiles(a, 16, rng) for _ in crops_b],
        "A-tiles 8": [shuffled_tiles(a, 8, rng) for _ in crops_b],
        "blurred": [smooth[:, :, k] for k in (0, 21, 42)],
        "structureless": [structureless(a, 64, rng)[:, :, 0] for _ in range(3)],
    }


def judge(name: str, seed: int) -> dict:
    photo = Exemplar(name, f"etr:{name}", "structured", held_out=True, half=True,
                     crops_b={**PHOTOS, **CHECK}[name])
    a, crops_b = photo.crops()
    rng = np.random.default_rng(seed)
    control = structureless(a, 64, rng)
    sets = image_sets(a, crops_b, control, rng)
    scores = {row: structure.image_scores(np.stack(images), a, rng=seed).ratio["images"]
              for row, images in sets.items()}
    pooled_control = measure(a, control, views=("front",))
    pooled = {row: ratios(measure(a, floor_volume(sets[row], 64), views=("front",)), pooled_control)
              for row in POOLED_ROWS}
    volumes = {}
    for label, volume in (("blurred", blurred(a, control)), ("structureless", control)):
        t0 = time.perf_counter()
        result = structure.structure_scores(volume, a, floor=np.stack(crops_b), rng=seed)
        volumes[label] = (result, time.perf_counter() - t0)
    return {"scores": scores, "pooled": pooled, "volumes": volumes}


#: The validation's conditions on one photograph for one score (lower is better).
CONDITIONS = {
    "floor < B-tiles 16, 8": lambda s: s["floor"] < min(s["B-tiles 16"], s["B-tiles 8"]),
    "floor < A-tiles 16, 8": lambda s: s["floor"] < min(s["A-tiles 16"], s["A-tiles 8"]),
    "floor < A-tiles 8": lambda s: s["floor"] < s["A-tiles 8"],
    "B-tiles 16, 8 < blurred, structureless":
        lambda s: max(s["B-tiles 16"], s["B-tiles 8"]) < min(s["blurred"], s["structureless"]),
    "blurred, structureless worst":
        lambda s: max(s[row] for row in ROWS[:5]) < min(s["blurred"], s["structureless"]),
}


def orderings(scores: dict[str, dict[str, float]], key: str) -> dict[str, bool]:
    """Which of :data:`CONDITIONS` hold on one photograph for the score ``key``."""
    s = {row: scores[row][key] for row in ROWS}
    return {name: bool(test(s)) for name, test in CONDITIONS.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--set", choices=(*SETS, "all"), default="all",
                        help="the ten structured photographs (validation), eight others (check)")
    parser.add_argument("--photos", help="comma-separated names of either set instead")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    chosen = {"all": SETS}.get(args.set, {args.set: SETS.get(args.set)})
    if args.photos:
        chosen = {"photos": [n.strip() for n in args.photos.split(",") if n.strip()]}
        unknown = [n for n in chosen["photos"] if n not in {**PHOTOS, **CHECK}]
        if unknown:
            raise SystemExit(f"unknown photographs {', '.join(unknown)}; known: "
                             f"{', '.join({**PHOTOS, **CHECK})}")
    if not Exemplar("x", "etr:pave01", "structured").available():
        raise SystemExit(ETR_HINT)
    print(f"# structure judge validation; {hardware()}; seed {args.seed}")
    for set_name, names in chosen.items():
        print(f"\n## {set_name}: {', '.join(names)}\n")
        report(list(names), args.seed)


def report(names: list[str], seed: int) -> None:
    """Score ``names`` and print the tables."""
    print("continuity / pyramid, ratios to the structureless control; lower is better\n")
    print("| photograph | " + " | ".join(ROWS) + " |")
    print("|" + " --- |" * (len(ROWS) + 1))
    results = {}
    for name in names:
        results[name] = judge(name, seed)
        cells = [" / ".join(f"{results[name]['scores'][row][k]:.2f}" for k in structure.ESTIMATORS)
                 for row in ROWS]
        print(f"| {name} | " + " | ".join(cells) + " |", flush=True)
    means = [" / ".join(f"{np.mean([r['scores'][row][k] for r in results.values()]):.2f}"
                        for k in structure.ESTIMATORS) for row in ROWS]
    print("| **mean** | " + " | ".join(means) + " |")

    print(f"\nOrderings met, of {len(names)} photographs:\n")
    print("| score | " + " | ".join(CONDITIONS) + " |")
    print("|" + " --- |" * (len(CONDITIONS) + 1))
    for key in structure.ESTIMATORS:
        met = [orderings(r["scores"], key) for r in results.values()]
        print(f"| {key} | " + " | ".join(str(sum(m[c] for m in met)) for c in CONDITIONS) + " |")
    failed = {name: [c for c, ok in orderings(r["scores"], "pyramid").items() if not ok]
              for name, r in results.items()}
    print("\npyramid, not met: " + ("; ".join(f"{n} ({', '.join(c)})" for n, c in failed.items() if c)
                                    or "none"))

    print("\nPooled metrics of the quality benchmark (front view), ratios to a structureless "
          "volume: ac / sw\n")
    print("| photograph | " + " | ".join(POOLED_ROWS) + " |")
    print("|" + " --- |" * (len(POOLED_ROWS) + 1))
    for name, r in results.items():
        cells = [f"{r['pooled'][row]['ac']:.2f} / {r['pooled'][row]['sw']:.2f}" for row in POOLED_ROWS]
        print(f"| {name} | " + " | ".join(cells) + " |")
    print(f"\nA broken set or the blurred control scored below the floor (better than a real "
          f"crop), photographs of {len(names)}, by the pooled metrics and by the judge:\n")
    print("| set | " + " | ".join(("ac", "sw", *structure.ESTIMATORS)) + " |")
    print("|" + " --- |" * (len(structure.ESTIMATORS) + 3))
    for row in POOLED_ROWS[1:]:
        pooled = [sum(r["pooled"][row][k] < r["pooled"]["floor"][k] for r in results.values())
                  for k in ("ac", "sw")]
        judged = [sum(r["scores"][row][k] < r["scores"]["floor"][k] for r in results.values())
                  for k in structure.ESTIMATORS]
        print(f"| {row} | " + " | ".join(str(n) for n in (*pooled, *judged)) + " |")

    print("\nstructure_scores on 64^3 control volumes (8 slices per axis, crops B as the floor): "
          "worst-axis continuity / pyramid ratios, pyramid's worst / floor, seconds\n")
    print("| photograph | blurred volume | structureless volume |")
    print("| --- | --- | --- |")
    for name, r in results.items():
        cells = [f"{res.worst['continuity']:.2f} / {res.worst['pyramid']:.2f}, "
                 f"{res.to_floor['pyramid']:.1f}x floor, {sec:.1f} s"
                 for res, sec in r["volumes"].values()]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
