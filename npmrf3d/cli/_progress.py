"""The progress lines of the command line, on stderr: one over a run's pyramid, one over a
study's runs, one over a count of steps (training steps, Zarr blocks); and the one line said
when the kernels compile."""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np
from tqdm import tqdm

from .._kernels._jit import timing_compiles
from ..model.pyramid import level_shape
from . import _interrupt
from ._common import PROG, say


def side_text(shape) -> str:
    """``16^3`` for a cube, ``16x16x32`` otherwise."""
    return f"{shape[0]}^3" if len(set(shape)) == 1 else "x".join(map(str, shape))


def value_symbol(config) -> str:
    """What a run's level value is (its ``history``), for the progress line: ``T``, the global
    temperature, for the full support (ICM's sum of per-voxel temperatures, or the annealing
    temperature); ``E``, the mean patch energy, for the coherent support."""
    return "T" if getattr(config, "support", None) == "full" else "E"


class _RunLine(tqdm):
    """A tqdm line whose time left leaves out the seconds ``excluded()`` (the kernels compiling
    on a cold cache, which the rest of the run does not repeat): the rate is the share done over
    the time spent computing."""

    excluded = staticmethod(lambda: 0.0)

    @property
    def format_dict(self):
        d = super().format_dict
        computing = d["elapsed"] - self.excluded()
        if d["n"] and computing > 0:
            d["rate"] = (d["n"] - d["initial"]) / computing
        return d


class LevelProgress:
    """One line on stderr over a whole pyramid: the share of the run done, the time left, the
    level running, its step and its value (``symbol``, e.g. ``E=`` an energy, ``T=`` a temperature).

    Called as ``progress(level, step, steps, value)`` with ``step = 0`` at the start of each
    level (:func:`npmrf3d.model.pyramid.run_pyramid`), levels from the coarsest (the first one
    called, or the first one left to run after a checkpoint) to 0. Each level's share of the run
    is its share of the voxels (a finer level holds 8x those of the one before), and within a
    level the share of its ``steps`` done (a count its method may correct as it goes). The line
    counts in the steps of the level running: its ``total`` is the whole run in those steps, so
    the time left, (total - done) / (done / elapsed), is the same whatever the unit; the seconds
    the kernels spent compiling (``compiling``, a :class:`~npmrf3d._kernels._jit.CompileClock`)
    are left out of ``elapsed`` there, since the rest of the run does not repeat them. A coarser
    level called after a finer one starts a new pyramid (the segmented preset's second one) on
    a new line. ``unit`` names a step (``sweep``, ``iter``, ``pass``): the line shows the level's
    step count beside the share of the whole run.
    """

    BAR_FORMAT = "{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}{postfix}"

    def __init__(self, size: tuple[int, int, int], enabled: bool, unit: str = "sweep",
                 symbol: str = "T", compiling=None):
        self.compiling = compiling  # a CompileClock: its seconds are left out of the time left
        self.size = size
        self.enabled = enabled
        self.unit = unit
        self.symbol = symbol
        self.bar = None
        self.level = None
        self.weights: dict[int, int] = {}  # voxels per level of the pyramid running
        self.done = 0  # voxels of its finished levels

    def __call__(self, level: int, sweep: int, max_sweeps: int, temperature: float) -> None:
        _interrupt.check()  # a Ctrl-C that a callback from C swallowed ends the run here
        if not self.enabled:
            return
        steps = max(int(max_sweeps), 1)
        step = min(max(int(sweep), 0), steps)
        desc = (f"{side_text(self.size)} volume: level {level} ({side_text(level_shape(self.size, level))}), "
                f"{self.unit} {step}/{steps}")
        if self.bar is None or level > self.level:
            self._start(level, desc)
        elif level < self.level:  # the previous level finished
            self.done += self.weights[self.level]
        self.level = level
        self.bar.set_description_str(desc, refresh=False)
        if not math.isnan(temperature):  # nan: no value yet at the start of a level
            self.bar.set_postfix({self.symbol: f"{temperature:.4g}"}, refresh=False)
        scale = steps / self.weights[level]  # steps per voxel of this level
        self.bar.total = sum(self.weights.values()) * scale
        self.bar.n = self.done * scale + step
        self.bar.refresh()

    def _start(self, level: int, desc: str) -> None:
        """A new line for a pyramid whose coarsest level (left to run) is ``level``."""
        self.close()
        self.weights = {k: math.prod(level_shape(self.size, k)) for k in range(level, -1, -1)}
        self.done = 0
        # smoothing 0: the time left is from the average rate since the start, not the last step
        self.bar = _RunLine(total=1, desc=desc, file=sys.stderr, leave=True, dynamic_ncols=True,
                            smoothing=0, bar_format=self.BAR_FORMAT, unit=self.unit)
        if self.compiling is not None:
            clock, before = self.compiling, self.compiling.seconds
            self.bar.excluded = lambda: clock.seconds - before

    def note(self, text: str) -> None:
        """One line on stderr between levels (a method's optional hook: the segmented preset
        says when its second pyramid starts and which volume it kept)."""
        _interrupt.check()
        self.close()
        if self.enabled:
            say(text, error=True)

    def finish(self) -> None:
        """The run is done: the line ends full (a level may stop before the steps it expected)."""
        if self.bar is not None:
            self.bar.n = self.bar.total
        self.close()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.refresh()
            self.bar.close()
            self.bar = None


