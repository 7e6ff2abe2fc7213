"""Every study's full variant on one Dask cluster, and the wall time of each.

The studies run one after the other on the same cluster (started once), cheapest first, so
that an interrupted suite leaves whole studies behind. Studies are resumable: run the command
again and finished runs are skipped. The wall time of each study and of the whole suite is
printed and written to ``OUT/suite.json`` (updated after every study).

Usage::

    python studies/suite.py --volume colin27_block.npy --slice-axis 1   # local cluster
    python studies/suite.py --scheduler tcp://HOST:8786 --out /shared/study-results --volume ...
    python studies/suite.py --studies heuristics npk                      # a subset

``--volume`` is the real 3-D volume of the ground-truth study (without it that study is left
out, with a message). On a local cluster the workers are ``--workers`` processes (default: the
cores) of one numba thread each.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

from npmrf3d._cluster import local_cluster, plan_workers
from npmrf3d.studies.catalog import STUDIES
from npmrf3d.studies.runner import run_study

#: The default order: cheapest first (measured wall times on the 2-core machine:
#: studies/README.md), the two with the longest full-Parzen runs last.
ORDER = ("views", "groundtruth", "heuristics", "npk", "icm_vs_anneal", "colour", "neighbourhood",
         "cooling")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--studies", nargs="+", default=list(ORDER), choices=list(STUDIES),
                        metavar="NAME", help=f"studies to run, in this order, of: {' '.join(STUDIES)}")
    parser.add_argument("--out", default="study-results", help="results root")
    parser.add_argument("--scheduler", default="local",
                        help="'local' (a LocalCluster here) or an existing scheduler's address")
    parser.add_argument("--workers", type=int, default=None,
                        help="local cluster: worker processes (default: None = the cores)")
    parser.add_argument("--volume", default=None,
                        help="real 3-D volume (.npy/.tif) of the groundtruth study")
    parser.add_argument("--slice-axis", type=int, default=0, choices=(0, 1, 2),
                        help="groundtruth: the exemplar is a slice across this axis")
    args = parser.parse_args(argv)

    names = [n for n in args.studies if args.volume or not STUDIES[n].needs_volume]
    for n in set(args.studies) - set(names):
        print(f"left out: study {n} needs --volume (a real 3-D volume)")
    cluster = None
    address = args.scheduler
    threads = None
    if args.scheduler == "local":
        workers, threads = plan_workers(args.workers, 1)
        cluster = local_cluster(workers)
        address = cluster.scheduler_address
        print(f"local cluster: {workers} workers x {threads} numba thread ({address})")
    out = pathlib.Path(args.out)
    results: dict[str, dict] = {}
    t0 = time.perf_counter()

    def record(total):
        out.mkdir(parents=True, exist_ok=True)
        (out / "suite.json").write_text(json.dumps(
            {"studies": results, "wall_seconds": round(total, 1), "scheduler": args.scheduler,
             "workers": args.workers, "volume": args.volume}, indent=2))

    try:
        for name in names:
            start = time.perf_counter()
            try:
                outcome = run_study(STUDIES[name], mode="full", out=out, scheduler=address,
                                    threads=threads, slice_axis=args.slice_axis,
                                    volume=args.volume if STUDIES[name].needs_volume else None,
                                    echo=lambda message: print(message, flush=True))
                results[name] = {"runs": len(outcome.rows), **outcome.counts,
                                 "wall_seconds": round(time.perf_counter() - start, 1)}
            except Exception as exc:  # one study's failure must not stop the others
                results[name] = {"error": f"{type(exc).__name__}: {exc}"}
            print(f"{name}: {results[name]}", flush=True)
            record(time.perf_counter() - t0)
    finally:
        if cluster is not None:
            cluster.close()
    total = time.perf_counter() - t0
    record(total)
    print(f"suite: {len(names)} studies in {total / 60:.1f} min -> {out / 'suite.json'}")
    return 1 if any("error" in r or r.get("failed") for r in results.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
