"""The paper-scale quality benchmark (``bench_quality.py --suite paper``; docs/quality.md).

64^3 volumes from 64 x 64 crops of real photographs, 3 levels, judged as docs/metrics.md
says: every figure also as a ratio to the **structureless control** (voxels drawn
independently from the exemplar: 1.0 = no structure), beside a **blurred control** (that
control Gaussian-smoothed to the exemplar's grain, rescaled to its mean and spread) and the
**variability floor** (crop B, a different, non-overlapping crop of the same photograph, used
in place of every slice: what a perfect method scores).

Measures (each averaged over the three views front, right and top):

The floor pools the three 64 x 64 quadrants of the 128 x 128 photograph that do not overlap
crop A (one crop B can be unrepresentative: ``hubble``'s diagonal quadrant holds one large
galaxy).

* ``ac``: L2 error of the grey autocorrelation, lags -8..8 (:func:`npmrf3d.analysis.metrics.autocorrelation_error`);
* ``hist_kl``: ``KL(exemplar || volume)``: grey histogram (32 bins) for grey exemplars, joint
  colour histogram (8 bins per channel) for colour ones, as :func:`npmrf3d.analysis.metrics.evaluate`;
* ``orient_kl``: KL of the structure-tensor orientation histograms;
* ``sw``: sliced Wasserstein distance of 7 x 7 patches at scales 1, 2 and 4
  (:func:`npmrf3d.analysis.metrics.multiscale_sliced_wasserstein`), exemplar units;
* ``top``: share of the voxels holding the most common value (flat volumes);
* ``bright``: share of voxels brighter (grey) than the exemplar's 99th percentile (sparse
  bright features such as ``hubble``'s galaxies; the exemplar and the control hold 0.01);
* ``spots``: connected bright regions (above that percentile, 8-connected within a slice)
  per slice, divided by the exemplar's count scaled to the slice area: 1.0 = as many bright
  spots as the exemplar; a volume whose bright voxels clump into a few blobs scores low even
  when ``bright`` is right (the control's isolated bright voxels score high).

Beside them, the **layout** (:func:`layout_scores`): the structure judge
(docs/structure.md) compares 8 sampled slices of each view one by one with the exemplar; its
``pyramid`` ratio to the control, divided by the floor's (the crops B judged against crop A),
averaged over the three views (``layout``) and for the worst view (``layout_worst``): 1 = as
good as crop B. ``continuity`` the same way is in the record. It needs the structure extra
(``pip install 'npmrf3d[structure]'``).

The ratio of ``hist_kl`` to the control is recorded but says little (the control draws from
the exemplar's own histogram, so its KL is only sampling noise); the targets use the value.

Add a method with one line (a callable ``(exemplar, size, levels, seed, **options) -> volume``)::

    METHODS["chen-wang"] = lambda ex, size, levels, seed, **_: chen_wang(ex, size=size, levels=levels, rng=seed).volume
"""

from __future__ import annotations

import dataclasses
import json
import math
import multiprocessing
import os
import subprocess
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Callable

import numpy as np
from scipy import ndimage

import npmrf3d
from npmrf3d.analysis import metrics, structure
from npmrf3d.analysis.metrics import layout
from npmrf3d.studies.catalog import ETR_DIR, load_exemplar

VIEWS = ("front", "right", "top")
MEASURES = ("ac", "hist_kl", "orient_kl", "sw", "top", "bright", "spots")
MAX_LAG = 8
SW_SCALES = (1, 2, 4)
SW_PATCH = 7
CROP = 64
#: Bump when the references (controls, floor) change, so cached ones are recomputed.
REFERENCE_VERSION = 4
ETR_HINT = ("the etr: exemplars are terrain photographs of Debian's extremetuxracer-data package "
            "(GPL-2+, not bundled): apt-get install -y extremetuxracer-data")


# --------------------------------------------------------------------------- methods

def _npmrf_default(ex, size, levels, seed, *, palette=None, **_):
    """``npmrf3d synth``'s default: the coherent variant (window 7 at every level)."""
    return npmrf3d.synthesize(ex, size=size, levels=levels, rng=seed, palette=palette).volume


def _npmrf_sharp(ex, size, levels, seed, *, palette=None, **_):
    """The full-Parzen rule of variant ``sharp`` (docs/model.md, section 8)."""
    return npmrf3d.synthesize(ex, size=size, levels=levels, rng=seed, palette=palette,
                              variant="sharp").volume


