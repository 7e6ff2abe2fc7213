"""Same seed, same volume at one and two threads on the batched-distance path.

Not marked ``kernels``: it runs whole syntheses in subprocesses, which the ``NUMBA_DISABLE_JIT``
pass of .ci/run would run as plain Python.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

THREADS_SCRIPT = textwrap.dedent("""
    import sys, numba, numpy as np
    import npmrf3d
    from npmrf3d import data
    from npmrf3d.model.relax._sweep import GEMM_MIN_DIMENSION
    assert numba.get_num_threads() == int(sys.argv[2])
    ihc = data.path("ihc64")
    assert 3 * (7 * 7 - 1) >= GEMM_MIN_DIMENSION  # colour 7x7 runs take the batched path
    vols = [
        npmrf3d.synthesize(ihc, size=16, window=7, levels=1, variant=v, palette=16, rng=7).volume
        for v in ("sharp", "literal")
    ] + [
        npmrf3d.synthesize(ihc, size=16, window=7, levels=1, relaxation="anneal", sampler=s,
                           palette=16, proposals=2, rng=7).volume
        for s in ("heat-bath", "metropolis")
    ]
    np.save(sys.argv[1], np.concatenate([v.ravel() for v in vols]))
""")


def test_same_seed_same_volume_at_one_and_two_threads(tmp_path):
    """Each thread count in its own process (numba's pool size is fixed at start-up); BLAS is
    left at the same count, so a BLAS that split its work by threads would show here too."""
    root = Path(__file__).resolve().parents[1]
    volumes = []
    for threads in (1, 2):
        out = tmp_path / f"t{threads}.npy"
        env = {**os.environ, "NUMBA_NUM_THREADS": str(threads), "OPENBLAS_NUM_THREADS": str(threads),
               "PYTHONPATH": str(root)}
        subprocess.run([sys.executable, "-c", THREADS_SCRIPT, str(out), str(threads)], check=True,
                       env=env, cwd=root, timeout=600)
        volumes.append(np.load(out))
    np.testing.assert_array_equal(volumes[0], volumes[1])
