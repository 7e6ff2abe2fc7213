"""A study's input, checked as a whole before its first run and before any folder is created.

:func:`check_reference` reads the real volume of the ground-truth study (a 3-D array of finite
numbers, the slice index inside it); :func:`check_runs` loads every exemplar once (with its
crop, or the slices of the real volume) and validates every run as its method will: its keyword
arguments against the method's options and configuration (``make_config``: e.g. a size too
small for the window and the pyramid levels), its exemplars against the method's window and
levels, and, for a run on this machine, its memory. The first problem is raised as one
:class:`~npmrf3d.errors.ParameterError` naming the study and the run (or the exemplar or the
volume), so a grid that cannot run is refused whole instead of failing run by run.

What only a run can find out (a worker that dies, a disk that fills up) still makes a failed
row (:mod:`.execute`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import ParameterError
from ..methods import METHODS
from ..methods._api import prepare
from ..model.exemplar import named_exemplar
from . import groundtruth
from .grid import RunSpec

__all__ = ["check_reference", "check_runs"]


def check_reference(study: str, path, *, slice_axis: int = 0,
                    slice_index: int | None = None) -> np.ndarray:
    """The real volume at ``path`` as float32 ``(N1, N2, N3, C)``, refused (one line naming
    the study and the file) if it cannot be read, is not 3-D, holds NaN or Inf, or has no
    slice ``slice_index`` across ``slice_axis``."""
    try:
        volume = groundtruth.load_reference(path)
    except ParameterError as exc:
        raise type(exc)(f"study {study}: {exc}") from None
    if slice_axis not in (0, 1, 2):
        raise ParameterError(f"study {study}: --slice-axis must be 0, 1 or 2; got {slice_axis!r}")
    n = volume.shape[slice_axis]
    if slice_index is not None and not 0 <= int(slice_index) < n:
        raise ParameterError(
            f"study {study}: --slice-index {slice_index} is past the volume '{path}': it has "
            f"{n} slices across axis {slice_axis} (indices 0 to {n - 1})")
    return volume


def _exemplars(spec: RunSpec, real: np.ndarray | None):
    """(the run's exemplar, each view's own exemplar or None), as :mod:`.execute` makes them."""
    if spec.reference is None:
        return named_exemplar(spec.exemplar, spec.crop), None
    if real is None:
        real = groundtruth.load_reference(spec.reference)
    slices = groundtruth.exemplar_slices(real, spec.slices, spec.slice_axis, spec.slice_index)
    return groundtruth.pooled_exemplar(slices), (None if spec.slices == 1 else slices)


def _check_run(spec: RunSpec, exemplar: np.ndarray, given: dict | None, *, memory: bool) -> None:
    if spec.algorithm == "real" and spec.reference is None:
        raise ParameterError("method 'real' is a crop of the real volume, and this study has "
                             "none (it is for the ground-truth study, with --volume)")
    method = METHODS.get(spec.algorithm)
    if method is None:  # the structureless control: the exemplar is all it needs
        return
    options = spec.kwargs()
    size, rng = options.pop("size"), options.pop("rng")
    if given is None:
        prepare(method, exemplar, None, size=size, rng=rng, options=options, memory=memory)
    else:
        prepare(method, None, {v: given[v] for v in spec.views}, size=size, rng=rng,
                options=options, memory=memory)


def check_runs(study: str, specs: Sequence[RunSpec], real: np.ndarray | None = None, *,
               memory: bool = True) -> None:
    """Refuse the grid ``specs`` of study ``study`` at its first run that cannot run.

    Parameters
    ----------
    study : str
        The study's name (for the message).
    specs : sequence of RunSpec
    real : array, optional
        The real volume the runs' ``reference`` names (read again when not given).
    memory : bool
        Also refuse a run larger than this machine's available memory (False when the runs go
        to another machine's scheduler).

    Raises
    ------
    ParameterError
        ``study NAME: exemplar ...`` or ``study NAME: run RUN_ID: ...``: the first problem.
    """
    loaded: dict = {}
    for spec in specs:
        key = ((spec.exemplar, spec.crop) if spec.reference is None else
               (spec.reference, spec.slices, spec.slice_axis, spec.slice_index))
        if key not in loaded:
            try:
                loaded[key] = _exemplars(spec, real)
            except ParameterError as exc:
                raise type(exc)(f"study {study}: {exc}") from None
        try:
            _check_run(spec, *loaded[key], memory=memory)
        except ParameterError as exc:
            raise type(exc)(f"study {study}: run {spec.run_id}: {exc}") from None
