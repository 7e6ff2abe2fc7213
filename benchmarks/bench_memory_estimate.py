"""Memory estimate against measured peak: the figure that guards every ``npmrf3d synth`` run.

For each bundled exemplar and volume side, ``npmrf3d synth bundled:NAME --size N`` runs in a
subprocess with its defaults otherwise; the peak resident set size of that process
(``ru_maxrss`` of ``os.wait4`` on the child, interpreter and libraries included) is compared
with the estimate the run is checked against (:func:`npmrf3d.methods.estimate`, the figure
``--dry-run`` prints). Prints one row per run (estimate, measured peak, ratio, wall time) and
exits 1 when a ratio lies outside ``[1 - tolerance, 1 + tolerance]``.

Exemplars (default): the 128x128 grey ``gravel`` and colour ``hubble`` and ``wood``
photographs, the 64x64 grey ``gravel64`` and colour ``ihc64``. Sides (default): 64, 128, 256.

Usage: ``python benchmarks/bench_memory_estimate.py [--sizes 64,128,256]
[--exemplars gravel,hubble,...] [--tolerance 0.25] [--threads 1] [-- extra synth options]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

from _common import hardware

from npmrf3d import data
from npmrf3d.methods import estimate
from npmrf3d.methods.npmrf import METHOD
from npmrf3d.model.exemplar import BUNDLED_PREFIX, resolve_exemplars
from npmrf3d.resources import format_bytes

EXEMPLARS = ("gravel", "hubble", "wood", "gravel64", "ihc64")


def estimated(name: str, size: int) -> int:
    """The estimate of ``synth bundled:NAME --size SIZE`` with the defaults otherwise."""
    config = METHOD.make_config(size=(size,) * 3)
    per_view = resolve_exemplars(data.path(name), None, config.views, **METHOD.fit(config))
    return estimate(METHOD, config, per_view).bytes


def measured(name: str, size: int, threads: int, extra: list[str]) -> tuple[int, float]:
    """(peak RSS in bytes, wall seconds) of one ``synth`` run in its own process."""
    env = {**os.environ, "NUMBA_NUM_THREADS": str(threads)}
    with tempfile.TemporaryDirectory() as tmp:
        argv = [sys.executable, "-m", "npmrf3d", "synth", f"{BUNDLED_PREFIX}{name}", "--size", str(size),
                "--quiet", "--out", os.path.join(tmp, "out"), *extra]
        t0 = time.perf_counter()
        proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        _, status, usage = os.wait4(proc.pid, 0)
        seconds = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        err = proc.stderr.read().decode()
        proc.stderr.close()
        if proc.returncode != 0:
            raise SystemExit(f"synth {name} --size {size} failed ({proc.returncode}): {err.strip()}")
    return usage.ru_maxrss * 1024, seconds


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="64,128,256")
    parser.add_argument("--exemplars", default=",".join(EXEMPLARS))
    parser.add_argument("--tolerance", type=float, default=0.25)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("extra", nargs="*", help="options passed on to synth (after --)")
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(",")]
    names = args.exemplars.split(",")
    print(f"{hardware()}; synth runs with NUMBA_NUM_THREADS={args.threads}")
    print(f"{'exemplar':>10} {'side':>5} {'estimate':>10} {'peak RSS':>10} {'ratio':>6} {'seconds':>8}")
    bad = []
    for size in sizes:
        for name in names:
            need = estimated(name, size)
            peak, seconds = measured(name, size, args.threads, args.extra)
            ratio = need / peak
            flag = "" if abs(ratio - 1.0) <= args.tolerance else "  OUTSIDE"
            print(f"{name:>10} {size:>5} {format_bytes(need):>10} {format_bytes(peak):>10} "
                  f"{ratio:6.2f} {seconds:8.1f}{flag}", flush=True)
            if flag:
                bad.append((name, size, ratio))
    if bad:
        print(f"{len(bad)} of {len(sizes) * len(names)} estimates outside +-{args.tolerance:.0%}",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