def _npmrf_anneal(ex, size, levels, seed, *, palette=None, **_):
    """``synth --relaxation anneal --variant coherent``: the coherent sampler annealed over its
    candidates (t0 1 to t_end 0.05 over each level's iterations)."""
    return npmrf3d.synthesize(ex, size=size, levels=levels, rng=seed, palette=palette,
                              relaxation="anneal", variant="coherent").volume


def _npmrf(**fixed):
    """``npmrf3d.synthesize`` with the coherent support and the options ``fixed`` (one
    combination of the sampler's heuristic, relaxation and temperatures)."""
    def run(ex, size, levels, seed, *, palette=None, **_):
        return npmrf3d.synthesize(ex, size=size, levels=levels, rng=seed, palette=palette,
                                  **fixed).volume
    run.__doc__ = f"npmrf3d.synthesize(..., {', '.join(f'{k}={v!r}' for k, v in fixed.items())})"
    return run


def _npmrf_coherent_with(**replaced):
    """``npmrf3d synth``'s default run (support ``coherent``) with fields of its coherent
    sampler's options replaced: the options :func:`npmrf3d.methods.npmrf._coherent_options`
    builds for the default configuration, ``replaced`` by :func:`dataclasses.replace`, run by
    :func:`npmrf3d.methods.npmrf_coherent.coherent_synthesize` (no palette) with the options the
    run reads (:func:`npmrf3d.options.recorded`: an option it would not read is refused)."""
    def run(ex, size, levels, seed, **_):
        from npmrf3d.methods import npmrf, npmrf_coherent
        from npmrf3d.options import recorded
        config = npmrf.make_config(size=size, levels=levels)
        phases = npmrf.segmented(config, {view: ex for view in config.views})
        if phases:
            raise ValueError("segmented exemplar: the default runs several pyramids; not covered")
        options = dataclasses.replace(npmrf._coherent_options(config, phases, levels), **replaced)
        fields = {k: v for k, v in recorded(options).items() if k not in ("size", "seed")}
        return npmrf_coherent.coherent_synthesize(ex, size=size, rng=seed, **fields).volume
    run.__doc__ = (f"the default coherent run with "
                   f"{', '.join(f'{k}={v!r}' for k, v in replaced.items())}")
    return run


def _npk(ex, size, levels, seed, **_):
    from npmrf3d.methods.kopf import kopf_synthesize
    return kopf_synthesize(ex, size=size, levels=levels, rng=seed).volume


#: Name -> ``(exemplar (H, W, C), size, levels, seed, **options) -> volume (N, N, N, C)``.
#: Options passed: ``palette`` (int or None; colour exemplars only, when ``--palette`` is given).
def _registered(name):
    """A method of npmrf3d's registry with its defaults (the public one-call function)."""
    def run(ex, size, levels, seed, **_):
        from npmrf3d.methods import get_method
        return get_method(name).synthesize(ex, size=size, levels=levels, rng=seed).volume
    return run


