"""Multi-scale grids and the one coarse-to-fine level loop (docs/model.md, section 7).

Level ``l`` is the level-0 grid decimated by ``2**l``; synthesis runs from ``l = levels - 1``
down to 0. The voxel of level ``l - 1`` at ``2 * (i, j, k)`` is the *inherited* child of voxel
``(i, j, k)`` of level ``l``: it always receives the parent's value and temperature 0. With
``1/8`` up-sampling the other 7 children are re-initialised by random draws from the exemplar
(temperature 1); with ``8/8`` they copy the parent's value (temperature 1); ``trilinear``
(Kopf et al. 2007, continuous values only) interpolates the parent on the torus.

:func:`run_pyramid` is the level loop every multi-scale method shares (the NP-MRF sampler, NP_K,
the k-coherence engine of Chen–Wang and the coherent sampler, the coordinate pyramid of
volume-lh and npmrf-3d): initialise the coarsest level, up-sample into each finer one, relax
it, report progress, write a checkpoint after each level and resume from one. A method gives
it a :class:`Levels` object that knows how to do those steps for its own state, and what a
checkpoint of each level must hold (:meth:`Levels.array_specs`): a checkpoint is resumed only
when every member is what that level of this run writes.
"""

from __future__ import annotations

import copy
import json
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy import ndimage

from .._kernels._jit import thread_count
from .regions import Frame, RegionPlan, whole_frame
from ..io.checkpoints import (KEY, check_array, check_members, check_rng_state, load_run_state,
                              refusal, save_run_state)

__all__ = ["ArraySpec", "INHERIT", "LABEL_UPSAMPLING", "LevelState", "Levels", "UPSAMPLERS",
           "UPSAMPLING", "level_shape", "random_state", "run_pyramid", "upsample"]

INHERIT = ("resynth", "fixed")

#: ``progress(level, step, steps, value)``: ``step = 0`` before the first step of a level.
ProgressCallback = Callable[[int, int, int, float], None]


@dataclass
class LevelState:
    """The mutable state of one level: values, label indices, temperatures, inherited mask."""

    volume: np.ndarray  # (N1, N2, N3, C) float32
    labels_volume: np.ndarray  # (N1, N2, N3) int32
    temps: np.ndarray  # (N1, N2, N3) float32
    inherited: np.ndarray  # (N1, N2, N3) bool


