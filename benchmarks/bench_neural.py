"""Speed benchmark of the neural method: training steps, generation, Zarr writing.

Trains the paper's generator (6 scales, 3 noise channels, step 4: about 85,000 parameters) for a
few timed steps on a bundled exemplar with the default descriptor, then generates a
``--gen-size``^3 block (default 256^3) and optionally writes a ``--zarr``^3 volume into Zarr on a
local Dask cluster of 2 single-thread workers. Prints the hardware and torch thread count, the
seconds per training step (and how many steps fit in 30 minutes), the generation throughput
(voxels/s) and what 1024^3 would take at that rate; the targets are training in
under 30 minutes on 2 cores, 256^3 in under 60 s, 1024^3 into Zarr in under 30 minutes.

Usage: ``python benchmarks/bench_neural.py [--exemplar ihc] [--slice 128] [--steps 5]
[--threads 2] [--gen-size 256] [--zarr 256]``
"""

from __future__ import annotations

import argparse
import os
import pathlib
import tempfile
import time

import numpy as np
import torch
from _common import hardware

from npmrf3d.methods import neural
from npmrf3d.model.exemplar import named_exemplar


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--exemplar", default="ihc")
    parser.add_argument("--slice", type=int, default=128, help="training slice side")
    parser.add_argument("--steps", type=int, default=5, help="timed training steps (after one warm-up)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--gen-size", type=int, default=256)
    parser.add_argument("--tile", type=int, default=neural.NeuralConfig.tile)
    parser.add_argument("--zarr", type=int, default=0, help="also write this size^3 into Zarr (0: no)")
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    print(f"hardware: {hardware()}; torch {torch.__version__}, {torch.get_num_threads()} threads; "
          f"load average {os.getloadavg()[0]:.2f}")
    exemplar = named_exemplar(args.exemplar)
    print(f"exemplar {args.exemplar}: {exemplar.shape}, slices {args.slice}^2, 3 views, batch 1")

    options = dict(slice_size=args.slice, tile=args.tile, seed=0)
    neural.train(exemplar, iterations=1, **options)  # warm-up
    times, cpu = [], []

    def clock(i, n, loss):
        times.append(time.perf_counter())
        cpu.append(time.process_time())

    model = neural.train(exemplar, iterations=args.steps, rng=0, progress=clock, **options)
    per_step = float(np.median(np.diff(times)))
    cpu_step = float(np.median(np.diff(cpu)))
    print(f"training: {per_step:.2f} s per step ({1 / per_step:.3f} steps/s); "
          f"{int(1800 / per_step)} steps fit in 30 min; {model.parameters} parameters")
    print(f"  CPU time {cpu_step:.2f} s per step (a machine shared with other jobs stretches the "
          f"wall time; idle, {args.threads} threads would take about {cpu_step / args.threads:.2f}-"
          f"{cpu_step:.2f} s)")

    neural.generate(model, (0, 0, 0), args.tile)  # warm-up
    t0, c0 = time.perf_counter(), time.process_time()
    volume = neural.generate(model, (0, 0, 0), args.gen_size)
    t, c = time.perf_counter() - t0, time.process_time() - c0
    rate = volume.shape[0] * volume.shape[1] * volume.shape[2] / t
    print(f"generation: {args.gen_size}^3 in {t:.1f} s ({rate:.3g} voxels/s, tile {args.tile}); "
          f"1024^3 at this rate: {1024 ** 3 / rate / 60:.1f} min; CPU time {c:.1f} s "
          f"(idle, {args.threads} threads: about {c / args.threads:.1f} s)")

    if args.zarr:
        with tempfile.TemporaryDirectory() as tmp:
            path = pathlib.Path(tmp, "m.pt")
            neural.save_model(model, path)
            t0 = time.perf_counter()
            neural.write_zarr(path, pathlib.Path(tmp, "v.zarr"), size=(args.zarr,) * 3, workers=2)
            t = time.perf_counter() - t0
        print(f"zarr: {args.zarr}^3 on 2 local workers in {t:.1f} s ({args.zarr ** 3 / t:.3g} voxels/s); "
              f"1024^3 at this rate: {1024 ** 3 / (args.zarr ** 3 / t) / 60:.1f} min")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
