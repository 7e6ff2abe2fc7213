"""A real 3D scan for the ground-truth study: a 64^3 block of the Colin27 T1 MRI template.

No micro-CT volume can be had offline here; Debian's ``mricron-data`` package ships MRIcron's
templates, among them ``ch2better.nii.gz``, the Colin Holmes 27-scan average T1 MRI at 0.5 mm
(316 x 370 x 301 voxels). This script cuts a 128^3 block of cortex and white matter (folded grey
matter on white: a two-phase-like structure), averages 2 x 2 x 2 voxels (1 mm) and writes a
``(64, 64, 64, 1)`` float32 ``.npy`` in [0, 1] for ``npmrf3d study groundtruth --volume``.

Usage::

    apt-get install mricron-data && pip install nibabel
    python benchmarks/scan_volume.py --out colin27_block.npy
    npmrf3d study groundtruth --volume colin27_block.npy --out figures/groundtruth

The file's licence: MRIcron's data files are distributed by Debian under a BSD-style licence
(``/usr/share/doc/mricron-data/copyright``); the volume is never bundled.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

TEMPLATE = Path("/usr/share/mricron/templates/ch2better.nii.gz")
#: Corner (axis 0, 1, 2 of the array nibabel returns, at 0.5 mm) of the 128^3 block.
CORNER = (20, 170, 150)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--template", default=str(TEMPLATE), help="the NIfTI file (default: %(default)s)")
    parser.add_argument("--out", default="colin27_block.npy", help="output .npy (default: %(default)s)")
    args = parser.parse_args(argv)
    try:
        import nibabel
    except ImportError:
        print("scan_volume: error: needs nibabel (pip install nibabel)", file=sys.stderr)
        return 2
    if not Path(args.template).is_file():
        print(f"scan_volume: error: {args.template} not found: apt-get install mricron-data", file=sys.stderr)
        return 2
    data = np.asarray(nibabel.load(args.template).dataobj, dtype=np.float32)
    a, b, c = CORNER
    block = data[a:a + 128, b:b + 128, c:c + 128]
    block = block.reshape(64, 2, 64, 2, 64, 2).mean(axis=(1, 3, 5))
    block = (block - block.min()) / max(float(np.ptp(block)), 1e-6)
    np.save(args.out, block[..., None].astype(np.float32))
    print(f"{args.out}: {block.shape} from {args.template} block at {CORNER} (0.5 mm, averaged to 1 mm); "
          f"mean {block.mean():.3f}, share above 0.5: {(block > 0.5).mean():.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
