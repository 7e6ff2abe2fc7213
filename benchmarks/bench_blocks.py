"""Volumes in blocks: equality with the volume made at once, the block rate, scaling over
workers, a cut-off Zarr run resumed, and seams.

The default sampler with ``blockwise=True`` (``npmrf3d synth --blockwise``, the sampler of
``--out VOL.zarr``) on a 64 x 64 exemplar: a crop of the bundled grey ``gravel`` photograph
(``--exemplar`` for another image), seed 0. Its levels of at most 256^3 voxels run whole, so
below 512^3 every level does; ``--whole-voxels N`` (``synth --whole-voxels``) lowers that
threshold, so that small volumes make their finer levels in blocks.
Parts (each ``--parts`` name):

* ``equal``: ``--size`` (default 128) at once and as blocks of ``--block`` (default 64), the
  blocks made one after the other in this process at 1 and at 2 numba threads: equal or not,
  and the seconds of each (the blocks' share over the whole is the cones' overlap).
* ``scaling``: the same volume into Zarr with 1 worker (every block made in this process, one
  numba thread), then on a local cluster of 2 workers of one thread: the wall time of the
  blocks after the first (the first, which also makes the shared coarse levels, runs while the
  cluster starts and is left out) and its speed-up, peak resident memory of a worker;
  ``scaling_workers.png``.
* ``resume``: the Zarr command run as a subprocess, interrupted (SIGINT) once a third of the
  blocks are done, then run again: equal to the uninterrupted volume or not.
* ``seams``: slices of the ``equal`` volume that cross block borders (the planes through the
  block corners) against slices inside blocks: the slice metrics of
  :func:`npmrf3d.analysis.metrics` (histogram KL, autocorrelation error, sliced Wasserstein
  of patches) of each set against the exemplar, and ``figures/blocks/seams.png``: a slice
  through four block corners beside the exemplar.

Prints a table and writes ``figures/blocks/blocks.json``.

Usage: ``python benchmarks/bench_blocks.py [--parts equal,scaling,resume,seams,estimate,quality]
[--size 128] [--block 64] [--estimate 512] [--big-block 192] [--whole-voxels N] [--out figures/blocks]``
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import zarr
from _common import hardware

import npmrf3d
from npmrf3d import data
from npmrf3d._kernels._jit import use_threads
from npmrf3d.analysis.metrics import autocorrelation_error, histogram_kl, sliced_wasserstein
from npmrf3d.methods import METHODS
from npmrf3d.io.zarr_blocks import block_box, block_indices
from npmrf3d.methods.blocks import block_plan, make_block, synthesize_blocks, write_zarr
from npmrf3d.model.regions import plan_region
from npmrf3d.plotting import save_figure

PARTS = ("equal", "scaling", "resume", "seams", "estimate", "quality")
#: ``--whole-voxels`` (``synth --whole-voxels``): None keeps the default's 256^3, so every level of
#: a volume up to 256^3 runs whole; a small number makes small volumes' finer levels in blocks.
WHOLE_VOXELS: int | None = None
METHOD = METHODS["npmrf"]


def exemplar(path: str | None) -> np.ndarray:
    image = npmrf3d.load_exemplar(path or data.path("gravel"))
    return np.ascontiguousarray(image[:64, :64], dtype=np.float32)


def views(image):
    return {v: image for v in ("front", "right", "top")}


def config(size: int):
    whole = {} if WHOLE_VOXELS is None else {"whole_voxels": WHOLE_VOXELS}
    return METHOD.make_config(size=size, blockwise=True, seed=0, **whole)


def part_equal(image, size: int, block: int) -> dict:
    cfg = config(size)
    out = {}
    use_threads(2)
    t0 = time.perf_counter()
    whole = METHOD.run(views(image), cfg, np.random.default_rng(cfg.seed)).volume
    out["whole_seconds"] = time.perf_counter() - t0
    for threads in (1, 2):
        use_threads(threads)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            blocks = synthesize_blocks(METHOD, views(image), cfg, block=block, start=Path(tmp) / "start.npz")
            out[f"blocks_seconds_{threads}_threads"] = time.perf_counter() - t0
        out[f"equal_{threads}_threads"] = bool(np.array_equal(blocks, whole))
    out["plan"] = block_plan(METHOD, views(image), cfg, block=block).describe()
    out["us_per_voxel_whole_2_threads"] = 1e6 * out["whole_seconds"] / size ** 3
    print(f"equal: {size}^3 at once {out['whole_seconds']:.1f} s (2 threads); blocks of {block}: "
          f"{out['blocks_seconds_1_threads']:.1f} s (1 thread, equal {out['equal_1_threads']}), "
          f"{out['blocks_seconds_2_threads']:.1f} s (2 threads, equal {out['equal_2_threads']})")
    np.save(Path(tempfile.gettempdir()) / "npmrf3d_bench_blocks_whole.npy", whole)
    return out


def _zarr(image, size: int, block: int, workers: int, out: Path) -> dict:
    cfg = config(size)
    t0 = time.perf_counter()
    summary = write_zarr(METHOD, views(image), cfg, out, block=block, record={}, workers=workers, overwrite=True)
    summary["wall_seconds"] = time.perf_counter() - t0
    return summary


def part_scaling(image, size: int, block: int, out: Path, figures: Path) -> dict:
    rows = {}
    for workers in (1, 2):
        summary = _zarr(image, size, block, workers, out / f"scaling_{workers}.zarr")
        rows[workers] = {"rest_seconds": summary["rest_seconds"], "blocks": summary["rest_blocks"],
                         "worker_peak_bytes": summary["worker_peak_bytes"], "wall_seconds": summary["wall_seconds"]}
    speedup = rows[1]["rest_seconds"] / rows[2]["rest_seconds"]
    print(f"scaling: {rows[1]['blocks']} blocks of {block} ({size}^3) after the first: 1 worker "
          f"{rows[1]['rest_seconds']:.1f} s, 2 workers {rows[2]['rest_seconds']:.1f} s, speed-up {speedup:.2f}; "
          f"worker peak {rows[2]['worker_peak_bytes'] / 2**30:.2f} GiB")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 3.2))
    seconds = [rows[w]["rest_seconds"] for w in (1, 2)]
    ax.bar(["1 worker", "2 workers"], seconds, color=["tab:gray", "tab:blue"])
    ax.axhline(seconds[0] / 2, color="k", lw=0.8, ls="--", label="ideal for 2 workers")
    ax.set_ylabel("seconds")
    ax.set_title(f"{rows[1]['blocks']} blocks of {block} ({size}^3): speed-up {speedup:.2f}", fontsize=9)
    ax.legend(fontsize=8)
    save_figure(fig, figures / "scaling_workers.png")
    return {"workers": rows, "speedup": speedup}


def _command(size: int, block: int, out: Path, exemplar_path: str | None) -> list[str]:
    whole = [] if WHOLE_VOXELS is None else ["--whole-voxels", str(WHOLE_VOXELS)]
    return [sys.executable, "-m", "npmrf3d", "synth", exemplar_path or f"bundled:{data.DEFAULT_EXEMPLAR}",
            "--size", str(size), "--blockwise", *whole, "--block", str(block), "--workers", "2", "--seed", "0",
            "--quiet", "--out", str(out)]


def part_resume(size: int, block: int, out: Path, exemplar_path: str | None) -> dict:
    whole, cut = out / "resume_whole.zarr", out / "resume_cut.zarr"
    for path in (whole, cut):
        subprocess.run(["rm", "-rf", str(path)], check=True)
    subprocess.run(_command(size, block, whole, exemplar_path), check=True)
    blocks = len(list((whole / ".npmrf3d-done").iterdir()))
    process = subprocess.Popen(_command(size, block, cut, exemplar_path))
    done = cut / ".npmrf3d-done"
    while process.poll() is None and (not done.is_dir() or len(list(done.iterdir())) < max(1, blocks // 3)):
        time.sleep(0.2)
    process.send_signal(signal.SIGINT)
    code = process.wait()
    kept = len(list(done.iterdir()))
    subprocess.run(_command(size, block, cut, exemplar_path), check=True)
    equal = bool(np.array_equal(zarr.open_array(whole, mode="r")[...], zarr.open_array(cut, mode="r")[...]))
    print(f"resume: {size}^3 in blocks of {block} interrupted (exit {code}) with {kept} of {blocks} blocks "
          f"done, run again: equal to the uninterrupted volume {equal}")
    return {"blocks": blocks, "kept": kept, "exit": code, "equal": equal}


def part_estimate(image, size: int, block: int) -> dict:
    """The first block of ``size``^3 (which also makes the levels that run whole and the pilot)
    and the next one, made here with 2 threads; the whole volume's time on these 2 cores
    estimated as the first block plus every other at the second's time per voxel of its cone
    (the last blocks along an axis are shorter)."""
    cfg = config(size)
    use_threads(2)
    plan = block_plan(METHOD, views(image), cfg, block=block)
    seconds = []
    with tempfile.TemporaryDirectory() as tmp:
        for index in ((0, 0, 0), (0, 0, 1)):
            origin = tuple(i * block for i in index)
            t0 = time.perf_counter()
            make_block(METHOD, views(image), cfg, origin, (block,) * 3, Path(tmp) / "start.npz")
            seconds.append(time.perf_counter() - t0)
    aprons = METHOD.aprons(cfg, views(image))
    cones = [sum(int(np.prod(f.shape)) for f in plan_region(cfg.size, cfg.levels, aprons,
                                                          *block_box(i, block, cfg.size)).frames if f is not None)
             for i in block_indices(cfg.size, block)]
    cone = cones[1] if len(cones) > 1 else cones[0]
    row = {"size": size, "block": block, "blocks": plan.blocks, "first_block_seconds": seconds[0],
           "block_seconds": seconds[1], "cone_voxels": cone, "us_per_cone_voxel": 1e6 * seconds[1] / cone,
           "estimated_seconds": seconds[0] + seconds[1] * sum(cones[1:]) / cone, "plan": plan.describe()}
    print(f"estimate: {size}^3 in {plan.blocks} blocks of {block}: the first block {seconds[0]:.0f} s (the "
          f"levels made whole and the pilot), the next {seconds[1]:.1f} s ({row['us_per_cone_voxel']:.1f} us per "
          f"cone voxel); the volume about {row['estimated_seconds'] / 60:.0f} min on these 2 cores")
    return row


def part_quality(size: int, names: list[str], seed: int, figures: Path) -> dict:
    """The default at once against the block-local sampler with every level below the coarsest
    made in blocks (``whole_voxels`` 1, the pilot of 64 a part of the grid from 128^3 on), at
    ``size``^3 from the 64 x 64 crops A of held-out photographs of ``bench_quality.py``: its
    measures as ratios to the structureless control, and a slice of each beside the exemplar."""
    import _quality as q
    import matplotlib.pyplot as plt

    runs = {"default": q.METHODS["npmrf-coherent-default"], "block-local": q.METHODS["npmrf-blockwise-pilot-64"]}
    rows = {}
    fig, axes = plt.subplots(len(names), 3, figsize=(9, 3 * len(names)), squeeze=False)
    for r, name in enumerate(names):
        crop = q.BY_NAME[name].crops()[0]
        control = q.measure(crop, q.structureless(crop, size, np.random.default_rng(seed)))
        axes[r, 0].imshow(np.clip(crop, 0, 1).squeeze(), cmap="gray", vmin=0, vmax=1)
        axes[r, 0].set_title(f"{name} (held out)", fontsize=9)
        rows[name] = {}
        for c, (label, run) in enumerate(runs.items()):
            t0 = time.perf_counter()
            volume = run(crop, size, 3, seed)
            raw = q.measure(crop, volume)
            rows[name][label] = {**q.ratios(raw, control), "hist_kl_raw": raw["hist_kl"],
                                 "seconds": time.perf_counter() - t0}
            ratio = rows[name][label]
            print(f"quality {size}^3 {name} {label}: ac {ratio['ac']:.3f} okl {ratio['orient_kl']:.3f} "
                  f"sw {ratio['sw']:.3f} hist KL {raw['hist_kl']:.4f}", flush=True)
            axes[r, c + 1].imshow(np.clip(volume[size // 2], 0, 1).squeeze(), cmap="gray", vmin=0, vmax=1)
            axes[r, c + 1].set_title(f"{label}, slice x1 = {size // 2}", fontsize=9)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{size}^3 from 64 x 64, seed {seed}: the default at once and block-local (pilot 64)", fontsize=10)
    save_figure(fig, figures / f"quality_{size}.png")
    means = {label: {k: float(np.mean([rows[n][label][k] for n in names])) for k in ("ac", "orient_kl", "sw",
                                                                                     "hist_kl_raw")}
             for label in runs}
    print("quality means: " + "; ".join(f"{label} " + ", ".join(f"{k} {v:.3f}" for k, v in m.items())
                                        for label, m in means.items()))
    return {"rows": rows, "means": means}


def slice_scores(one: np.ndarray, image: np.ndarray) -> dict:
    """Histogram KL, autocorrelation error and sliced Wasserstein distance of patches of one
    slice ``(N, N, C)`` against the exemplar (a one-slice volume seen from the view whose
    slices it is)."""
    thin = one[None]
    return {"hist_kl": histogram_kl(image, thin), "autocorrelation": autocorrelation_error(image, thin, "right"),
            "sliced_wasserstein": sliced_wasserstein(image, thin, "right")}


def part_seams(image, block: int, out: Path) -> dict:
    whole = np.load(Path(tempfile.gettempdir()) / "npmrf3d_bench_blocks_whole.npy")
    n = whole.shape[0]
    borders = [i for i in range(block, n, block)]
    inside = [i + block // 2 for i in range(0, n, block)]
    rows = {}
    for name, planes in (("across block borders", borders), ("inside blocks", inside)):
        slices = [whole[i] for i in planes] + [whole[:, i] for i in planes] + [whole[:, :, i] for i in planes]
        scores = [slice_scores(one, image) for one in slices]
        rows[name] = {k: (float(np.mean([s[k] for s in scores])), float(np.std([s[k] for s in scores])))
                      for k in scores[0]}
    print("seams (mean +- sd over the slices): " + "; ".join(
        f"{name}: " + ", ".join(f"{k} {m:.4f} +- {sd:.4f}" for k, (m, sd) in r.items()) for name, r in rows.items()))
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(12, 4.3))
    lo, hi = float(image.min()), float(image.max())
    axes[0].imshow(image[..., 0], cmap="gray", vmin=lo, vmax=hi)
    axes[0].set_title("exemplar 64 x 64")
    axes[1].imshow(whole[block, :, :, 0], cmap="gray", vmin=lo, vmax=hi)
    axes[1].set_title(f"slice x1 = {block}: a block border")
    axes[2].imshow(whole[:, :, block, 0], cmap="gray", vmin=lo, vmax=hi)
    axes[2].set_title(f"slice x3 = {block}: a block border")
    for ax in axes[1:]:
        for b in borders:
            ax.axhline(b - 0.5, color="tab:red", lw=0.6, alpha=0.6)
            ax.axvline(b - 0.5, color="tab:red", lw=0.6, alpha=0.6)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(f"{n}^3 made as blocks of {block} (red: block borders; the volume equals the one made at once)")
    save_figure(fig, out / "seams.png")
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", default=",".join(PARTS))
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--block", type=int, default=64)
    parser.add_argument("--big-block", type=int, default=192)
    parser.add_argument("--estimate", type=int, default=512, help="side of the volume the estimate part times")
    parser.add_argument("--quality-size", type=int, default=128)
    parser.add_argument("--quality-exemplars", default="etr_sand01,etr_rock06,etr_pebbles04",
                        help="held-out photographs of bench_quality.py (extremetuxracer-data)")
    parser.add_argument("--exemplar", default=None)
    parser.add_argument("--whole-voxels", type=int, default=None,
                        help="levels of at most this many voxels run whole (default: the default's, 256^3)")
    parser.add_argument("--out", default="figures/blocks")
    args = parser.parse_args(argv)
    global WHOLE_VOXELS
    WHOLE_VOXELS = args.whole_voxels
    parts = [p for p in args.parts.split(",") if p]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    image = exemplar(args.exemplar)
    record = {"hardware": hardware(), "size": args.size, "block": args.block, "whole_voxels": args.whole_voxels}
    results_path = out / "blocks.json"
    if results_path.is_file():
        record = {**json.loads(results_path.read_text()), **record}
    work = Path(os.environ.get("NPMRF3D_BENCH_WORK", tempfile.gettempdir())) / "npmrf3d_bench_blocks"
    work.mkdir(parents=True, exist_ok=True)
    if "equal" in parts:
        record["equal"] = part_equal(image, args.size, args.block)
    if "scaling" in parts:
        record["scaling"] = part_scaling(image, args.size, args.block, work, out)
    if "resume" in parts:
        record["resume"] = part_resume(args.size, args.block, work, args.exemplar)
    if "seams" in parts:
        record["seams"] = part_seams(image, args.block, out)
    if "quality" in parts:
        record["quality"] = part_quality(args.quality_size, args.quality_exemplars.split(","), 7, out)
    if "estimate" in parts:
        record["estimate"] = part_estimate(image, args.estimate, args.big_block)
    results_path.write_text(json.dumps(record, indent=2, default=str) + "\n")
    print(f"wrote {results_path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
