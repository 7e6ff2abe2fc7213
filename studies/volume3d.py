"""From a 3D scan: the ``volume-lh`` method on synthetic scans, pictures and numbers.

Two parts, each writing a PNG and the JSON of the numbers behind it into ``--out``
(default ``figures/volume3d``):

* ``scan``: a periodic porous "scan" (smoothed noise, thresholded; ``--scan-side`` voxels a side)
  stands in for a micro-CT volume (no real scan is available offline). A ``--crop`` crop is the
  exemplar; the method makes a ``--size`` volume. Its octants' volume fraction, specific surface
  area and two-point correlation are compared with the spread of ``--crops`` other crops of the
  scan of the same side (``scan.json``, ``scan.png``: slices and S2 curves).
* ``twist``: a layered exemplar (wavy layers) synthesised without a field and under ``twist``;
  the dominant in-plane orientation of every slice ``volume[i]`` (structure tensor) follows the
  field's angle (``twist.json``, ``twist.png``: slices and the orientation against i).

Run: ``python studies/volume3d.py`` (64^3 crop -> 128^3) or ``--quick``.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import platform
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

from npmrf3d._kernels import _jit  # noqa: E402
from npmrf3d.analysis import materials  # noqa: E402
from npmrf3d.methods.volume_lh import volume_synthesize  # noqa: E402
from npmrf3d.model.fields import level_frames  # noqa: E402


def porous_scan(side: int, seed: int) -> np.ndarray:
    """Periodic two-phase volume: Gaussian-smoothed noise (sigma 2) above its median."""
    field = ndimage.gaussian_filter(np.random.default_rng(seed).random((side,) * 3), 2.0, mode="wrap")
    return (field > np.median(field)).astype(np.float32)


def wavy_layers(side: int, period: float = 8.0) -> np.ndarray:
    """Layers normal to axis 1 with a gentle wave along axis 2 (so slices are not all equal)."""
    i, j, k = np.meshgrid(*[np.arange(side, dtype=np.float64)] * 3, indexing="ij")
    phase = 2 * np.pi * (j + 1.5 * np.sin(2 * np.pi * k / 32) + 0.8 * np.sin(2 * np.pi * i / 24)) / period
    return (np.sin(phase) > 0).astype(np.float32)


def slice_orientation(plane: np.ndarray) -> float:
    """Dominant orientation (degrees, in (-90, 90]) of the gradient in a 2D plane (axes j, k),
    from the plane's summed structure tensor (gradient of a sigma-1 Gaussian)."""
    smooth = ndimage.gaussian_filter(plane.astype(np.float64), 1.0, mode="wrap")
    gj, gk = np.gradient(smooth)
    return float(np.degrees(0.5 * np.arctan2(2 * (gj * gk).sum(), (gj ** 2 - gk ** 2).sum())))


def stats(ind: np.ndarray, r: int | None) -> dict:
    out = {"fraction": float(ind.mean()), "surface_area": materials.specific_surface_area(ind)}
    if r is not None:
        out["s2_radial"] = materials.radial_two_point(ind, max_distance=r).tolist()
    return out


