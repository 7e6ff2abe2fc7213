"""Does a label volume keep what its input shows? Every phase's materials statistics along each
axis of the volume, beside the same statistics of the input along the same direction, with a
verdict in words; ``npmrf3d materials`` writes the result.

The input is one slice (every view's exemplar), one slice per view, or a 3D crop. A slice seen
by view ``v`` lies in the plane :data:`npmrf3d.model.neighbourhood.VIEW_AXES` ``[v]`` of the
volume: its rows run along the first of those axes and its columns along the second, so the
volume's axis ``a`` is compared with the mean over the views that contain ``a`` of the slice's
statistic along the matching image axis. A crop is compared axis by axis with itself.

Statistics per phase (:mod:`npmrf3d.analysis.materials` measures them): the volume fraction;
the interface density ``P_L`` per axis and ``2 P_L``, the stereological specific surface area
(like with like: a slice has no marching-cubes surface; the volume's marching-cubes area is
reported beside it); the two-point correlation ``S2`` per axis (non-periodic) and its
normalised form ``(S2 - f^2) / (f - f^2)``; chord-length distributions and mean chords per axis;
percolation per axis (face connectivity); relative diffusivity per axis (3D only: a slice's
2D diffusivity is not a 3D one). A slice that percolates along a direction proves that the
material does; one that does not proves nothing, and the report says so.

A module of its own because it pairs directions and judges; :mod:`.materials` only measures.
"""

from __future__ import annotations

import numpy as np

from .. import _validation as check
from ..model.neighbourhood import VIEW_AXES
from . import materials
from .metrics import two_point_correlation

__all__ = ["TOLERANCES", "compare", "image_statistics", "materials_report", "reference_along_axes"]

#: When a volume's statistic counts as the input's (documented in docs/materials.md):
#: ``fraction``: within max(absolute, relative x the input's); ``surface``, ``chord`` and
#: ``diffusivity``: ratio to the input's within 1 +- the value; ``two_point``: the root mean
#: square over the distances of the difference of the normalised curves at most this.
TOLERANCES = {"fraction_absolute": 0.01, "fraction_relative": 0.15, "surface": 0.2, "chord": 0.2,
              "two_point": 0.1, "diffusivity": 0.3}
#: A relative diffusivity below this counts as none (a phase that does not connect).
NO_FLOW = 0.005


def _shape(s2: np.ndarray) -> list[float] | None:
    """The normalised two-point curve ``(S2 - f^2) / (f - f^2)`` (None for an empty or full phase)."""
    f = float(s2[0])
    if f <= 0.0 or f >= 1.0:
        return None
    return ((np.asarray(s2) - f * f) / (f - f * f)).tolist()


