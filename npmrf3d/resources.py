"""What a run will need, computed from its configuration before anything is allocated.

Every method of :data:`npmrf3d.methods.METHODS` has a ``resources(config, exemplars)``
hook that returns an :class:`Estimate`: the peak memory of the run, split into named parts, and
where it can be guessed a rough wall time. The formulas of every built-in method are here, in
one place (why this module is over 400 lines), counted from the arrays their code allocates (numbers of bytes per voxel of the
finest level and per exemplar patch) and checked against measured peaks
(``tests/test_resources.py``: the arrays within a factor of 2 of ``tracemalloc``'s peak). The
default ``synth``'s estimate also counts the process itself and is fitted to the peak resident
memory of whole runs (``benchmarks/bench_memory_estimate.py``: within 25 %). A new method
registers its own hook (``SynthesisMethod(resources=...)``); one without a hook gets
:func:`generic_estimate` (the volume and a work copy).

:func:`check_memory` refuses an estimate beyond the machine's available memory
(:func:`available_memory`: ``MemAvailable`` of ``/proc/meminfo``, else ``os.sysconf``) with a
:class:`ResourceError`, which the command line prints as one line with exit code 2.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from .errors import ParameterError
from .model.kopf_optimise import SWEEP_CHUNK as KOPF_SWEEP_CHUNK
from .model.kopf_search import CHUNK_BYTES as KOPF_CHUNK_BYTES
from .model.parzen import KERNEL_TABLE_BYTES
from .model.phases import MAX_PHASES

__all__ = ["Estimate", "ResourceError", "available_memory", "check_memory", "coherent_patch_bytes",
           "format_bytes", "generate_estimate", "generic_estimate", "kopf_estimate", "neural_estimate",
           "npmrf_estimate", "one_after_another", "patch_count", "tile_bytes", "volume_estimate"]

#: Bytes per voxel of the finest level that the NP-MRF sampler keeps or builds: the level state
#: (volume 4C, labels 4, temperatures 4, inherited 1), the parent level (1/8 of that), the colour
#: classes (three int64 coordinates, 24) and the peak of building them (sort keys, order and
#: coordinate copies, 64 in all while the parent is alive).
NPMRF_CLASS_BUILD = 64
NPMRF_CLASSES = 24
#: Bytes of one float32 value.
F4 = 4
#: Rough throughputs on this project's 2-core machine (README, Performance), for time guesses:
#: NP-MRF multiply-adds of the patch-distance loop per second; NP_K kd-tree queries per second
#: of wall time with the optimisation phase included (the README's jobs: 64^3 ICM 89 s, guessed
#: 2 min; 64^3 Metropolis annealing 7.3 min, guessed 11 min; NP_K 128^3 2.6 min, guessed 2.5 min).
NPMRF_FLOPS = 1.3e10
KOPF_QUERIES = 6.0e4
#: ICM sweeps per level assumed by the time guess (the stop rule usually needs about 8).
ICM_SWEEPS_GUESS = 10


class ResourceError(ParameterError):
    """A run needs more memory than the machine has available (a user-facing error)."""


@dataclass(frozen=True)
class Estimate:
    """Peak memory of a run in bytes, by part, and a rough wall time in seconds (or None)."""

    parts: dict[str, int] = field(default_factory=dict)
    seconds: float | None = None

    @property
    def bytes(self) -> int:
        return int(sum(self.parts.values()))

    def describe(self) -> str:
        """One line: total, the parts, the time guess."""
        parts = ", ".join(f"{name} {format_bytes(n)}" for name, n in self.parts.items() if n)
        text = f"needs about {format_bytes(self.bytes)} ({parts})"
        if self.seconds is not None:
            text += f" and roughly {format_seconds(self.seconds)} on 2 cores"
        return text


def one_after_another(estimates) -> Estimate:
    """The estimate of runs made one after the other: the largest one's memory, the sum of the
    times (None if one is unknown).

    >>> one_after_another([Estimate({"a": 2}, 1.0), Estimate({"a": 3}, 2.0)])
    Estimate(parts={'a': 3}, seconds=3.0)
    """
    estimates = list(estimates)
    peak = max(estimates, key=lambda e: e.bytes)
    seconds = None if any(e.seconds is None for e in estimates) else sum(e.seconds for e in estimates)
    return Estimate(dict(peak.parts), seconds)


def format_bytes(n: float) -> str:
    """``1536`` -> ``'1.5 KiB'``."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def format_seconds(s: float) -> str:
    if s < 90:
        return f"{s:.0f} s"
    if s < 5400:
        return f"{s / 60:.0f} min"
    if s < 3 * 86400:
        return f"{s / 3600:.1f} h"
    return f"{s / 86400:.0f} days"