def compile_notice(enabled: bool):
    """What to call when the kernels start compiling (:func:`npmrf3d._kernels._jit.on_first_compile`):
    one line on stderr, printed above a progress line if one is drawn; None when ``enabled`` is
    false (``--quiet``)."""
    if not enabled:
        return None
    return lambda: tqdm.write(f"{PROG}: compiling the kernels once (about a minute the first "
                              f"time; later runs load them from the cache)", file=sys.stderr)


class RunsProgress:
    """tqdm over a study's runs on stderr; ``run_study(progress=...)`` calls it as
    ``progress(row, done, total)`` (``row = None`` once the runs start)."""

    def __init__(self, name: str, enabled: bool):
        self.name, self.enabled, self.bar = name, enabled, None

    def __call__(self, row: dict | None, done: int, total: int) -> None:
        _interrupt.check()
        if not self.enabled:
            return
        if self.bar is None:
            self.bar = tqdm(total=total, desc=self.name, unit="run", file=sys.stderr,
                            dynamic_ncols=True)
        if row is not None:
            self.bar.update(1)
            if row["status"] == "failed":
                self.bar.write(f"run {row['run_id']} failed: {row['error']}", file=sys.stderr)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class CountProgress:
    """One tqdm bar on stderr over a count of steps (training steps, Zarr blocks), called as
    ``progress(done, total, value)``; ``value`` (the loss) is shown as a postfix when given."""

    def __init__(self, name: str, *, unit: str, symbol: str = "", enabled: bool = True):
        self.name, self.unit, self.symbol, self.enabled, self.bar = name, unit, symbol, enabled, None

    def __call__(self, done: int, total: int, value: float | None = None) -> None:
        _interrupt.check()
        if not self.enabled:
            return
        if self.bar is None:
            self.bar = tqdm(total=total, initial=done, desc=self.name, unit=self.unit,
                            file=sys.stderr, dynamic_ncols=True)
        if value is not None and self.symbol and value == value:
            self.bar.set_postfix({self.symbol: f"{value:.4g}"}, refresh=False)
        self.bar.update(done - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def run_method(args: argparse.Namespace, method, config, per_view: dict, *, checkpoint=None,
               t_start: float | None = None, unit: str = "sweep", symbol: str | None = None, **inputs):
    """``method.run`` seeded by ``config.seed`` with one progress line over the run (none with
    ``--quiet``); ``symbol`` names the level value (None: :func:`value_symbol` of ``config``)."""
    symbol = value_symbol(config) if symbol is None else symbol
    with timing_compiles() as compiling:
        progress = LevelProgress(config.size, enabled=not args.quiet, unit=unit, symbol=symbol,
                                 compiling=compiling)
        try:
            result = method.run(per_view, config, np.random.default_rng(config.seed),
                                progress=progress, checkpoint=checkpoint, t_start=t_start, **inputs)
            progress.finish()
        finally:
            progress.close()
    _interrupt.check()  # an interrupt swallowed after the last progress tick: write nothing
    return result