def _pieces(cube: np.ndarray, axis: int, window: int | None) -> list:
    """``cube`` cut along ``axis`` into pieces ``window`` long (the rest dropped), so that its
    chords are cut where a volume of that side cuts them; the whole without a window."""
    n = cube.shape[axis]
    if window is None or window >= n:
        return [cube]
    return [np.take(cube, np.arange(k * window, (k + 1) * window), axis=axis) for k in range(n // window)]


def _distribution(lengths: np.ndarray, top: int) -> list:
    hist = np.bincount(np.minimum(lengths, top) - 1, minlength=top)[:top].astype(np.float64)
    return (hist / hist.sum() if hist.sum() else hist).tolist()


def image_statistics(labels: np.ndarray, value, *, max_distance: int, max_chord: int,
                     diffusivity: str | None = None, chord_window: list | None = None) -> dict:
    """One phase's statistics of a 2D or 3D label array, each a list over its axes.

    ``chord_window``: per axis, the length of the pieces its chords are measured in (the side of
    the volume it is compared with: a chord longer than the volume cannot lie inside it, and
    border chords are dropped in both alike); None: the whole array.

    ``diffusivity``: a solver of :data:`npmrf3d.analysis.materials.DIFFUSIVITY_SOLVERS` (3D
    only; None: not computed); 3D arrays also get ``surface_area`` by marching cubes."""
    ind = np.asarray(labels) == value
    cube = ind if ind.ndim == 3 else ind[None]
    shift = 3 - ind.ndim
    axes = range(ind.ndim)
    window = [None] * ind.ndim if chord_window is None else chord_window
    pieces = [_pieces(cube, a + shift, window[a]) for a in axes]
    chords = [np.concatenate([materials.chord_lengths(p, a + shift) for p in pieces[a]]) for a in axes]
    s2 = two_point_correlation(ind.astype(np.uint8), 1, max_distance=max_distance)
    stats = {
        "fraction": float(ind.mean()),
        "interface_density": [materials.interface_density(ind, a) for a in axes],
        "two_point": s2.tolist(),
        "two_point_shape": [_shape(row) for row in s2],
        "chord_distribution": [_distribution(c, max_chord) for c in chords],
        "mean_chord": [float(c.mean()) if c.size else 0.0 for c in chords],
        "percolates": materials.percolates(ind),
    }
    stats["surface_stereology"] = [2.0 * p for p in stats["interface_density"]]
    if ind.ndim == 3:
        stats["surface_area"] = materials.specific_surface_area(ind)
        if diffusivity is not None:
            stats["diffusivity"] = [materials.relative_diffusivity(ind, axis=a, solver=diffusivity)
                                    for a in range(3)]
    return stats


def reference_along_axes(per_view: dict) -> dict:
    """The slices' statistics along the volume's three axes: ``per_view`` maps a view to its
    slice's :func:`image_statistics`; each axis gets the mean over the views whose plane holds it
    (``percolates``: whether any of them percolates), ``None`` where no view holds it."""
    out = {"fraction": float(np.mean([s["fraction"] for s in per_view.values()]))}
    for key in ("interface_density", "surface_stereology", "two_point", "two_point_shape",
                "chord_distribution", "mean_chord", "percolates"):
        out[key] = []
        for axis in range(3):
            seen = [s[key][VIEW_AXES[v].index(axis)] for v, s in per_view.items() if axis in VIEW_AXES[v]]
            seen = [x for x in seen if x is not None]
            if not seen:
                out[key].append(None)
            elif key == "percolates":
                out[key].append(any(seen))
            else:
                out[key].append(np.mean(np.asarray(seen, dtype=np.float64), axis=0).tolist())
    return out


def _ratio_ok(value: float, ref: float | None, tolerance: float, floor: float = 0.0) -> bool | None:
    """Whether ``value / ref`` lies within ``1 +- tolerance`` (a ``ref`` at most ``floor``: whether
    ``value`` is too); None without a ``ref``."""
    if ref is None:
        return None
    if ref <= floor:
        return value <= floor
    return abs(value / ref - 1.0) <= tolerance


def _numbers(values) -> str:
    return ", ".join("-" if v is None or v != v else f"{v:.3g}" for v in values)


def _verdict(flags: list) -> str:
    bad = [a for a, ok in enumerate(flags) if ok is False]
    return ": kept" if not bad else f": not kept along axis {' or '.join(map(str, bad))}"


def _axes_words(flags: list, values: list, refs: list, unit: str = "") -> str:
    return f"{_numbers(values)}{unit} along axes 0, 1, 2 against the input's {_numbers(refs)}{_verdict(flags)}"


def compare(volume: dict, ref: dict, *, crop: bool) -> dict:
    """Verdicts of one phase: {statistic: {"match": bool or None, "axes": [...], "words": str}}
    (``match`` None: the input cannot tell). ``volume``: :func:`image_statistics` of the volume;
    ``ref``: of the crop (``crop``) or :func:`reference_along_axes` of the slices."""
    t = TOLERANCES
    out = {}
    f_in, f_out = ref["fraction"], volume["fraction"]
    ok = abs(f_out - f_in) <= max(t["fraction_absolute"], t["fraction_relative"] * f_in)
    out["fraction"] = {"match": ok, "words": f"fraction {f_out:.3f} against the input's {f_in:.3f}: "
                                             f"{'kept' if ok else 'not kept'}"}
    surface = [_ratio_ok(v, r, t["surface"]) for v, r in zip(volume["surface_stereology"], ref["surface_stereology"])]
    out["surface"] = {"axes": surface, "match": all(x is not False for x in surface),
                      "words": "surface per unit volume (2 P_L) " + _axes_words(
                          surface, volume["surface_stereology"], ref["surface_stereology"], " per voxel")}
    s2 = []
    worst = []
    for v, r in zip(volume["two_point_shape"], ref["two_point_shape"]):
        if v is None or r is None:
            s2.append(None if r is None else False)
            worst.append(float("nan"))
            continue
        n = min(len(v), len(r))
        worst.append(float(np.sqrt(np.mean((np.asarray(v[:n]) - np.asarray(r[:n])) ** 2))))
        s2.append(worst[-1] <= t["two_point"])
    out["two_point"] = {"axes": s2, "match": all(x is not False for x in s2), "difference": worst,
                        "words": f"two-point correlation: the normalised curves differ by "
                                 f"{_numbers(worst)} along axes 0, 1, 2 (root mean square over the distances; "
                                 f"tolerance {t['two_point']}){_verdict(s2)}"}
    chord = [_ratio_ok(v, r, t["chord"]) for v, r in zip(volume["mean_chord"], ref["mean_chord"])]
    out["chord"] = {"axes": chord, "match": all(x is not False for x in chord),
                    "words": "mean chord " + _axes_words(chord, volume["mean_chord"], ref["mean_chord"], " voxels")}
    out["percolation"] = _percolation(volume["percolates"], ref["percolates"], crop=crop)
    if "diffusivity" in volume:
        out["diffusivity"] = _diffusivity(volume["diffusivity"], ref.get("diffusivity") if crop else None)
    return out


def _percolation(mine: list, theirs: list, *, crop: bool) -> dict:
    axes = []
    for m, r in zip(mine, theirs):
        if r is None:
            axes.append(None)
        elif crop or r:
            axes.append(m == r)
        else:
            axes.append(None)  # a slice that does not percolate proves nothing about 3D
    yes = [a for a, m in enumerate(mine) if m]
    words = "connects face to face along " + (
        "no axis" if not yes else f"{'axes' if len(yes) > 1 else 'axis'} {', '.join(map(str, yes))}")
    lost = [a for a, x in enumerate(axes) if x is False and theirs[a]]
    extra = [a for a, x in enumerate(axes) if x is False and not theirs[a]]
    if lost:
        words += f"; not along axis {' or '.join(map(str, lost))}, where the input connects: not kept"
    if extra:
        words += f"; along axis {' or '.join(map(str, extra))}, where the crop does not: not kept"
    unknown = [a for a, x in enumerate(axes) if x is None]
    if unknown and not crop:
        words += (f"; the slices do not connect along axis {' or '.join(map(str, unknown))}, which "
                  f"says nothing of 3D")
    if not lost and not extra:
        words += "; kept" if any(x is True for x in axes) else ""
    return {"axes": axes, "match": all(x is not False for x in axes), "volume": mine, "input": theirs,
            "words": words}


def _diffusivity(mine: list, theirs: list | None) -> dict:
    if theirs is None:
        return {"axes": [None] * 3, "match": None, "volume": mine,
                "words": "relative diffusivity " + ", ".join(f"{d:.3g}" for d in mine)
                         + " along axes 0, 1, 2 (3D only: a slice has no 3D diffusivity to compare)"}
    axes = [_ratio_ok(v, r, TOLERANCES["diffusivity"], NO_FLOW) for v, r in zip(mine, theirs)]
    return {"axes": axes, "match": all(axes), "volume": mine, "input": theirs,
            "words": "relative diffusivity " + _axes_words(axes, mine, theirs)}


def materials_report(volume: np.ndarray, values, *, inputs: dict, diffusivity: str = "finite-volume",
                     max_distance: int = 32) -> dict:
    """The statistics and verdicts of every phase of a label ``volume`` (N1, N2, N3) whose
    phases are ``values``, against ``inputs``: {view: 2D label slice} or {"volume": 3D crop}.

    Returns ``{"phases": [{"value", "volume", "input", "compare"}, ...], "max_distance",
    "max_chord", "kept", "not_kept", "summary"}``; ``input`` holds the crop's statistics or
    the slices' along the volume's axes (:func:`reference_along_axes`) and, under
    ``"slices"``, each slice's own."""
    vol = np.asarray(volume)
    if vol.ndim != 3:
        check.fail(f"volume must be a label volume (N1, N2, N3); got shape {vol.shape}")
    crop = set(inputs) == {"volume"}
    sides = [n for a in inputs.values() for n in np.shape(a)] + list(vol.shape)
    r_max = int(min(max_distance, min(sides) // 2))
    top = int(min(sides))
    phases = []
    for value in values:
        mine = image_statistics(vol, value, max_distance=r_max, max_chord=top, diffusivity=diffusivity)
        if crop:
            ref = image_statistics(inputs["volume"], value, max_distance=r_max, max_chord=top,
                                   diffusivity=diffusivity, chord_window=list(vol.shape))
        else:
            own = {v: image_statistics(a, value, max_distance=r_max, max_chord=top,
                                       chord_window=[vol.shape[a] for a in VIEW_AXES[v]])
                   for v, a in inputs.items()}
            ref = {**reference_along_axes(own), "slices": own}
        phases.append({"value": value, "volume": mine, "input": ref, "compare": compare(mine, ref, crop=crop)})
    return {"phases": phases, "max_distance": r_max, "max_chord": top, **_summary(phases)}


def _summary(phases: list) -> dict:
    kept, lost = [], []
    for p in phases:
        for name, verdict in p["compare"].items():
            label = f"phase {p['value']}: {name}"
            if verdict["match"] is True:
                kept.append(label)
            elif verdict["match"] is False:
                lost.append(label)
    lines = [f"phase {p['value']}: " + "; ".join(v["words"] for v in p["compare"].values()) for p in phases]
    head = ("The volume keeps every statistic the input shows." if not lost else
            f"The volume keeps {len(kept)} of {len(kept) + len(lost)} statistics the input can judge; "
            f"not kept: {', '.join(lost)}.")
    return {"kept": kept, "not_kept": lost, "summary": [head, *lines]}
