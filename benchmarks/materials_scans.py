"""The real scans of the materials benchmark, built from their public repositories.

Nothing of them is bundled (licences and sizes: ``npmrf3d/data/SOURCES.md``, "Real scans of the
materials benchmark"). Clone the repositories named in :data:`SCANS` (or only the files named)
into one folder, then::

    python benchmarks/materials_scans.py --sources SRC --out scans

writes ``scans/<name>.npy`` (float32 in [0, 1], ``(N1, N2, N3)``) for every scan whose files are
present, after checking each file against its pinned SHA-256. A file that is missing is reported
and its scan left out; a file whose checksum differs is refused (the scan would not be the one
the benchmark's numbers were measured on).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import io
import pathlib
import sys
import zipfile
from collections.abc import Callable

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).parent))
from bench_volume_scan import block_mean


def _tif(blobs: list[bytes]) -> np.ndarray:
    """One multi-page TIFF, or a stack of one 2-D TIFF per slice."""
    import tifffile
    images = [tifffile.imread(io.BytesIO(b)) for b in blobs]
    return (images[0] if len(images) == 1 else np.stack(images)).astype(np.float32)


def _zip_tif(blobs: list[bytes]) -> np.ndarray:
    """The one TIFF inside a zip archive."""
    with zipfile.ZipFile(io.BytesIO(blobs[0])) as archive:
        return _tif([archive.read(archive.namelist()[0])])


def _raw128(blobs: list[bytes]) -> np.ndarray:
    """A raw 128^3 uint8 volume."""
    return np.frombuffer(blobs[0], dtype=np.uint8).reshape(128, 128, 128).astype(np.float32)


def _nmc_phase(raw: np.ndarray) -> np.ndarray:
    """Labels 0 pore, 1 NMC, 2 generated carbon-binder: the binder joins the pore phase."""
    return (raw == 1).astype(np.float32)


def _central_170(raw: np.ndarray) -> np.ndarray:
    """The central 170 x 170 square of a cylinder's slices."""
    c = (raw.shape[1] - 170) // 2
    return raw[:, c:c + 170, c:c + 170]


def _slices_last(raw: np.ndarray) -> np.ndarray:
    return raw.transpose(1, 2, 0)


@dataclasses.dataclass(frozen=True)
class Scan:
    """One real scan: where its files lie and how they become a volume in [0, 1]."""

    name: str
    repository: str
    files: tuple[str, ...]          # paths in the repository (a stack of 2-D slices: every file, in order)
    sha256: str                     # of the files' bytes, concatenated in order
    description: str
    binary: bool                    # two phases (judged at 0.5); grey scans are judged at Otsu's threshold
    isotropic: bool                 # one slice says enough; an anisotropic scan gives three
    held_out: bool                  # never used for a choice of the project's defaults
    downsample: int = 1             # mean over this many voxels per side
    reader: Callable[[list[bytes]], np.ndarray] = _tif   # the files' bytes -> the raw volume
    transform: Callable[[np.ndarray], np.ndarray] | None = None  # applied to the raw volume first

    def volume(self, blobs: list[bytes]) -> np.ndarray:
        """The files' bytes as the benchmark's volume: float32 in [0, 1], averaged by ``downsample``."""
        raw = self.reader(blobs)
        if self.transform is not None:
            raw = self.transform(raw)
        if raw.max() > 1.0:
            raw = raw / 255.0
        return np.ascontiguousarray(block_mean(raw, self.downsample), dtype=np.float32)


