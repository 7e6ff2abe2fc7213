"""Where the default sampler's time goes: per level and per step, beside the arithmetic floor.

Two jobs, each the fastest of ``--repeats`` warm runs (after one run that compiles the kernels;
the volume of every profiled run is checked equal to the unprofiled one):

* ``whole``: ``npmrf3d.synthesize`` with its defaults (the coherent NP-MRF, 7 x 7, 3 levels) at
  ``--size`` (default 128) from the bundled 64 x 64 ``gravel64``, seed 0;
* ``block``: one block of side ``--block`` (default 192) of a ``--blockwise`` run of
  ``--block-size``^3 (default 512, the Zarr default), the block at grid index (0, 0, 1): the
  first block, which makes the levels that run whole and the pilot, runs once before, untimed.

The steps are timed by wrapping the engine's calls for the run (``StepClock`` of
``_common.py``), each step's own time without the wrapped calls inside it: the search kernel,
the Python around it (its rule, the energy sum), the solver kernel (votes, candidates, decision,
its histograms' updates), the position and value histograms built outside the kernel, the voxel
order (a permutation and a sort per iteration), the exemplar models (PCA, candidate lists), the
up-sampling with its initial colours, a level's set-up (packing, the NP-MRF kernel table), the
ICM bookkeeping (none in the default), the Python between the kernels in the iteration loop
(targets, rules, the smoothness prior's volume copy, the level's statistics) and, per level,
the rest of the level loop; outside the levels, the set-up and the result, and what follows a
level (a block-wise run's pilot, made by its first block only). Per step: wall and CPU
seconds, share of the run's wall time and microseconds per voxel of the output; beside the
search and solver kernels and each level, the floor of ``bench_voxel_rate.py`` (its candidate
comparisons at this machine's float32 matrix-multiply rate) and the ratio to it.

Usage: ``python benchmarks/bench_profile.py [--parts whole,block] [--size 128] [--block-size 512]
[--block 192] [--repeats 3] [--out figures]``
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import StepClock, hardware, matmul_gflops
from bench_voxel_rate import exemplar, floor_operations

import npmrf3d
from npmrf3d._kernels import kcoherence as kernels_search
from npmrf3d._kernels import kcoherence_solver as kernels_solver
from npmrf3d._kernels._jit import use_threads
from npmrf3d.methods import METHODS
from npmrf3d.methods.blocks import make_block
from npmrf3d.model import kcoherence_engine as engine
from npmrf3d.model import kcoherence_histograms as histograms
from npmrf3d.model import kcoherence_icm as icm
from npmrf3d.model import kcoherence_pass as passes

SEARCH, SOLVE = "candidate search (kernel)", "solver and votes (kernel)"
BETWEEN, REST, OUTSIDE = "Python between kernels", "rest of the level loop", "set-up and result"
#: The steps in the order printed; REST and OUTSIDE are what the wrapped calls leave of the level's and the run's time.
STEPS = (SEARCH, "search: Python around the kernel", "global matches", SOLVE, "histograms",
         "voxel order (permutation, sort)", "exemplar models (PCA, candidates)", "up-sampling, initial colours",
         "level set-up (packing, kernel table)", "ICM bookkeeping", BETWEEN, REST, "after a level (the pilot)")
ICM_METHODS = ("warm", "expected", "search_trust", "vote_trust", "visit", "cool")
BETWEEN_METHODS = ("run", "iterate", "boxes", "value_target", "solver_rule", "phase_step", "stats")


def targets(clock: StepClock) -> list:
    """What the clock wraps: (owner, attribute, step[, hook])."""
    def enter_level(_levels, level, _shape):
        clock.group = level

    def leave_level(*_):  # what follows a level (a block's last crop) is outside it
        clock.group = None

    L, P = engine.KCoherenceLevels, passes.LevelPass
    return [(kernels_search, "search_view", SEARCH), (kernels_solver, "solve", SOLVE),
            (P, "search", STEPS[1]), (P, "search_view", STEPS[1]), (P, "global_matches", STEPS[2]),
            (passes, "position_histogram", STEPS[4]), (histograms.ValueHistogram, "build", STEPS[4]),
            (P, "batch_histograms", STEPS[4]), (P, "voxel_order", STEPS[5]),
            (L, "prepare", STEPS[6], enter_level), (L, "initial", STEPS[7]), (L, "upsample", STEPS[7]),
            (L, "crop", STEPS[7]), (L, "after_level", STEPS[12], leave_level), (P, "__init__", STEPS[8]),
            (passes, "kernel_table", STEPS[8]),
            *((icm.IcmLevel, name, STEPS[9]) for name in ICM_METHODS),
            *((P, name, BETWEEN) for name in BETWEEN_METHODS), (L, "relax", BETWEEN)]


def profiled(make, repeats: int, reference: np.ndarray):
    """The fastest of ``repeats`` profiled runs of ``make()`` (which returns the result, its
    volume and its level timings): (wall, cpu, clock, result)."""
    best = None
    for _ in range(repeats):
        clock = StepClock()
        with clock.patch(targets(clock)):
            w0, c0 = time.perf_counter(), time.process_time()
            result, volume, timings = make()
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
        if not np.array_equal(volume, reference):
            raise SystemExit("the profiled volume differs from the unprofiled one")
        clock.level_seconds = {int(k.split("_")[1]): v for k, v in timings.items() if k.startswith("level_")}
        if best is None or wall < best[0]:
            best = (wall, cpu, clock, result)
    return best


def split(wall: float, cpu: float, clock: StepClock) -> dict:
    """Per level (None: outside the levels) and step, ``[wall, cpu]`` seconds, the rests included."""
    table: dict = {}
    for (group, step), seconds in clock.wall.items():
        table.setdefault(group, {})[step] = [seconds, clock.cpu[(group, step)]]
    for level, seconds in clock.level_seconds.items():
        if level not in table:  # a level read from the shared checkpoint, not run here
            continue
        steps = table[level]
        steps[REST] = [seconds - sum(w for w, _ in steps.values()), float("nan")]
    timed = [sum(w for w, _ in steps.values()) for steps in table.values()]
    timed_cpu = [sum(c for s, (_, c) in steps.items() if s != REST) for steps in table.values()]
    table.setdefault(None, {})[OUTSIDE] = [wall - sum(timed), cpu - sum(timed_cpu)]
    return table


def floors(stats: dict, levels) -> dict:
    """Per level, the floor's operations of the search and of the solver (``floor_operations``
    of ``bench_voxel_rate.py`` with the other part zeroed)."""
    out = {}
    for level in levels:
        one = stats["levels"][f"level_{level}"]
        search = floor_operations({"levels": {0: {**one, "grid": float("inf")}}})
        solve = floor_operations({"levels": {0: {**one, "sites_per_iteration": 0}}})
        out[level] = {SEARCH: search, SOLVE: solve}
    return out


def _cpu(seconds: float) -> str:
    return f"{'':>8}" if np.isnan(seconds) else f"{seconds:>8.3f}"


def report(title: str, wall: float, cpu: float, clock: StepClock, stats: dict, voxels: int, rate: float) -> dict:
    table = split(wall, cpu, clock)
    levels = sorted((g for g in table if g is not None), reverse=True)
    ops = floors(stats, levels)
    us = 1e6 / voxels
    floor_us = {lv: {s: o / (rate * 1e3) / voxels for s, o in f.items()} for lv, f in ops.items()}
    print(f"\n{title}: {wall:.2f} s wall, {cpu:.2f} s CPU, {us * wall:.2f} us per voxel "
          f"({voxels:,} voxels)")
    print(f"  {'step':<40}{'wall s':>8}{'cpu s':>8}{'share':>7}{'us/vox':>8}{'floor us':>9}{'ratio':>7}")
    rows = []
    for group in [None, *levels]:
        if group is None:
            print("  outside the levels")
        else:
            one = stats["levels"][f"level_{group}"]
            seconds = clock.level_seconds[group]
            print(f"  level {group}: {'x'.join(map(str, one['shape']))}, {one['iterations']} iterations, window "
                  f"{one['window']}, sites every {one['grid']}: {seconds:.3f} s, {seconds / wall:.1%}, "
                  f"{seconds * us:.3f} us per voxel")
        for step in [OUTSIDE, *STEPS]:
            if step not in table[group]:
                continue
            w, c = table[group][step]
            floor = floor_us.get(group, {}).get(step)
            rows.append({"level": group, "step": step, "wall": w, "cpu": c, "share": w / wall, "us_per_voxel": w * us,
                         "floor_us_per_voxel": floor})
            print(f"    {step:<38}{w:>8.3f}{_cpu(c)}{w / wall:>7.1%}{w * us:>8.3f}"
                  + ("" if floor is None else f"{floor:>9.4f}{w * us / floor:>7.0f}"))
    print("  all levels")
    for step in [OUTSIDE, *STEPS]:
        w = sum(table[g].get(step, [0.0])[0] for g in table)
        floor = sum(f.get(step, 0.0) for f in floor_us.values()) or None
        if w:
            c = sum(table[g].get(step, [0.0, 0.0])[1] for g in table)
            print(f"    {step:<38}{w:>8.3f}{_cpu(c)}{w / wall:>7.1%}{w * us:>8.3f}"
                  + ("" if floor is None else f"{floor:>9.4f}{w * us / floor:>7.0f}"))
    floor_all = sum(sum(f.values()) for f in floor_us.values())
    print(f"  floor of the whole run {floor_all:.4f} us per voxel; the run is {us * wall / floor_all:.0f} times it")
    return {"title": title, "wall": wall, "cpu": cpu, "voxels": voxels, "floor_us_per_voxel": floor_all, "rows": rows}


def job_whole(image, size: int, repeats: int, rate: float) -> dict:
    reference = npmrf3d.synthesize(image, size=size, rng=0).volume

    def make():
        result = npmrf3d.synthesize(image, size=size, rng=0)
        return result, result.volume, result.timings

    wall, cpu, clock, result = profiled(make, repeats, reference)
    return report(f"{size}^3 at once (default, gravel64, seed 0)", wall, cpu, clock, result.stats, size ** 3, rate)


def job_block(image, size: int, block: int, repeats: int, rate: float) -> dict:
    method = METHODS["npmrf"]
    cfg = method.make_config(size=size, blockwise=True, seed=0)
    views = {v: image for v in cfg.views}
    origin, shape = (0, 0, block), (block,) * 3
    captured = {}

    def run(*args, **kwargs):  # the block's result, for its statistics and level timings
        captured["result"] = method.run(*args, **kwargs)
        return captured["result"]

    capturing = dataclasses.replace(method, run=run)

    with tempfile.TemporaryDirectory() as tmp:
        start = Path(tmp) / "start.npz"
        t0 = time.perf_counter()
        make_block(method, views, cfg, (0, 0, 0), shape, start)
        print(f"\nthe first block of {size}^3 (levels made whole, the pilot): {time.perf_counter() - t0:.1f} s, "
              "untimed below")
        reference = make_block(method, views, cfg, origin, shape, start)

        def make():
            volume = make_block(capturing, views, cfg, origin, shape, start)
            return captured["result"], volume, captured["result"].timings

        wall, cpu, clock, result = profiled(make, repeats, reference)
    return report(f"one {block}^3 block at {origin} of a --blockwise {size}^3 run", wall, cpu, clock, result.stats,
                  block ** 3, rate)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--parts", default="whole,block", help="comma-separated: whole, block")
    parser.add_argument("--size", type=int, default=128, help="the whole job's volume side")
    parser.add_argument("--block-size", type=int, default=512, help="the block job's volume side")
    parser.add_argument("--block", type=int, default=192, help="the block job's block side")
    parser.add_argument("--repeats", type=int, default=3, help="profiled runs per job; the fastest counts")
    parser.add_argument("--threads", type=int, default=2, help="numba threads")
    parser.add_argument("--out", default="figures")
    args = parser.parse_args(argv)
    parts = [p for p in args.parts.split(",") if p]
    unknown = sorted(set(parts) - {"whole", "block"})
    if unknown:
        parser.error(f"unknown part {unknown[0]!r}: the parts are whole and block")
    use_threads(args.threads)
    image = exemplar()
    print(hardware())
    npmrf3d.synthesize(image, size=16, levels=2, rng=0)  # compile (or load) the kernels
    rate = matmul_gflops()
    print(f"float32 matmul on this machine: {rate:.1f} GFLOP/s (the floor's rate)")
    record = {"hardware": hardware(), "matmul_gflops": rate, "threads": args.threads}
    if "whole" in parts:
        record["whole"] = job_whole(image, args.size, args.repeats, rate)
    if "block" in parts:
        record["block"] = job_block(image, args.block_size, args.block, args.repeats, rate)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "profile.json"
    path.write_text(json.dumps(record, indent=2, default=str) + "\n")
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