METHODS: dict[str, Callable[..., np.ndarray]] = {
    "npmrf-default": _npmrf_default,
    "npmrf-sharp": _npmrf_sharp,
    "npmrf-anneal": _npmrf_anneal,
    "npk": _npk,
    "chen-wang": _registered("chen-wang"),
    "coherent": _registered("coherent"),
}
#: The sampler's combinations over coherent candidates: each heuristic under ICM (the default's
#: iterations, or per-voxel temperatures), ML_H2a/ML_H2b annealed by each sampler.
SAMPLER_COMBINATIONS = {
    "npmrf-H1a": dict(heuristic="ML_H1a"),
    "npmrf-H1b": dict(heuristic="ML_H1b"),
    "npmrf-H2a": dict(heuristic="ML_H2a"),
    "npmrf-temperatures": dict(temperatures=True),
    "npmrf-H2a-heat-bath": dict(heuristic="ML_H2a", relaxation="anneal", sampler="heat-bath"),
    "npmrf-H2b-heat-bath": dict(heuristic="ML_H2b", relaxation="anneal", sampler="heat-bath"),
    "npmrf-H2a-metropolis": dict(heuristic="ML_H2a", relaxation="anneal", sampler="metropolis"),
    "npmrf-H2b-metropolis": dict(heuristic="ML_H2b", relaxation="anneal", sampler="metropolis"),
}
METHODS.update({name: _npmrf(**options) for name, options in SAMPLER_COMBINATIONS.items()})
#: The default run made block-local (``synth --blockwise``): up to 256^3 every level runs whole,
#: so this is the default's volume.
BLOCKWISE = {"npmrf-blockwise": dict(blockwise=True)}
METHODS.update({name: _npmrf(**options) for name, options in BLOCKWISE.items()})
#: The block-local sampler with every level below the coarsest made in blocks (``whole_voxels``
#: 1), reading the histograms of a pilot block of side 16, 32 or 64, through the coherent
#: sampler's options. At 64^3 a pilot of 32 or 64 is the whole volume (its histograms are the
#: run's own); one of 16 is a part of it: how far blocks that read another region's histograms
#: stay from the default.
BLOCK_PILOTS = {f"npmrf-blockwise-pilot-{p}": dict(blockwise=True, pilot=p, whole_voxels=1) for p in (16, 32, 64)}
METHODS.update({name: _npmrf_coherent_with(**options) for name, options in BLOCK_PILOTS.items()})
METHODS["npmrf-coherent-default"] = _npmrf_coherent_with()
#: The default run without its global histograms: the index and position histograms of the
#: candidate search and the value-histogram prior switched off (value_weight is 0 already).
HISTOGRAM_ABLATIONS = {
    "npmrf-no-histograms": dict(index_weight=0.0, position_weight=0.0, position_boost=0.0,
                                value_weight=0.0, value_prior=0.0),
    "npmrf-value-prior-only": dict(index_weight=0.0, position_weight=0.0, position_boost=0.0,
                                   value_weight=0.0),
    "npmrf-position-only": dict(index_weight=0.0, value_weight=0.0, value_prior=0.0),
}
METHODS.update({name: _npmrf_coherent_with(**options)
                for name, options in HISTOGRAM_ABLATIONS.items()})
#: The default run with fewer search + solve iterations per level (coarsest first; the default's
#: are (4, 4, 3)), with its sparse sites or with every site (``grid`` 1): what the finest level's
#: iterations, most of the run time, add to quality.
ITERATION_VARIANTS = {
    f"npmrf-{'every-site-' if grid == 1 else ''}iterations-{'-'.join(map(str, its))}": dict(iterations=its, grid=grid)
    for grid, its in ((2, (4, 4, 2)), (2, (3, 3, 2)), (2, (4, 4, 1)), (2, (2, 2, 2)), (1, (4, 4, 2)), (1, (4, 4, 1)))
}
METHODS.update({name: _npmrf_coherent_with(**options)
                for name, options in ITERATION_VARIANTS.items()})
#: The default run with another weight of its histogram prior's phase control (``synth
#: --phase-weight W``; the default's is 16): the guard that a weight chosen on scans leaves
#: photographs as they were.
PHASE_CONTROL = {f"npmrf-phase-{w}": {"phase_weight": float(w)} for w in (0, 8, 16, 32)}
METHODS.update({name: _npmrf(**options) for name, options in PHASE_CONTROL.items()})
#: The default run with the neighbourhoods of every site searched and voting (``synth --grid 1``;
#: the default's lie every 2nd voxel along both plane axes of each view).
METHODS["npmrf-every-site"] = _npmrf_coherent_with(grid=1)
#: Methods that take ``palette`` (the others never see it, and their cache key has none).
PALETTE_METHODS = {"npmrf-default", "npmrf-sharp", "npmrf-anneal", *SAMPLER_COMBINATIONS,
                   *BLOCKWISE, *PHASE_CONTROL}


# --------------------------------------------------------------------------- exemplars