_LHDL = "test_data/LHDL/"
SCANS: tuple[Scan, ...] = (
    Scan("berea", "LukasMosser/PorousMediaGan", ("data/berea/original/raw/berea.zip",),
         "5728a6e8f2aee9bba5b3e732eec8c08f32642f841b3cf08da69d8972d0d334c9",
         "Berea sandstone, segmented micro-CT (Imperial College), 400^3 at half resolution",
         binary=True, isotropic=True, held_out=False, downsample=2, reader=_zip_tif),
    Scan("ketton", "LukasMosser/PorousMediaGan", ("data/ketton/original/raw/ketton.zip",),
         "c7d024693d4028a0909736a81e8bea8bef21dab00be1717a118e3246a8e9e203",
         "Ketton limestone, segmented micro-CT (Imperial College), 256^3 at half resolution",
         binary=True, isotropic=True, held_out=True, downsample=2, reader=_zip_tif),
    Scan("nmc", "NREL/MATBOX_Microstructure_analysis_toolbox",
         (("Data_example/From computed tomography with additives numerically generated/"
          "nmc-1-cal_generatedCBD_bridge.tif"),),
         "0197a8da2b6def10265e8fa2f3ce6a4c9b9a4f11af6c40c13d9dcbb7861eaf08",
         "calendered NMC cathode, X-ray CT (NREL), NMC against pore + binder",
         binary=True, isotropic=True, held_out=True, transform=_nmc_phase),
    Scan("bone3155", "ciclope-microFE/ciclope", tuple(f"{_LHDL}3155_D_4_bc/cropped/3155_D_4_bc_{i:04d}.tif"
                                                      for i in range(200)),
         "eedf8c5feb7cd10ef7c41ca9f7a42884cf6ace75f347aa71741ce6cd71d32cc0",
         "human trabecular bone, micro-CT 19.5 um (LHDL), grey",
         binary=False, isotropic=True, held_out=False),
    Scan("bone2923", "ciclope-microFE/ciclope", tuple(f"{_LHDL}Ti_2923_D_1/resampled/Ti_2923_D_1_{i:04d}.tif"
                                                      for i in range(495)),
         "7f4f11f78d1d8c7340a229a18fe5edca6ebf296ff5810d9904d7db174dc31a98",
         "human trabecular bone core, micro-CT 19.5 um (LHDL), grey, central square",
         binary=False, isotropic=True, held_out=True, transform=_central_170),
    Scan("soil", "EMSL-Computing/Pore2Chip", tuple(f"examples/bean_bucket_100/Bean Bucket 8bit image{i:04d}.tif"
                                                   for i in range(100)),
         "803ed2a9d5528a5bc5f4449e84ca085bf50ce95e2e657bfa1f3c0618d6f47ed4",
         "soil core, XCT, 38 grey levels",
         binary=False, isotropic=True, held_out=True, transform=_slices_last),
    Scan("polymer", "rshkarin/quanfima", ("data/polymer3d_8bit_128x128x128.raw",),
         "3806417b3e876e909f6f08d5b0b33248cd5e8ddb81596abc86b212ec186470c9",
         "short fibres in a polymer matrix, micro-CT, grey",
         binary=False, isotropic=False, held_out=True, reader=_raw128),
    Scan("fiberform", "nasa/puma", ("python/pumapy/data/100_fiberform.tif",),
         "1386f825c71272f2cac7a7dbf8c82a25387b70c379655c02a843f6150edbe861",
         "FiberForm carbon-fibre preform, micro-CT 1.3 um, grey",
         binary=False, isotropic=False, held_out=True),
    Scan("weave", "nasa/puma", ("python/pumapy/data/small_weave.tif",),
         "87033f78dcd579dc03af18e099dc43cfccdc420ff7cc55ff9007ae3c0d05c623",
         "woven fibre composite, grey",
         binary=False, isotropic=False, held_out=False),
)

def by_name(name: str) -> Scan:
    for scan in SCANS:
        if scan.name == name:
            return scan
    raise KeyError(f"no scan named {name!r}; known: {', '.join(s.name for s in SCANS)}")


def build(scan: Scan, sources: pathlib.Path) -> tuple[np.ndarray, str]:
    """The scan's volume from ``sources/<repository name>/<file>``, and its files' SHA-256."""
    root = sources / scan.repository.split("/")[1]
    files = [root / f for f in scan.files]
    missing = [f for f in files if not f.is_file()]
    if missing:
        raise FileNotFoundError(f"{len(missing)} of {len(files)} files missing, first {missing[0]}")
    blobs = [f.read_bytes() for f in files]
    digest = hashlib.sha256()
    for blob in blobs:
        digest.update(blob)
    return scan.volume(blobs), digest.hexdigest()


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("--sources", required=True, help="folder holding the repositories' checkouts by name")
    parser.add_argument("--out", default="scans", help="folder for the .npy volumes")
    parser.add_argument("--scans", nargs="+", default=[s.name for s in SCANS], help="which scans")
    args = parser.parse_args(argv)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    status = 0
    for name in args.scans:
        scan = by_name(name)
        try:
            volume, digest = build(scan, pathlib.Path(args.sources))
        except FileNotFoundError as exc:
            print(f"{name}: left out: {exc}", file=sys.stderr)
            continue
        if scan.sha256 and digest != scan.sha256:
            print(f"{name}: refused: SHA-256 {digest} differs from the pinned {scan.sha256}", file=sys.stderr)
            status = 2
            continue
        np.save(out / f"{name}.npy", volume)
        print(f"{name}: {volume.shape}, mean {volume.mean():.3f}, sha256 {digest}")
    return status


if __name__ == "__main__":
    raise SystemExit(main())