def level_shape(size: tuple[int, int, int], level: int) -> tuple[int, int, int]:
    """Grid shape of ``level`` (size divided by ``2**level``)."""
    return tuple(n // 2 ** level for n in size)


def random_state(shape, labels: np.ndarray, label_freq: np.ndarray, rng: np.random.Generator) -> LevelState:
    """Every voxel a label drawn from the exemplar's label frequencies, temperature 1."""
    drawn = rng.choice(len(labels), size=shape, p=label_freq).astype(np.int32)
    return LevelState(
        volume=np.ascontiguousarray(labels[drawn], dtype=np.float32),
        labels_volume=drawn,
        temps=np.ones(shape, dtype=np.float32),
        inherited=np.zeros(shape, dtype=bool),
    )


# --------------------------------------------------------------------------- up-sampling


def _inherit(child: LevelState, parent: LevelState) -> LevelState:
    child.volume[::2, ::2, ::2] = parent.volume
    child.labels_volume[::2, ::2, ::2] = parent.labels_volume
    child.temps[::2, ::2, ::2] = 0.0
    child.inherited[::2, ::2, ::2] = True
    return child


def upsample_one_of_eight(parent: LevelState, labels, label_freq, rng) -> LevelState:
    """``1/8``: the inherited child keeps the parent; the other 7 are random exemplar draws."""
    shape = tuple(2 * n for n in parent.labels_volume.shape)
    return _inherit(random_state(shape, labels, label_freq, rng), parent)


def upsample_eight_of_eight(parent: LevelState, labels, label_freq, rng) -> LevelState:
    """``8/8``: all 8 children copy the parent (only the inherited one at temperature 0)."""
    shape = tuple(2 * n for n in parent.labels_volume.shape)
    lab = parent.labels_volume
    for axis in range(3):
        lab = np.repeat(lab, 2, axis=axis)
    vol = parent.volume
    for axis in range(3):
        vol = np.repeat(vol, 2, axis=axis)
    child = LevelState(np.ascontiguousarray(vol), np.ascontiguousarray(lab),
                       np.ones(shape, dtype=np.float32), np.zeros(shape, dtype=bool))
    return _inherit(child, parent)


def upsample_trilinear(parent: LevelState, labels, label_freq, rng) -> LevelState:
    """``trilinear`` (Kopf et al. 2007): interpolate the values on the torus; no labels, no
    inherited voxels (for methods with continuous values)."""
    out = ndimage.zoom(parent.volume, (2, 2, 2, 1), order=1, mode="grid-wrap", grid_mode=True)
    shape = out.shape[:3]
    return LevelState(np.ascontiguousarray(out, dtype=np.float32), np.zeros(shape, dtype=np.int32),
                      np.zeros(shape, dtype=np.float32), np.zeros(shape, dtype=bool))


class Upsampler(NamedTuple):
    """One way of initialising a finer level: ``fn(parent, labels, label_freq, rng)``."""

    fn: Callable[[LevelState, np.ndarray, np.ndarray, np.random.Generator], LevelState]
    labels: bool  # keeps label indices (usable by the label-based NP-MRF sampler)
    description: str


#: Up-sampling choices by name (docs/model.md, section 7, and Kopf et al. 2007).
UPSAMPLERS: dict[str, Upsampler] = {
    "1/8": Upsampler(upsample_one_of_eight, True,
                     "keep only the inherited voxel and draw the other 7 at random"),
    "8/8": Upsampler(upsample_eight_of_eight, True, "copy the parent into all 8 children"),
    "trilinear": Upsampler(upsample_trilinear, False,
                           "trilinear interpolation of the values (continuous methods only)"),
}
#: The choices of the label-based NP-MRF sampler.
LABEL_UPSAMPLING = tuple(name for name, u in UPSAMPLERS.items() if u.labels)
#: The NP-MRF sampler's choices (the same as LABEL_UPSAMPLING).
UPSAMPLING = LABEL_UPSAMPLING


def upsample(parent: LevelState, mode: str, labels: np.ndarray, label_freq: np.ndarray,
             rng: np.random.Generator) -> LevelState:
    """Up-sample a relaxed level to the next finer one (``mode`` a name of :data:`UPSAMPLERS`)."""
    return UPSAMPLERS[mode].fn(parent, labels, label_freq, rng)


# --------------------------------------------------------------------------- the level loop


class ArraySpec(NamedTuple):
    """What one array of a level's checkpoint must be: its exact shape and dtype, and bounds of
    its values (inclusive, broadcast against the array; None: any finite value)."""

    shape: tuple[int, ...]
    dtype: Any
    low: Any = None
    high: Any = None


#: Members every checkpoint of the level loop holds besides the method's arrays.
LOOP_MEMBERS = (KEY, "level", "rng_state", "history", "timings", "stats")


class Levels(ABC):
    """What a multi-scale method tells :func:`run_pyramid` (override every method).

    Attributes
    ----------
    size : (N1, N2, N3)
    levels : int
    key : str
        Identity of the run (:func:`npmrf3d.io.checkpoints.run_key`); a checkpoint with another
        key is refused.
    fingerprint : dict of arrays
        Further arrays a checkpoint must match (e.g. the label set, which depends on the
        exemplar).

    Random numbers are drawn from the loop's generator in the order the loop calls the
    methods: per level :meth:`prepare` (draws none), :meth:`initial` or :meth:`upsample`, then
    :meth:`relax`. State a method keeps across levels besides the level's state (e.g. a phase
    control) belongs in :meth:`to_arrays` / :meth:`from_arrays`, so that a resumed run goes on
    exactly as the uninterrupted one.
    """

    size: tuple[int, int, int]
    levels: int
    key: str
    fingerprint: dict[str, np.ndarray] = {}
    #: The region of the current level's grid the loop runs (:mod:`npmrf3d.model.regions`); set
    #: by :func:`run_pyramid` before each level's :meth:`prepare`.
    frame: Frame | None = None

    def aprons(self) -> tuple[int | None, ...] | None:
        """Per level (0 the finest), how far a level's result reaches over its iterations (a
        region grown by it gives its core exactly: :mod:`npmrf3d.model.regions`), None for a
        level that runs whole; None when the method cannot run on a region at all. A method
        with aprons also defines ``crop(state, index)``: the part of a level's state at the
        per-axis array indices ``index``."""
        return None

    def after_level(self, level: int, state: Any, rng: np.random.Generator) -> None:
        """Called with each finished level's whole or regional state (also one resumed from a
        checkpoint), before it is cut to a region and up-sampled: a method may keep what its
        finer levels need from it (statistics of a level that runs whole). ``rng`` is the run's
        generator at that point: a method may copy it, never draw from it."""

    def prepare(self, level: int, shape: tuple[int, int, int]) -> None:
        """Per-level set-up that draws no random numbers (models, exemplar pyramids)."""

    @abstractmethod
    def initial(self, shape: tuple[int, int, int], rng: np.random.Generator) -> Any:
        """The coarsest level's starting state."""

    @abstractmethod
    def upsample(self, state: Any, rng: np.random.Generator) -> Any:
        """The finer level's starting state from the relaxed coarser ``state``."""

    @abstractmethod
    def start(self, level: int, state: Any) -> tuple[int, float]:
        """(steps expected, the level quantity before the first step) for progress; ``relax``
        may correct the expected steps as it goes (``on_step(step, value, expected)``)."""

    @abstractmethod
    def relax(self, level: int, state: Any, rng: np.random.Generator,
              on_step: Callable[[int, float], None]) -> tuple[Any, list[float], dict]:
        """Relax one level: (state, history of the level quantity, level statistics)."""

    @abstractmethod
    def to_arrays(self, state: Any) -> dict[str, np.ndarray]:
        """The state, and the method's own state carried across levels, as named arrays (for a
        checkpoint)."""

    @abstractmethod
    def from_arrays(self, arrays: dict[str, np.ndarray]) -> Any:
        """Inverse of :meth:`to_arrays`: restores the method's own state, returns the level's."""

    @abstractmethod
    def array_specs(self, level: int, shape: tuple[int, int, int]) -> dict[str, ArraySpec]:
        """What :meth:`to_arrays` writes after relaxing ``level`` (grid ``shape``): name ->
        :class:`ArraySpec`, every name it writes and nothing else. A checkpoint is resumed only
        when it holds exactly these (and :attr:`fingerprint`), so :meth:`from_arrays` never
        sees an array of another shape, dtype or range."""


@dataclass
class PyramidRun:
    """What :func:`run_pyramid` returns: the finest state and the run's records."""

    state: Any
    history: list[list[float]]
    timings: dict
    stats: dict


def run_pyramid(method: Levels, rng: np.random.Generator, *, progress: ProgressCallback | None = None,
                checkpoint: str | Path | None = None, timings: dict | None = None,
                stats: dict | None = None, t_start: float | None = None,
                region: RegionPlan | None = None, after: tuple[int, Any] | None = None) -> PyramidRun:
    """Run ``method`` from its coarsest level to level 0.

    Parameters
    ----------
    method : Levels
    rng : numpy Generator
        The only source of randomness; restored from the checkpoint on resume.
    progress : callable, optional
        ``progress(level, step, steps, value)`` before the first step of a level (``step = 0``)
        and after every step; ``steps`` is the number of steps expected on the level, which a
        method may correct as it goes (ICM: the sweeps its stop rule will need).
    checkpoint : path, optional
        A ``.npz`` file written after each level; if it exists and matches ``method.key`` and
        ``method.fingerprint``, the run resumes after its last finished level.
    timings, stats : dict, optional
        Start values; per-level entries are added. Default: the ``setup`` time since
        ``t_start`` and the ``threads`` numba's loops use.
    t_start : float, optional
        ``time.perf_counter()`` when the run started (for ``timings["total"]``).
    region : RegionPlan, optional
        Make one block of the finest level from its dependency cone (a method with
        :meth:`Levels.aprons`): every level runs its region, a finished level is cut to the
        parents of the next one's, and the returned state is the block's. The levels that run
        whole (the coarsest ones) come from the checkpoint ``region.start``, made by the first
        block that finds none and resumed by every other, so all blocks share them; no
        ``checkpoint`` then. None: the whole grid.
    after : (level, state), optional
        Start after the finished whole ``level`` given as ``state`` (instead of a checkpoint).
    """
    t_start = time.perf_counter() if t_start is None else t_start
    timings = {"setup": time.perf_counter() - t_start} if timings is None else dict(timings)
    stats = {"threads": thread_count()} if stats is None else dict(stats)
    stats.setdefault("levels", {})
    history: list[list[float]] = []
    state = None
    first_level = method.levels - 1
    if region is not None:
        if checkpoint is not None or method.aprons() is None:
            raise ValueError("a region runs without a checkpoint, for a method with aprons only")
        checkpoint = region.start
    resumed = None if after is not None else _load(checkpoint, method, rng, shared=region is not None)
    if after is not None:
        done_level, state = after
        first_level = done_level - 1
    elif resumed is not None:
        state, done_level, rng_state, history, timings, stats = resumed
        rng.bit_generator.state = rng_state
        first_level = done_level - 1
        method.after_level(done_level, state, rng)
    for level in range(first_level, -1, -1):
        t0 = time.perf_counter()
        frame = None if region is None else region.frames[level]
        method.frame = whole_frame(level_shape(method.size, level)) if frame is None else frame
        shape = method.frame.shape
        method.prepare(level, shape)
        if state is not None and frame is not None:
            state = method.crop(state, region.parents(level))
        state = method.initial(shape, rng) if state is None else method.upsample(state, rng)
        steps, value = method.start(level, state)

        def on_step(step, value, expected=None, level=level, steps=steps):
            if progress is not None:
                progress(level, step, steps if expected is None else expected, value)

        if progress is not None:
            progress(level, 0, steps, value)
        state, level_history, level_stats = method.relax(level, state, rng, on_step)
        history.append(level_history)
        timings[f"level_{level}"] = time.perf_counter() - t0
        stats["levels"][f"level_{level}"] = level_stats
        method.after_level(level, state, rng)
        if checkpoint is not None and frame is None:  # a region's own levels are not kept
            save_run_state(
                checkpoint, method.key, **method.fingerprint, **method.to_arrays(state),
                level=level, rng_state=json.dumps(rng.bit_generator.state),
                history=json.dumps(history), timings=json.dumps(timings),
                stats=json.dumps(stats, default=str),
            )
    if region is not None:
        state = method.crop(state, region.block_indices())
    timings["total"] = time.perf_counter() - t_start
    return PyramidRun(state, history, timings, stats)


def _load(path, method: Levels, rng: np.random.Generator, *, shared: bool = False):
    """State after the last finished level, or None when there is nothing to resume
    (:func:`_read`, or :func:`_read_shared` for a block run's start, then the method's state of
    its arrays)."""
    read = (_read_shared if shared else _read)(path, method, rng)
    if read is None:
        return None
    arrays, *rest = read
    return (method.from_arrays(arrays), *rest)


#: The last block start read in this process (:func:`_read_shared`): its file's identity and
#: what :func:`_read` made of it.
_START: dict = {}


def _read_shared(path, method: Levels, rng: np.random.Generator):
    """:func:`_read` of a block run's start (the levels that run whole, shared by all blocks),
    once per process: a worker's later blocks take it from memory as long as the file is the
    same (path, size, modification time) and so is the run. The arrays are read-only, the
    lists and dicts copied."""
    try:
        stat = Path(path).stat()
    except (OSError, TypeError):
        return _read(path, method, rng)
    key = (str(Path(path).resolve()), stat.st_size, stat.st_mtime_ns, method.key)
    if key not in _START:
        read = _read(path, method, rng)
        if read is None:
            return None
        for value in read[0].values():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
        _START.clear()
        _START[key] = read
    arrays, level, rng_state, history, timings, stats = _START[key]
    return arrays, level, copy.deepcopy(rng_state), copy.deepcopy(history), dict(timings), copy.deepcopy(stats)


def _read(path, method: Levels, rng: np.random.Generator):
    """What a checkpoint holds after the last finished level -- its arrays, level, random
    state, history, timings and stats -- or None when there is nothing to resume.

    Past its checksum and identity (:func:`npmrf3d.io.checkpoints.load_run_state`) every member
    is checked against what this run writes at the saved level; anything else is refused with
    the one checkpoint refusal (:func:`npmrf3d.io.checkpoints.refusal`)."""
    data = load_run_state(path, method.key, fingerprint=method.fingerprint)
    if data is None:
        return None
    level = data.get("level")
    if isinstance(level, bool) or not isinstance(level, int) or not 0 <= level < method.levels:
        raise refusal(path, f"'level' is {level!r}; this run has levels 0 to {method.levels - 1}")
    specs = method.array_specs(level, level_shape(method.size, level))
    check_members(path, data, [*LOOP_MEMBERS, *method.fingerprint, *specs])
    arrays = {name: check_array(path, data, name, *spec) for name, spec in specs.items()}
    rng_state = check_rng_state(path, data["rng_state"], rng.bit_generator)
    history = _json_member(path, data, "history", list)
    if len(history) != method.levels - level or not all(
            isinstance(h, list) and all(_is_number(v) for v in h) for h in history):
        raise refusal(path, f"'history' is not {method.levels - level} lists of numbers, one per "
                            f"level finished")
    timings = _json_member(path, data, "timings", dict)
    if not all(_is_number(v) for v in timings.values()):
        raise refusal(path, "'timings' holds a value that is not a number")
    stats = _json_member(path, data, "stats", dict)
    if not isinstance(stats.get("levels"), dict):
        raise refusal(path, "'stats' has no per-level statistics")
    return arrays, level, rng_state, history, timings, stats


def _json_member(path, data, name: str, kind: type):
    """Member ``name``: JSON text of a ``kind`` (list or dict)."""
    try:
        value = json.loads(data[name]) if isinstance(data[name], str) else None
    except ValueError:
        value = None
    if not isinstance(value, kind):
        raise refusal(path, f"'{name}' is not the JSON text of a {kind.__name__}")
    return value


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)