def available_memory() -> int | None:
    """Bytes the machine can give a new process now: ``MemAvailable`` of ``/proc/meminfo``,
    else free physical pages from ``os.sysconf``; None when neither is known."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def check_memory(estimate: Estimate, *, available: int | None = None,
                 hint: str = "lower --size, --levels or the exemplar size") -> None:
    """Raise :class:`ResourceError` when ``estimate`` exceeds the available memory."""
    available = available_memory() if available is None else available
    if available is None or estimate.bytes <= available:
        return
    biggest = max(estimate.parts, key=estimate.parts.get)
    raise ResourceError(
        f"this run needs about {format_bytes(estimate.bytes)} of memory (most of it for the "
        f"{biggest}); {format_bytes(available)} are available; {hint}")


# --------------------------------------------------------------------------- shapes


def _voxels(size) -> int:
    return int(math.prod(int(n) for n in size))


def patch_count(height: int, width: int, window: int, level: int, toroidal: bool = False) -> int:
    """Exemplar patches of one view at ``level``, summed over its ``4**level`` decimation
    phases (:func:`npmrf3d.model.parzen.build_view_models`)."""
    f = 2 ** level
    total = 0
    for a in range(min(f, height)):
        rows = len(range(a, height, f))
        for b in range(min(f, width)):
            cols = len(range(b, width, f))
            if toroidal:
                total += rows * cols
            elif min(rows, cols) >= window:
                total += (rows - window + 1) * (cols - window + 1)
    return total


def _shapes(exemplars) -> dict:
    """view -> (H, W, C) from view -> array or shape."""
    out = {}
    for v, a in exemplars.items():
        shape = tuple(int(x) for x in getattr(a, "shape", a))
        out[v] = shape if len(shape) > 2 else (*shape[:2], 1)
    return out


def _channels(exemplars) -> int:
    shapes = list(_shapes(exemplars).values())
    return shapes[0][2] if shapes else 1


def _distinct(exemplars) -> list:
    """The distinct exemplars (arrays by identity, shapes by value)."""
    seen = {}
    for a in exemplars.values():
        seen.setdefault(id(a) if hasattr(a, "shape") else tuple(a), a)
    return list(seen.values())


def _label_bound(exemplars) -> int:
    """At most how many labels the exemplars make: their distinct values when the arrays are
    given (cheap: exemplars are small), else their pixel count."""
    count = 0
    for a in _distinct(exemplars):
        if hasattr(a, "shape"):
            rows = np.asarray(a).reshape(-1, a.shape[2] if a.ndim > 2 else 1)
            count += len(np.unique(rows, axis=0))
        else:
            count += int(a[0]) * int(a[1])
    return count


def _pixels(exemplars) -> int:
    return sum(int(s[0]) * int(s[1]) for s in
               (getattr(a, "shape", a) for a in _distinct(exemplars)))


# --------------------------------------------------------------------------- methods


def generic_estimate(config, exemplars) -> Estimate:
    """A method without its own formula: the float32 volume and one work copy of it."""
    c = _channels(exemplars)
    volume = _voxels(config.size) * c * F4
    return Estimate({"volume": volume, "work arrays": volume})


#: Coherent search sites (site x view x iteration) per second on 2 cores: the idle wall times of
#: Chen–Wang's 64^3 colour run (3.4 s, 2.8 million sites) and of the default ``synth`` at 128^3
#: (10.0 s, 5.6 million sites at every second site) over their site counts, 0.82 and 0.56 million
#: per second (docs/benchmarks.md); the estimate is meant to within a factor of 1.5.
COHERENT_SITES = 7.0e5
#: Resident memory of a synthesis process before its arrays: the interpreter, numpy, scipy,
#: numba and the loaded kernels. Peak RSS measured (``benchmarks/bench_memory_estimate.py``,
#: ``os.wait4`` on the child): a 8^3 run 220-225 MiB, the imports alone 157 MiB; 211 MiB is
#: the intercept of the line through the 64^3 and 128^3 peaks of the default ``synth``.
RUNTIME_BYTES = 211 * 2**20
#: Bytes per voxel of the finest level that the default ``synth`` (the coherent sampler) holds
#: at its peak, per channel and besides: the slopes of its measured peak RSS from 64^3 to 128^3
#: (64 x 64 exemplars: grey 95.4 B per voxel, colour 168.6 B per voxel, ``gravel64``, ``ihc64``).
COHERENT_VOXEL_BYTES = 59
COHERENT_CHANNEL_BYTES = 36.5
#: Nearest-neighbour work of building a level model, ``P log2(P) D`` per second (P patches of
#: D PCA dimensions; a 300 x 300 noise exemplar's search took about 3 s).
TREE_RATE = 4.5e6


def coherent_patch_bytes(window: int, channels: int, dims: int = 20, k: int = 5,
                         exclude: float = 0.0) -> int:
    """Peak bytes per exemplar patch while a coherent level model is built
    (:func:`npmrf3d.model.kcoherence.build_level_model`): the patch matrix (float32,
    ``d = window**2 * C`` values), then the larger of the PCA (two float64 copies of the
    patches and the projection) and the search (the projection, its copy in the full-size
    table, the repeat check's copy, hash and groups, the k-d tree's copy and indices, the query's
    distances and indices, the k-coherence sets).

    >>> coherent_patch_bytes(7, 1)
    1140
    """
    d = window * window * channels
    dd = min(dims, d)
    want = k + 1 if exclude <= 0 else k + (2 * math.floor(exclude) + 1) ** 2
    pca = 16 * d + 8 * dd
    search = 4 * 8 * dd + 48 + 8 + 16 * want + 20 * k
    return 4 * d + max(pca, search)


def coherent_estimate(config, exemplars) -> Estimate:
    """Peak memory (and a time guess) of the coherent methods (Chen–Wang and the coherent NP-MRF
    sampler, :mod:`npmrf3d.methods.chen_wang`, :mod:`npmrf3d.methods.npmrf_coherent`).

    Four parts: the process itself (:data:`RUNTIME_BYTES`); the volume; the work arrays of the
    finest level, fitted to measured peaks (:data:`COHERENT_VOXEL_BYTES` and
    :data:`COHERENT_CHANNEL_BYTES` per voxel less the volume); the exemplar patch tables, counted
    from the arrays of each distinct exemplar's finest level model
    (:func:`coherent_patch_bytes` per patch) and its float32 copies and label set (16 C + 16
    bytes per pixel). The time guess adds the level models' nearest-neighbour searches to the
    coherent searches."""
    exemplar_shapes = _shapes(exemplars)
    n = _voxels(config.size)
    c = _channels(exemplar_shapes)
    views = len(config.views)
    volume = F4 * c * n
    work = int((COHERENT_VOXEL_BYTES + COHERENT_CHANNEL_BYTES * c) * n) - volume
    dims = getattr(config, "pca_dims", 20)
    k = getattr(config, "k", 5)
    exclude = getattr(config, "coherence_exclude", 0.0)
    tables = 0
    tree_work = 0.0
    for a in _distinct(exemplars):
        h, w_, ch = _shapes({0: a})[0]
        biggest = 0
        for level in range(config.levels):
            window = config.window[config.levels - 1 - level]
            lh, lw = h >> level, w_ >> level
            p = max(0, lh - window + 1) * max(0, lw - window + 1)
            biggest = max(biggest, p * coherent_patch_bytes(window, ch, dims, k, exclude))
            tree_work += p * math.log2(max(p, 2)) * min(dims, window * window * ch)
        tables += biggest + h * w_ * (16 * ch + 16)
    sites = sum(config.iterations[config.levels - 1 - level] * views * (n / 8 ** level)
                for level in range(config.levels)) / getattr(config, "grid", 1) ** 2
    return Estimate({"runtime": RUNTIME_BYTES, "volume": volume, "work arrays": max(0, work),
                     "exemplar patch tables": tables},
                    seconds=sites / COHERENT_SITES + tree_work / TREE_RATE)


def npmrf_estimate(config, exemplars) -> Estimate:
    """Peak memory (and a time guess) of the NP-MRF sampler, :func:`npmrf3d.synthesize`.

    ``exemplars``: view -> each constrained view's exemplar (an array, or its (H, W, C) shape).
    The label count ``K`` is bounded by the distinct values (the pixels when only shapes are
    given, or the palette / grey levels); the label kernel tables by their cap
    (:data:`npmrf3d.model.parzen.KERNEL_TABLE_BYTES`).
    (The ``coherent`` support is estimated by :func:`coherent_estimate` on its own options, see
    :func:`npmrf3d.methods.npmrf.npmrf_resources`.)
    """
    exemplar_shapes = _shapes(exemplars)
    n = _voxels(config.size)
    c = _channels(exemplar_shapes)
    views = len(exemplar_shapes)
    w = config.window
    m = w * w - 1
    state = (F4 * c + 9) * n
    parent = state // 8
    # the finest level: building the colour classes while the parent lives, then the state,
    # the classes and the up-sampling draws (int64) together
    prepare = parent + n * NPMRF_CLASSES // 8 + n * NPMRF_CLASS_BUILD
    relax = parent + state + n * NPMRF_CLASSES + 8 * n
    work = max(prepare, relax) - state
    patches = 0
    for level in range(config.levels):
        per_view = [patch_count(s[0], s[1], w, level, config.toroidal_exemplar)
                    for s in exemplar_shapes.values()]
        # each view's patch matrix (P, M*C) and its concatenation, then the padded transposed table
        level_bytes = (2 * sum(per_view) + views * max(per_view or [0])) * m * c * F4
        patches = max(patches, level_bytes)
    pixels = _pixels(exemplars)
    k = _label_bound(exemplars)
    if config.palette is not None:
        k = min(k, config.palette)
    if config.grey_levels is not None:
        k = min(k, config.grey_levels ** c)
    k = min(k, 65536)
    tables = views * k * k * 8 if views * k * k * 8 <= KERNEL_TABLE_BYTES else 0
    labels = 3 * pixels * max(c, 2) * 8 + views * k * 8 * 4
    # time: per sweep, every voxel and view scans the level's patches (M*C multiply-adds each)
    sweeps = ICM_SWEEPS_GUESS if config.relaxation == "icm" else config.proposals
    flops = 0.0
    for level in range(config.levels):
        p = max(patch_count(s[0], s[1], w, level, config.toroidal_exemplar)
                for s in exemplar_shapes.values())
        flops += sweeps * (n / 8 ** level) * views * p * m * c
    if config.relaxation == "anneal" and config.sampler == "heat-bath":
        flops *= 1.0 + k / 256
    return Estimate({"volume": state, "work arrays": work, "exemplar patch tables": patches,
                     "label tables": tables + labels}, seconds=flops / NPMRF_FLOPS)


def kopf_estimate(config, exemplars) -> Estimate:
    """Peak memory (and a time guess) of NP_K, :func:`npmrf3d.methods.kopf_synthesize`."""
    exemplar_shapes = _shapes(exemplars)
    n = _voxels(config.size)
    c = _channels(exemplar_shapes)
    views = len(config.views)
    w, g = config.window, config.grid
    volume = F4 * c * n
    # per iteration: assign (int32) and omega (float32) per view, one view's pair while searching,
    # the random order (int64, copied once), the histogram bins (float64 copies of the volume)
    loop = 8 * views * n + 8 * n + 16 * n + 24 * c * n + volume // 8
    # search: neighbourhood vectors of one batch, their centred copy, the matched patches, the
    # differences and the padded planes
    vectors = min(KOPF_CHUNK_BYTES, -(-n // (g * g)) * w * w * c * F4)
    search = 4 * vectors + volume
    sweep = min(KOPF_SWEEP_CHUNK, n) * views * (-(-w // g)) ** 2 * 16
    work = loop + max(search, sweep)
    pixels = _pixels(exemplars)
    patches = 0
    for s in {tuple(s) for s in exemplar_shapes.values()}:
        p = max(0, s[0] - w + 1) * max(0, s[1] - w + 1)
        patches += p * w * w * c * (F4 * 3 + 8)  # patches, projections, kd-tree, PCA work
    if config.constrained:
        volume_extra = 2 * volume + F4 * n
    else:
        volume_extra = 0
    queries = sum(config.iterations[config.levels - 1 - level] * views * (n / 8 ** level) / (g * g)
                  for level in range(config.levels))
    return Estimate({"volume": volume, "work arrays": work + volume_extra,
                     "exemplar patch tables": patches + 8 * pixels * c},
                    seconds=queries / KOPF_QUERIES)


def volume_estimate(config, exemplars) -> Estimate:
    """Peak memory of a run of the 3D-exemplar methods (``volume-lh``, ``npmrf-3d``): per output
    voxel the coordinates (int64 x 3, two copies while a sub-pass runs, three while up-sampling),
    the frames (9 float32, when a field is used) and the jitter (3 float32); per exemplar voxel
    the appearance space (float64 x dims, twice while it is built), the similarity sets (int64 x
    k, and as positions int64 x 3k) and the smoothed exemplar (float64 x C), and with the phase
    histogram the phases (int64), the cost (float64) and the phase mix (float32 x phases,
    counted as ``MAX_PHASES``, twice while it is built)."""
    n = int(np.prod(config.size))
    shape = next(iter(dict(exemplars).values()))
    shape = tuple(np.shape(shape)) if not isinstance(shape, tuple) else shape
    m = int(np.prod(shape[:3]))
    c = shape[3] if len(shape) > 3 else 1
    field = 0 if config.vector_field == "none" else 36 * n
    return Estimate({"coordinates": 3 * 24 * n + 12 * n + 4 * c * n, "vector field": field,
                     "exemplar model": m * (16 * config.pca_dims + 32 * config.k + 16 * c),
                     "phase histogram": m * (16 + 8 * MAX_PHASES) if config.balance else 0},
                    seconds=n / 2.0e5)


#: The neural generator: live float32 tensors of the finest scale's channel count while one tile
#: is computed (the block input, its convolution, normalisation and activation, the
#: concatenation; measured peak of a 64^3 tile: about 5 such tensors).
TILE_TENSORS = 6
#: The neural generator's throughput (output voxels per second) on this project's 2-core
#: machine, for time guesses.
VOXELS_PER_SECOND = 2.5e5


def tile_bytes(config) -> int:
    """Working memory of the neural generator's generation (``config`` a
    :class:`npmrf3d.methods.neural.NeuralConfig`): the finest scale's activations of one tile
    with its margins, times the tiles computed at once (one per core)."""
    side = config.tile + 8
    return TILE_TENSORS * F4 * config.channel_step * config.scales * side ** 3 * (os.cpu_count() or 1)


def neural_estimate(config, exemplars) -> Estimate:
    """Peak memory (and a time guess) of the neural method: the volume, one tile's work, the
    training slices (``batch`` per view, forward and backward; their side
    ``config.slice_side(exemplar shape)``)."""
    shapes = [tuple(getattr(a, "shape", a)) for a in exemplars.values()]
    channels = shapes[0][2] if shapes and len(shapes[0]) > 2 else 1
    voxels = math.prod(config.size)
    side = config.slice_side(shapes[0] if shapes else None) + 8
    train = 3 * 3 * F4 * config.channel_step * config.scales * side * side * 9 * config.batch
    return Estimate({"volume": F4 * channels * voxels, "work arrays": tile_bytes(config) + train},
                    seconds=voxels / VOXELS_PER_SECOND)


def generate_estimate(model, shape) -> Estimate:
    """Memory of one block of a trained neural generator (``model.channels``, ``model.config``):
    the float32 block and one tile's work."""
    return Estimate({"volume": F4 * model.channels * math.prod(shape), "work arrays": tile_bytes(model.config)})
