"""The progress bars of the command line, on stderr: one per pyramid level, one over a
study's runs, one over a count of steps (training steps, Zarr blocks)."""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np
from tqdm import tqdm

from ..model.pyramid import level_shape
from . import _interrupt
from ._common import say


class LevelProgress:
    """One tqdm bar per level on stderr: steps (``unit``) done, a level quantity as postfix.

    Called as ``progress(level, step, steps, value)`` with ``step = 0`` at the start of each
    level (:func:`npmrf3d.model.pyramid.run_pyramid`): sweeps and the global temperature ``T`` for
    synth, iterations and the energy ``E`` for NP_K.
    """

    def __init__(self, size: tuple[int, int, int], enabled: bool, unit: str = "sweep",
                 symbol: str = "T"):
        self.size = size
        self.enabled = enabled
        self.unit = unit
        self.symbol = symbol
        self.bar = None

    def __call__(self, level: int, sweep: int, max_sweeps: int, temperature: float) -> None:
        _interrupt.check()  # a Ctrl-C that a callback from C swallowed ends the run here
        if not self.enabled:
            return
        if sweep == 0 or self.bar is None:
            self.close()
            shape = level_shape(self.size, level)
            side = f"{shape[0]}^3" if len(set(shape)) == 1 else "x".join(map(str, shape))
            self.bar = tqdm(total=max_sweeps, desc=f"level {level} ({side})", unit=self.unit,
                            file=sys.stderr, leave=True, dynamic_ncols=True)
        if not math.isnan(temperature):  # nan: no value yet at the start of a level
            self.bar.set_postfix({self.symbol: f"{temperature:.4g}"}, refresh=False)
        if max_sweeps != self.bar.total:  # the method corrected its expected step count
            self.bar.total = max_sweeps
        if sweep > self.bar.n:
            self.bar.update(sweep - self.bar.n)
        else:
            self.bar.refresh()

    def note(self, text: str) -> None:
        """One line on stderr between levels (a method's optional hook: the segmented preset
        says when its second pyramid starts and which volume it kept)."""
        _interrupt.check()
        self.close()
        if self.enabled:
            say(text, error=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.total = self.bar.n
            self.bar.refresh()
            self.bar.close()
            self.bar = None


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
               t_start: float | None = None, unit: str = "sweep", symbol: str = "T", **inputs):
    """``method.run`` seeded by ``config.seed`` with a bar per level (none with ``--quiet``)."""
    progress = LevelProgress(config.size, enabled=not args.quiet, unit=unit, symbol=symbol)
    try:
        result = method.run(per_view, config, np.random.default_rng(config.seed), progress=progress,
                            checkpoint=checkpoint, t_start=t_start, **inputs)
    finally:
        progress.close()
    _interrupt.check()  # an interrupt swallowed after the last progress tick: write nothing
    return result