def scan_part(args, out: pathlib.Path) -> dict:
    scan = porous_scan(args.scan_side, args.seed)
    rng = np.random.default_rng(args.seed + 1)
    c = args.crop
    exemplar = scan[:c, :c, :c]
    t0 = time.perf_counter()
    res = volume_synthesize(exemplar, size=args.size, levels=args.levels, rng=args.seed)
    seconds = time.perf_counter() - t0
    v = res.volume[..., 0] > 0.5
    r = min(c, args.size) // 4
    crops = []
    for _ in range(args.crops):
        o = rng.integers(0, args.scan_side - c, size=3)
        crops.append(stats(scan[o[0]:o[0] + c, o[1]:o[1] + c, o[2]:o[2] + c] > 0.5, r))
    h = args.size // 2
    octants = [stats(v[a:a + h, b:b + h, d:d + h], None) for a in (0, h) for b in (0, h) for d in (0, h)]
    whole = stats(v, r)

    def spread(key, items):
        values = [x[key] for x in items]
        return [float(min(values)), float(max(values))]

    s2_crops = np.array([x["s2_radial"] for x in crops])
    s2_out = np.array(whole["s2_radial"])
    inside = (s2_out >= s2_crops.min(0) - 1e-12) & (s2_out <= s2_crops.max(0) + 1e-12)
    numbers = {
        "exemplar": f"crop {c}^3 of a {args.scan_side}^3 porous scan (seed {args.seed})",
        "size": args.size, "levels": args.levels, "seconds": seconds, "threads": _jit.thread_count(),
        "timings": res.timings,
        "output": whole, "output_octants": {"fraction": spread("fraction", octants),
                                            "surface_area": spread("surface_area", octants)},
        "crops": {"count": args.crops, "fraction": spread("fraction", crops),
                  "surface_area": spread("surface_area", crops),
                  "s2_min": s2_crops.min(0).tolist(), "s2_max": s2_crops.max(0).tolist()},
        "s2_inside_crop_spread": [bool(x) for x in inside],
        "machine": platform.platform(),
    }
    fig, ax = plt.subplots(1, 4, figsize=(14, 3.6))
    ax[0].imshow(exemplar[c // 2], cmap="gray")
    ax[0].set_title(f"exemplar crop {c}^3, slice")
    ax[1].imshow(scan[: args.size, : args.size, args.size // 2] if args.scan_side >= args.size else scan[0], cmap="gray")
    ax[1].set_title("the scan (same scale)")
    ax[2].imshow(res.volume[:, :, args.size // 2, 0], cmap="gray")
    ax[2].set_title(f"volume-lh {args.size}^3, slice")
    for a in ax[:3]:
        a.axis("off")
    rr = np.arange(r + 1)
    ax[3].fill_between(rr, s2_crops.min(0), s2_crops.max(0), color="0.8", label=f"{args.crops} scan crops")
    ax[3].plot(rr, s2_out, "r-", label="volume-lh")
    ax[3].set_xlabel("distance r (voxels)")
    ax[3].set_ylabel("S2(r), radial")
    ax[3].legend()
    fig.tight_layout()
    fig.savefig(out / "scan.png", dpi=80)
    plt.close(fig)
    return numbers


def twist_part(args, out: pathlib.Path) -> dict:
    side = args.twist_size
    exemplar = wavy_layers(max(48, side // 2 + 16))
    plain = volume_synthesize(exemplar, size=side, levels=args.levels, rng=args.seed).volume[..., 0]
    twisted = volume_synthesize(exemplar, size=side, levels=args.levels, rng=args.seed,
                                vector_field="twist", angle=args.angle).volume[..., 0]
    frames = level_frames("twist", None, (side,) * 3, 0, args.angle)
    # the layers' normal is exemplar axis 1; its direction in slice i is column 1 of the frame
    expected = np.degrees(np.arctan2(frames[:, 0, 0, 2, 1], frames[:, 0, 0, 1, 1]))
    expected = (expected + 90) % 180 - 90
    measured = np.array([slice_orientation(twisted[i]) for i in range(side)])
    unturned = np.array([slice_orientation(plain[i]) for i in range(side)])
    error = (measured - expected + 90) % 180 - 90
    numbers = {"size": side, "angle": args.angle, "levels": args.levels,
               "expected_deg": expected.tolist(), "measured_deg": measured.tolist(),
               "no_field_deg": unturned.tolist(),
               "mean_abs_error_deg": float(np.abs(error).mean()),
               "no_field_mean_abs_deg": float(np.abs(unturned).mean())}
    picks = [0, side // 3, 2 * side // 3, side - 1]
    fig, ax = plt.subplots(2, 5, figsize=(16, 6.4))
    ax[0, 0].imshow(exemplar[exemplar.shape[0] // 2], cmap="gray")
    ax[0, 0].set_title("exemplar slice (layers)")
    ax[1, 0].imshow(twisted[:, :, side // 2], cmap="gray")
    ax[1, 0].set_title("twisted, slice along axis 0")
    for n, i in enumerate(picks):
        ax[0, n + 1].imshow(plain[i], cmap="gray")
        ax[0, n + 1].set_title(f"no field, i = {i}")
        ax[1, n + 1].imshow(twisted[i], cmap="gray")
        ax[1, n + 1].set_title(f"twist {args.angle:g}, i = {i}: {measured[i]:.0f} deg")
    for a in ax.ravel():
        a.axis("off")
    fig.tight_layout()
    fig.savefig(out / "twist_slices.png", dpi=70)
    plt.close(fig)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    ax[0].plot(expected, "k--", label="field (twist)")
    ax[0].plot(measured, "r.-", label="measured, twisted")
    ax[0].plot(unturned, "b.", label="measured, no field")
    ax[0].set_xlabel("slice i (axis 0)")
    ax[0].set_ylabel("layer normal in the (j, k) plane, degrees")
    ax[0].legend()
    bins = np.linspace(-90, 90, 19)
    for i, colour in zip(picks, ("C0", "C1", "C2", "C3")):
        smooth = ndimage.gaussian_filter(twisted[i].astype(np.float64), 1.0, mode="wrap")
        gj, gk = np.gradient(smooth)
        angle = np.degrees(np.arctan2(gk, gj))
        angle = (angle + 90) % 180 - 90
        weight = np.hypot(gj, gk)
        ax[1].hist(angle.ravel(), bins=bins, weights=weight.ravel(), histtype="step", color=colour,
                   density=True, label=f"i = {i} (field {expected[i]:.0f})")
    ax[1].set_xlabel("gradient orientation in slice i, degrees")
    ax[1].set_ylabel("density (gradient-weighted)")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "twist.png", dpi=80)
    plt.close(fig)
    return numbers


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="tiny sizes (a smoke test)")
    p.add_argument("--part", choices=("scan", "twist", "both"), default="both")
    p.add_argument("--out", default="figures/volume3d")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    args.scan_side, args.crop, args.size, args.crops = (48, 24, 16, 4) if args.quick else (192, 64, 128, 12)
    args.levels = 2 if args.quick else 4
    args.twist_size = 16 if args.quick else 64
    args.angle = 90.0 if args.quick else 180.0
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.part in ("scan", "both"):
        (out / "scan.json").write_text(json.dumps(scan_part(args, out), indent=2) + "\n")
    if args.part in ("twist", "both"):
        (out / "twist.json").write_text(json.dumps(twist_part(args, out), indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
