"""One run of a study, on a Dask worker or in this process: synthesise (or draw the control, or
crop the real volume), measure, and write the run's folder; a failure writes ``error.json`` and
a ``failed`` row instead of raising, so the other runs go on.

A run's folder holds ``volume.npy``, ``volume.tif``, ``preview.png``, ``run.json`` and
``metrics.json`` (written last: both present = finished), or ``error.json``.
"""

from __future__ import annotations

import math
import os
import pathlib
import socket
import time
import traceback
from collections.abc import Sequence
from datetime import datetime, timezone

import numpy as np

from .. import io
from .._kernels import _jit
from ..analysis import metrics
from ..analysis.metrics import largest_value_share, references
from ..errors import ParameterError
from ..io.runs import run_record, write_run
from ..methods import METHODS
from ..model.exemplar import named_exemplar
from . import groundtruth
from .grid import RunSpec
from .table import make_row

__all__ = ["evaluate_metrics", "execute_run", "record_failure", "structureless"]


def evaluate_metrics(volume: np.ndarray, exemplars: dict[str, np.ndarray],
                     views: Sequence[str] | None = None) -> dict:
    """:func:`npmrf3d.analysis.metrics.evaluate` of ``volume`` against the exemplars of ``views``."""
    views = tuple(exemplars) if views is None else tuple(views)
    return metrics.evaluate(volume, {v: exemplars[v] for v in views}, views=list(views))


def structureless(exemplar: np.ndarray, size: int, rng) -> np.ndarray:
    """The structureless control: ``size^3`` voxels drawn independently from the exemplar's
    pixels (same histogram, no spatial structure; :func:`npmrf3d.analysis.metrics.references.structureless`).

    >>> structureless(np.ones((4, 4, 1), np.float32), 2, 0).shape
    (2, 2, 2, 1)
    """
    return references.structureless(exemplar, (size,) * 3, rng)


def _synthesise(spec: RunSpec, exemplar: np.ndarray, real: np.ndarray | None,
                given: dict[str, np.ndarray] | None = None):
    """(volume, per-view exemplars, result or None) for one run; ``given`` holds each view's
    own exemplar (three slices of the real volume), else ``exemplar`` serves every view."""
    views = spec.views
    per_view = {v: exemplar if given is None else given[v] for v in views}
    if spec.algorithm in METHODS:
        if given is None:
            result = METHODS[spec.algorithm].synthesize(exemplar, **spec.kwargs())
        else:
            result = METHODS[spec.algorithm].synthesize(exemplars=per_view, **spec.kwargs())
        return result.volume, per_view, result
    if spec.algorithm == "control":
        return structureless(exemplar, spec.size, spec.seed), per_view, None
    if spec.algorithm == "real":
        if real is None:
            raise ParameterError("method 'real' needs a reference volume (ground-truth study)")
        n = spec.size
        return np.ascontiguousarray(real[:n, :n, :n]), per_view, None
    raise ParameterError(f"unknown algorithm {spec.algorithm!r}: registered methods are "
                         f"{', '.join(METHODS)}; study-only: control, real")


def execute_run(spec: RunSpec, study_dir: str, threads: int | None = None) -> dict:
    """Run one specification and write its folder; never raises (a failure is a row).

    Parameters
    ----------
    spec : RunSpec
    study_dir : str
        The study's output folder; the run goes to ``study_dir/spec.run_id``.
    threads : int, optional
        Numba threads for this run (None: leave the process's setting).

    Returns
    -------
    dict
        The run's row of ``results.csv`` (``status`` ``done`` or ``failed``).
    """
    run_dir = pathlib.Path(study_dir) / spec.run_id
    t_start = time.perf_counter()
    try:
        used_threads = _jit.use_threads(threads)
        (run_dir / "error.json").unlink(missing_ok=True)
        real = None
        if spec.reference is not None:
            real = groundtruth.load_reference(spec.reference)
            slices = groundtruth.exemplar_slices(real, spec.slices, spec.slice_axis, spec.slice_index)
            given = None if spec.slices == 1 else slices
            exemplar = groundtruth.pooled_exemplar(slices)
        else:
            given, exemplar = None, named_exemplar(spec.exemplar, spec.crop)
        volume, per_view, result = _synthesise(spec, exemplar, real, given)
        if real is not None:
            truth = groundtruth.compare(volume, real, exemplar)
            scores = truth.pop("slice_metrics")
        else:
            truth, scores = None, evaluate_metrics(volume, per_view, spec.views)
        measured = {"metrics": scores, "largest_value_share": largest_value_share(volume)}
        if truth is not None:
            measured["groundtruth"] = truth
        wall = time.perf_counter() - t_start
        timings = dict(getattr(result, "timings", None) or {"total": wall})
        record = run_record(
            "study", result, method=spec.algorithm if spec.algorithm in METHODS else None,
            exemplars={v: spec.exemplar for v in per_view}, threads=used_threads,
            study=spec.study, run_id=spec.run_id, spec=spec.to_dict(), seed=spec.seed,
            host=socket.gethostname(), pid=os.getpid(), wall_seconds=wall,
            labels=None if result is None or getattr(result, "labels", None) is None
            else int(len(result.labels)),
        )
        record["timings"] = timings
        title = f"{spec.study}: {spec.method} on {spec.exemplar}, seed {spec.seed}"
        (run_dir / "metrics.json").unlink(missing_ok=True)  # finished = both files, written last
        write_run(run_dir, volume=volume, exemplars=per_view, record=record, overwrite=True, title=title)
        io.write_json(run_dir / "metrics.json", measured)
        return make_row(spec, "done", record, measured)
    except Exception as exc:  # a failed run is recorded, the others go on
        return record_failure(spec, study_dir, exc, time.perf_counter() - t_start)


def record_failure(spec: RunSpec, study_dir, exc: BaseException, wall: float = math.nan) -> dict:
    """Write ``error.json`` for a failed run and return its row."""
    message = f"{type(exc).__name__}: {exc}".strip()
    error = {
        "run_id": spec.run_id,
        "error": message,
        "traceback": "".join(traceback.format_exception(exc)),
        "spec": spec.to_dict(),
        "wall_seconds": wall,
        "host": socket.gethostname(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    }
    run_dir = pathlib.Path(study_dir) / spec.run_id
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        io.write_json(run_dir / "error.json", error)
    except Exception:  # pragma: no cover - e.g. the disk is full; the row still says why
        pass
    return make_row(spec, "failed", {"wall_seconds": wall}, None, error=message)