@dataclasses.dataclass(frozen=True)
class Exemplar:
    """A photograph of the set: crop A (top-left ``CROP x CROP``) is the exemplar; the crops B
    (top-left corners ``crops_b``, none overlapping A) give the variability floor."""

    name: str
    source: str          # a name of npmrf3d.studies.catalog.load_exemplar
    kind: str            # stochastic / structured / sparse / layered
    held_out: bool = False
    half: bool = False   # 2 x 2 block mean first (256 x 256 terrains -> 128 x 128)
    grey: bool = False   # mean of the channels
    crops_b: tuple[tuple[int, int], ...] = ((64, 64), (0, 64), (64, 0))

    def image(self) -> np.ndarray:
        image = load_exemplar(self.source)
        if self.half:
            h, w = image.shape[0] // 2 * 2, image.shape[1] // 2 * 2
            image = image[:h, :w].reshape(h // 2, 2, w // 2, 2, -1).mean(axis=(1, 3))
        if self.grey:
            image = image.mean(axis=-1, keepdims=True)
        return np.ascontiguousarray(image, dtype=np.float32)

    def crops(self, side: int = CROP) -> tuple[np.ndarray, list[np.ndarray]]:
        """Crop A and the crops B, each ``(side, side, C)``."""
        image = self.image()
        out = []
        for r, c in self.crops_b:
            if image.shape[0] < r + side or image.shape[1] < c + side or (r < side and c < side):
                raise ValueError(f"{self.name}: {image.shape[:2]} holds no crop B at {(r, c)} "
                                 f"of side {side} apart from crop A")
            out.append(np.ascontiguousarray(image[r:r + side, c:c + side]))
        return np.ascontiguousarray(image[:side, :side]), out

    def available(self) -> bool:
        return not self.source.startswith("etr:") or (
            ETR_DIR / f"{self.source[4:]}.png").is_file()


#: Tuning set: bundled crops of scikit-image photographs (npmrf3d/data/SOURCES.md), 128 x 128.
#: Held-out set: Extreme Tux Racer terrain photographs (not in the repository), never used to
#: choose a default; two of them as grey.
EXEMPLARS: tuple[Exemplar, ...] = (
    Exemplar("gravel", "gravel", "stochastic"),
    Exemplar("brick", "brick", "structured"),
    Exemplar("grass", "grass", "stochastic"),
    Exemplar("lawn", "lawn", "stochastic"),
    Exemplar("phase_bands", "phase_bands", "layered"),
    Exemplar("pompeii_coins", "pompeii_coins", "structured"),
    Exemplar("ihc", "ihc", "stochastic"),
    Exemplar("hubble", "hubble", "sparse"),
    Exemplar("wood", "wood", "layered"),
    Exemplar("retina_vessels", "retina_vessels", "structured"),
    Exemplar("etr_pebbles04", "etr:pebbles04", "stochastic", held_out=True, half=True),
    Exemplar("etr_pave01", "etr:pave01", "structured", held_out=True, half=True),
    Exemplar("etr_sand01", "etr:sand01", "stochastic", held_out=True, half=True),
    Exemplar("etr_rock06", "etr:rock06", "structured", held_out=True, half=True),
    Exemplar("etr_floor01_grey", "etr:floor01", "stochastic", held_out=True, half=True, grey=True),
    Exemplar("etr_dirt01_grey", "etr:dirt01", "stochastic", held_out=True, half=True, grey=True),
)
QUICK = ("gravel", "hubble", "brick", "etr_pebbles04")
BY_NAME = {e.name: e for e in EXEMPLARS}


# --------------------------------------------------------------------------- measures

def grain_sigma(exemplar: np.ndarray) -> float:
    """Gaussian sigma whose smoothed white noise has the exemplar's correlation length.

    The lag ``r`` where the grey autocorrelation (mean of the row and column profiles) first
    falls to 0.5; smoothed noise has autocorrelation ``exp(-r^2 / (4 sigma^2))``, so
    ``sigma = r / (2 sqrt(ln 2))``, kept within [0.5, 8].
    """
    grey = exemplar.mean(axis=-1) if exemplar.ndim == 3 else exemplar
    lag = min(16, min(grey.shape) // 2 - 1)
    ac = metrics.autocorrelation(grey, lag)
    profile = 0.25 * (ac[lag, lag:] + ac[lag, lag::-1] + ac[lag:, lag] + ac[lag::-1, lag])
    below = np.nonzero(profile < 0.5)[0]
    if below.size == 0:
        r = float(lag)
    else:
        k = int(below[0])
        r = k - 1 + (profile[k - 1] - 0.5) / (profile[k - 1] - profile[k])
    return float(np.clip(r / (2.0 * math.sqrt(math.log(2.0))), 0.5, 8.0))


def structureless(exemplar: np.ndarray, size: int, rng: np.random.Generator) -> np.ndarray:
    """Voxels drawn independently from the exemplar's pixels: ``(size,) * 3 + (C,)``."""
    flat = exemplar.reshape(-1, exemplar.shape[-1])
    return flat[rng.integers(0, len(flat), size=size**3)].reshape((size,) * 3 + (-1,))


def blurred(exemplar: np.ndarray, control: np.ndarray) -> np.ndarray:
    """The control smoothed to the exemplar's grain, rescaled to its per-channel mean and spread."""
    s = grain_sigma(exemplar)
    out = ndimage.gaussian_filter(control.astype(np.float64), sigma=(s, s, s, 0), mode="wrap")
    flat_e = exemplar.reshape(-1, exemplar.shape[-1])
    mean, spread = out.mean(axis=(0, 1, 2)), out.std(axis=(0, 1, 2))
    out = (out - mean) / np.where(spread > 0, spread, 1.0) * flat_e.std(axis=0) + flat_e.mean(axis=0)
    return out.astype(np.float32)


def floor_volume(crops_b, size: int) -> np.ndarray:
    """The crops' non-overlapping ``size x size`` tiles as the front slices.

    Every tile appears equally often (the list is repeated until there are at least 4 slices,
    the metrics' smallest side), so pooled statistics weigh the crops equally.
    """
    if isinstance(crops_b, np.ndarray) and crops_b.ndim == 3:
        crops_b = [crops_b]
    tiles = [crop[a:a + size, b:b + size] for crop in crops_b
             for a in range(0, crop.shape[0] - size + 1, size)
             for b in range(0, crop.shape[1] - size + 1, size)]
    tiles = tiles * -(-4 // len(tiles))
    return np.stack(tiles, axis=2)


def measure(exemplar: np.ndarray, volume: np.ndarray, views=VIEWS) -> dict[str, float]:
    """The benchmark's measures of ``volume`` against ``exemplar``, averaged over ``views``."""
    volume = np.asarray(volume, dtype=np.float32)
    if volume.ndim == 3:
        volume = volume[..., None]
    c = exemplar.shape[-1]
    if c == 1:
        hist = metrics.histogram_kl(exemplar, volume)
    else:
        hist = metrics.joint_histogram_kl(exemplar, volume)
    grey_e, grey_v = exemplar.mean(axis=-1), volume.mean(axis=-1)
    threshold = np.quantile(grey_e, 0.99)
    return {
        "ac": float(np.mean([metrics.autocorrelation_error(exemplar, volume, v, MAX_LAG)
                             for v in views])),
        "hist_kl": float(hist),
        "orient_kl": float(np.mean([metrics.orientation_kl(exemplar, volume, v) for v in views])),
        "sw": float(np.mean([metrics.multiscale_sliced_wasserstein(
            exemplar, volume, v, scales=SW_SCALES, patch=SW_PATCH) for v in views])),
        "top": metrics.largest_value_share(volume),
        "bright": float(np.mean(grey_v > threshold)),
        "spots": float(np.mean([spot_density(grey_e, grey_v, threshold, v) for v in views])),
    }


def layout_scores(exemplar: np.ndarray, volume: np.ndarray, floor: dict[str, float],
                  seed: int = 0) -> dict:
    """The structure judge on every view of ``volume`` against ``exemplar``, as ratios to
    ``floor`` (the judge's ratios of the crops B, :func:`references`): ``layout`` (the mean
    ``pyramid`` over the views), ``layout_worst`` and its view, ``continuity`` (its mean) and
    the judge's whole result (``judge``)."""
    judged = layout.view_scores(volume, {v: exemplar for v in VIEWS}, {v: floor for v in VIEWS},
                                rng=seed)
    return {"layout": judged["mean"]["pyramid"], "layout_worst": judged["worst"]["pyramid"],
            "layout_worst_view": judged["worst_view"]["pyramid"],
            "continuity": judged["mean"]["continuity"], "judge": judged}


def spot_density(grey_e: np.ndarray, grey_v: np.ndarray, threshold: float, view: str) -> float:
    """Bright connected regions per slice of ``view``, relative to the exemplar's per area."""
    eight = np.ones((3, 3), dtype=bool)
    count_e = ndimage.label(grey_e > threshold, structure=eight)[1]
    slices = metrics.view_slices(grey_v[..., None], view)[..., 0]
    structure = np.zeros((3, 3, 3), dtype=bool)
    structure[1] = eight                         # no connection across slices
    count_v = ndimage.label(slices > threshold, structure=structure)[1]
    area = slices.shape[1] * slices.shape[2] / grey_e.size
    return float(count_v / len(slices) / max(count_e * area, 1e-12))


def ratios(row: dict[str, float], control: dict[str, float]) -> dict[str, float]:
    """Each measure divided by the structureless control's (1.0 = no better than noise)."""
    return {k: float(row[k] / max(control[k], 1e-12)) for k in MEASURES}


def references(exemplar: Exemplar, size: int, seed: int) -> dict[str, dict]:
    """Control, blurred control and variability floor: raw measures and ratios to the control."""
    a, b = exemplar.crops()
    rng = np.random.default_rng(seed)
    control = structureless(a, size, rng)
    smooth = blurred(a, control)
    rows = {"control": measure(a, control), "blurred": measure(a, smooth),
            "floor": measure(a, floor_volume(b, size), views=("front",))}
    out = {name: {"raw": row, "ratio": ratios(row, rows["control"])} for name, row in rows.items()}
    judge_floor = structure.image_scores(np.stack(b), a, rng=seed).ratio["images"]
    out["floor"]["judge"] = judge_floor
    out["blurred"]["layout"] = layout_scores(a, smooth, judge_floor, seed)
    out["version"] = REFERENCE_VERSION
    return out


# --------------------------------------------------------------------------- runs and cache

def run_key(method: str, exemplar: str, seed: int, size: int, palette: int | None) -> str:
    return f"{method}|{exemplar}|seed{seed}|size{size}" + (f"|palette{palette}" if palette else "")


def _effective_palette(method: str, exemplar: np.ndarray, palette: int | None) -> int | None:
    return palette if (palette and method in PALETTE_METHODS and exemplar.shape[-1] > 1) else None


def _run_one(method: str, name: str, size: int, levels: int, seed: int, palette: int | None,
             threads: int | None) -> tuple[np.ndarray, float]:
    if threads:
        from npmrf3d._kernels import _jit
        _jit.use_threads(threads)
    a, _ = BY_NAME[name].crops()
    t0 = time.perf_counter()
    volume = METHODS[method](a, size, levels, seed, palette=palette)
    return np.asarray(volume, dtype=np.float32), time.perf_counter() - t0


def _version() -> str:
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, cwd=Path(__file__).parent, check=False).stdout.strip()
    except OSError:
        commit = ""
    return f"{npmrf3d.__version__}" + (f"+{commit}" if commit else "")


def run_all(methods, names, seeds, size, levels, palette, results, cache_dir: Path, *,
            jobs=1, recompute=False, echo=print) -> None:
    """Compute the missing (method, exemplar, seed, size) cells into ``results["runs"]``."""
    todo = []
    for name in names:
        a, _ = BY_NAME[name].crops()
        for seed in seeds:
            for method in methods:
                p = _effective_palette(method, a, palette)
                key = run_key(method, name, seed, size, p)
                if recompute or key not in results["runs"]:
                    todo.append((key, method, name, seed, p))
    echo(f"{len(todo)} run(s) to compute, {jobs} at a time")
    threads = max(1, (os.cpu_count() or 1) // jobs) if jobs > 1 else None

    def store(key, method, name, seed, p, volume, seconds):
        a, _ = BY_NAME[name].crops()
        raw = measure(a, volume)
        refs = results["references"][f"{name}|seed{seed}|size{size}"]
        results["runs"][key] = {"method": method, "exemplar": name, "seed": seed, "size": size,
                                "levels": levels, "palette": p, "seconds": seconds,
                                "version": _version(), "raw": raw,
                                "ratio": ratios(raw, refs["control"]["raw"]),
                                "layout": layout_scores(a, volume, refs["floor"]["judge"], seed)}
        np.save(cache_dir / (key.replace("|", "__") + ".npy"), volume)
        r, lay = results["runs"][key]["ratio"], results["runs"][key]["layout"]
        echo(f"  {method:16s} {name:18s} seed {seed}: ac {r['ac']:.3f} hist_kl {raw['hist_kl']:.3f} "
             f"orient {r['orient_kl']:.3f} sw {r['sw']:.3f} top {raw['top']:.3f} "
             f"bright {raw['bright']:.4f} spots {raw['spots']:.2f} layout {lay['layout']:.2f} "
             f"(worst {lay['layout_worst']:.2f} {lay['layout_worst_view']})  {seconds:.1f} s"
             + (f" (palette {p})" if p else ""))

    if jobs <= 1:
        for key, method, name, seed, p in todo:
            volume, seconds = _run_one(method, name, size, levels, seed, p, None)
            store(key, method, name, seed, p, volume, seconds)
    else:
        # spawn, not fork: numba's OpenMP threading layer aborts a forked child ("fork() called
        # from a process already using GNU OpenMP") once the parent has run a parallel kernel.
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = {pool.submit(_run_one, m, n, size, levels, s, p, threads): (k, m, n, s, p)
                       for k, m, n, s, p in todo}
            for future, args in futures.items():
                store(*args, *future.result())


def remeasure(results: dict, cache_dir: Path, keys, size: int, echo=print) -> None:
    """Recompute the measures of cached runs from their saved volumes (after a metric change)."""
    for key in keys:
        run, volume = results["runs"].get(key), load_volume(cache_dir, key)
        if run is None or volume is None:
            continue
        a, _ = BY_NAME[run["exemplar"]].crops()
        control = results["references"][f"{run['exemplar']}|seed{run['seed']}|size{size}"]
        run["raw"] = measure(a, volume)
        run["ratio"] = ratios(run["raw"], control["control"]["raw"])
        run["layout"] = layout_scores(a, volume, control["floor"]["judge"], run["seed"])
    echo(f"re-measured {len(list(keys))} cached run(s)")


def load_volume(cache_dir: Path, key: str) -> np.ndarray | None:
    path = cache_dir / (key.replace("|", "__") + ".npy")
    return np.load(path) if path.is_file() else None


# --------------------------------------------------------------------------- summary

def summarise(results: dict, methods, names, seeds, size, palette) -> dict:
    """Per set (tuning / held-out) and method: mean and worst ratios, the floor's mean, verdicts."""
    out = {}
    for set_name, held in (("tuning", False), ("held-out", True)):
        members = [n for n in names if BY_NAME[n].held_out == held]
        if not members:
            continue
        refs = [results["references"][f"{n}|seed{s}|size{size}"] for n in members for s in seeds]
        block = {"exemplars": members,
                 "floor": {k: float(np.mean([r["floor"]["ratio"][k] for r in refs]))
                           for k in MEASURES},
                 "blurred": {k: float(np.mean([r["blurred"]["ratio"][k] for r in refs]))
                             for k in MEASURES},
                 "floor_hist_kl": float(np.mean([r["floor"]["raw"]["hist_kl"] for r in refs])),
                 "blurred_hist_kl": float(np.mean([r["blurred"]["raw"]["hist_kl"] for r in refs])),
                 "blurred_layout": {k: float(np.mean([r["blurred"]["layout"][k] for r in refs]))
                                    for k in ("layout", "layout_worst")},
                 "methods": {}}
        for method in methods:
            rows = []
            for n in members:
                a, _ = BY_NAME[n].crops()
                for s in seeds:
                    run = results["runs"].get(run_key(method, n, s, size,
                                                      _effective_palette(method, a, palette)))
                    if run is not None:
                        rows.append(run)
            if not rows:
                continue
            stats = {"count": len(rows), "seconds": float(np.mean([r["seconds"] for r in rows]))}
            for k in MEASURES:
                values = [r["ratio"].get(k, np.nan) for r in rows]
                stats[f"{k}_mean"], stats[f"{k}_worst"] = float(np.mean(values)), float(np.max(values))
            # the layout: runs cached before it was measured have none (--remeasure adds it)
            lay = [r["layout"] for r in rows if "layout" in r]
            stats["layout_count"] = len(lay)
            stats["layout_mean"] = float(np.mean([x["layout"] for x in lay])) if lay else float("nan")
            stats["layout_worst"] = float(np.max([x["layout_worst"] for x in lay])) if lay else float("nan")
            for k in ("hist_kl", "top", "bright", "spots"):
                values = [r["raw"].get(k, np.nan) for r in rows]
                stats[f"{k}_raw_mean"], stats[f"{k}_raw_worst"] = float(np.mean(values)), float(np.max(values))
                stats[f"{k}_raw_min"] = float(np.min(values))
            # the floor over the same cells (a partial run is compared with its own exemplars)
            floor_ac = float(np.mean([results["references"][f"{r['exemplar']}|seed{r['seed']}|"
                                                            f"size{size}"]["floor"]["ratio"]["ac"]
                                      for r in rows]))
            stats["floor_ac_same_cells"] = floor_ac
            stats["verdict"] = _verdict(results, method, rows, floor_ac, size, palette)
            block["methods"][method] = stats
        out[set_name] = block
    return out


def _verdict(results, method, rows, floor_ac, size, palette) -> dict[str, str]:
    ac = [r["ratio"]["ac"] for r in rows]
    hist = [r["raw"]["hist_kl"] for r in rows]
    v = {
        "ac_mean_within_0.1_of_floor": _yes(np.mean(ac) - floor_ac <= 0.1,
                                            f"mean {np.mean(ac):.3f} vs floor {floor_ac:.3f}"),
        "ac_worst_le_0.6": _yes(max(ac) <= 0.6, f"worst {max(ac):.3f}"),
        "hist_kl_le_0.2_everywhere": _yes(max(hist) <= 0.2, f"{sum(h <= 0.2 for h in hist)}/"
                                          f"{len(hist)} at or below, worst {max(hist):.3f}"),
    }
    if method != "npk":
        wins = total = 0
        for r in rows:
            npk = results["runs"].get(run_key("npk", r["exemplar"], r["seed"], size, None))
            if npk is not None:
                total += 1
                wins += r["raw"]["orient_kl"] <= npk["raw"]["orient_kl"]
        v["orient_kl_le_npk_on_2/3"] = (_yes(wins * 3 >= 2 * total, f"{wins}/{total}") if total
                                        else "n/a (no npk runs)")
    refs = [results["references"][f"{r['exemplar']}|seed{r['seed']}|size{size}"] for r in rows]
    beats = [r["exemplar"] for r, ref in zip(rows, refs)
             if r["ratio"]["ac"] < ref["blurred"]["ratio"]["ac"]
             and r["ratio"]["sw"] < ref["blurred"]["ratio"]["sw"]]
    v["beats_blurred_control_on_ac_and_sw"] = (
        f"{len(beats)}/{len(rows)}" + (f" ({', '.join(beats)})" if beats else ""))
    sparse = [r for r in rows if BY_NAME[r["exemplar"]].kind == "sparse"]
    if sparse:
        shares = ", ".join(f"{r['exemplar']} bright {r['raw']['bright']:.4f} spots "
                           f"{r['raw'].get('spots', float('nan')):.2f}" for r in sparse)
        v["sparse_features_survive"] = _yes(
            all(r["raw"]["bright"] >= 0.005 and r["raw"].get("spots", 0.0) >= 0.5 for r in sparse),
            f"{shares}; needs bright >= 0.005 (exemplar 0.01) and spots >= 0.5")
    return v


def _yes(ok, detail: str) -> str:
    return f"{'MET' if ok else 'NOT MET'} ({detail})"


def format_summary(summary: dict) -> str:
    lines = []
    for set_name, block in summary.items():
        lines.append(f"\n== {set_name} set: {', '.join(block['exemplars'])}")
        lines.append("runs per method: " + ", ".join(f"{m} {st['count']}"
                                                     for m, st in block["methods"].items()))
        lines.append("ac, okl (orientation KL), sw: ratios to the structureless control "
                     "(1 = no structure); hkl (histogram KL), top and spots: raw values; lay: "
                     "the structure judge's layout, a ratio to the floor (1 = as good as crop B), "
                     "mean over the views and the worst view")
        head = (f"{'':16s} {'ac mean':>8s} {'ac worst':>8s} {'okl mean':>8s} {'okl wrst':>8s} "
                f"{'sw mean':>8s} {'sw worst':>8s} {'hkl mean':>8s} {'hkl wrst':>8s} "
                f"{'top max':>8s} {'spot min':>8s} {'lay mean':>8s} {'lay wrst':>8s} {'sec':>6s}")
        lines.append(head)
        blurred_layout = block["blurred_layout"]
        for label, lay in (("floor", (1.0, 1.0)),
                           ("blurred", (blurred_layout["layout"], blurred_layout["layout_worst"]))):
            r = block[label]
            lines.append(f"{label:16s} {r['ac']:8.3f} {'':8s} {r['orient_kl']:8.3f} {'':8s} "
                         f"{r['sw']:8.3f} {'':8s} "
                         f"{block[label + '_hist_kl']:8.3f} {'':8s} {'':8s} {'':8s} "
                         f"{lay[0]:8.3f} {lay[1]:8.3f}")
        for method, s in block["methods"].items():
            lines.append(f"{method:16s} {s['ac_mean']:8.3f} {s['ac_worst']:8.3f} "
                         f"{s['orient_kl_mean']:8.3f} {s['orient_kl_worst']:8.3f} "
                         f"{s['sw_mean']:8.3f} {s['sw_worst']:8.3f} {s['hist_kl_raw_mean']:8.3f} "
                         f"{s['hist_kl_raw_worst']:8.3f} {s['top_raw_worst']:8.3f} "
                         f"{s['spots_raw_min']:8.2f} {s['layout_mean']:8.3f} {s['layout_worst']:8.3f} "
                         f"{s['seconds']:6.1f}")
        for method, s in block["methods"].items():
            lines.append(f"verdict {method} ({set_name}, the targets of docs/quality.md):")
            lines.extend(f"    {k}: {v}" for k, v in s["verdict"].items())
    return "\n".join(lines)


def save_json(path: Path, results: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(results, indent=1, sort_keys=True))
    tmp.replace(path)
