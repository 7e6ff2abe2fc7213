"""Run a study's grid on Dask (or serially) and write its runs, table and figures.

(Why over 400 lines: besides the runner, the up-front checks that refuse a bad --workers,
--threads, --scheduler address or study folder before anything is created live here, beside
the only code that uses them.)

Layout of the output (``OUT`` is ``--out``)::

    OUT/<study>/study.json            declaration, options, scheduler, versions, wall time,
                                      methods left out (``left_out``: optional extra missing)
    OUT/<study>/results.csv           one row per run (status, timings, metrics)
    OUT/<study>/*.png, *.csv          figures and the numbers behind them
    OUT/<study>/<run_id>/             volume.npy, volume.tif, preview.png, run.json, metrics.json
                                      or error.json for a failed run

Behaviour
---------
* **Schedulers**: ``scheduler=None`` (or ``"local"``) starts a ``dask.distributed``
  ``LocalCluster`` of ``workers`` single-threaded worker processes whose numba kernels use
  ``threads`` threads each, with ``workers x threads <= cores`` (``NUMBA_NUM_THREADS`` is set
  in the workers' environment before they start, and again inside each task); an address
  (``tcp://host:8786``) connects to an existing scheduler, whose workers keep their own
  ``NUMBA_NUM_THREADS``; ``"serial"`` runs in this process, one run after the other. The
  dashboard address is printed (it needs ``bokeh`` to be served).
* **Same results everywhere**: every run is seeded by its own seed only and numba kernels do
  not depend on the thread count, so Dask and serial execution write identical volumes.
* **Resumable**: a run whose folder holds ``run.json`` and ``metrics.json`` is finished and is
  skipped (its row is read back from disk); a failed run is tried again.
* **Failures**: an exception in a run writes ``error.json`` (message and traceback) into its
  folder and a ``failed`` row; the other runs go on.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pathlib
import socket
import time
import traceback
from collections.abc import Callable, Sequence
from datetime import datetime, timezone

import numpy as np

from .. import io
from .._cluster import local_cluster
from .._kernels import _jit
from ..analysis import metrics
from ..analysis.metrics import METRICS, largest_value_share
from ..errors import ParameterError
from ..io.runs import run_record, write_run
from ..methods import METHODS
from ..model.exemplar import named_exemplar
from . import groundtruth
from .figures import make_figures
from .grid import RunSpec, Study
from .table import (
    BASE_COLUMNS,
    is_finished,
    load_row,
    make_row,
    read_results,  # noqa: F401 (re-exported: runner.read_results)
    write_csv,
)

__all__ = [
    "StudyOutcome",
    "evaluate_metrics",
    "execute_run",
    "is_finished",
    "leave_out_unavailable",
    "plan_workers",
    "read_results",
    "run_study",
    "structureless",
]

#: The metrics of the studies (the paper's three first), as :data:`npmrf3d.analysis.metrics.METRICS`.
HEADLINE_METRICS = METRICS

# --------------------------------------------------------------------------- metrics

def evaluate_metrics(volume: np.ndarray, exemplars: dict[str, np.ndarray],
                     views: Sequence[str] | None = None) -> dict:
    """:func:`npmrf3d.analysis.metrics.evaluate` of ``volume`` against the exemplars of ``views``."""
    views = tuple(exemplars) if views is None else tuple(views)
    return metrics.evaluate(volume, {v: exemplars[v] for v in views}, views=list(views))

def structureless(exemplar: np.ndarray, size: int, rng) -> np.ndarray:
    """The structureless control: ``size^3`` voxels drawn independently from the exemplar's
    pixels (same histogram, no spatial structure).

    >>> structureless(np.ones((4, 4, 1), np.float32), 2, 0).shape
    (2, 2, 2, 1)
    """
    generator = np.random.default_rng(rng)
    flat = np.asarray(exemplar, dtype=np.float32).reshape(-1, exemplar.shape[-1])
    picks = generator.integers(0, len(flat), size=size ** 3)
    return flat[picks].reshape(size, size, size, flat.shape[1])

# --------------------------------------------------------------------------- one run

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
            "study", result, method=spec.algorithm if spec.algorithm in METHODS else None, exemplars={v: spec.exemplar for v in per_view}, threads=used_threads,
            study=spec.study, run_id=spec.run_id, spec=spec.to_dict(), seed=spec.seed,
            host=socket.gethostname(), pid=os.getpid(), wall_seconds=wall,
            labels=None if result is None or getattr(result, "labels", None) is None
            else int(len(result.labels)),
        )
        record["timings"] = timings
        title = f"{spec.study}: {spec.method} on {spec.exemplar}, seed {spec.seed}"
        (run_dir / "metrics.json").unlink(missing_ok=True)  # finished = both files, written last
        write_run(run_dir, volume=volume, exemplars=per_view, record=record, overwrite=True,
                     title=title)
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

# --------------------------------------------------------------------------- schedulers

class _Progress:
    """Counts finished runs and hands each to the caller's ``progress(row, done, total)``
    (``row = None`` when the runs start); the library draws no bar itself."""

    def __init__(self, callback, total: int):
        self.callback = callback if callable(callback) else None
        self.total, self.done = total, 0

    def start(self) -> None:
        if self.callback is not None:
            self.callback(None, 0, self.total)

    def __call__(self, row: dict) -> None:
        self.done += 1
        if self.callback is not None:
            self.callback(row, self.done, self.total)


def plan_workers(workers: int | None, threads: int | None, cores: int | None = None) -> tuple[int, int]:
    """(workers, numba threads per worker) with ``workers * threads <= cores``.

    >>> plan_workers(None, None, 8)
    (8, 1)
    >>> plan_workers(2, None, 8)
    (2, 4)
    >>> plan_workers(None, 3, 8)
    (2, 3)
    """
    cores = max(1, int(cores or os.cpu_count() or 1))
    if workers is not None and workers < 1:
        raise ParameterError(f"--workers must be a positive integer; got {workers}")
    if threads is not None and threads < 1:
        raise ParameterError(f"--threads must be a positive integer; got {threads}")
    if workers is None:
        threads = 1 if threads is None else threads
        workers = max(1, cores // threads)
    elif threads is None:
        threads = max(1, cores // workers)
    if workers * threads > cores:
        raise ParameterError(f"{workers} workers x {threads} numba threads exceed the {cores} "
                             f"cores of this machine; use fewer --workers or --threads")
    return workers, threads

def _start_local_cluster(workers: int):
    """A LocalCluster of ``workers`` processes of one Dask thread each
    (:func:`npmrf3d._cluster.local_cluster`).

    The numba thread count is not put in the workers' environment as ``NUMBA_NUM_THREADS``: a
    spawned worker imports the parent's main module (a study script imports numba) before the
    Nanny's environment is applied, so numba's pool would be sized already and the first
    compilation in the worker (a fresh install, an empty cache) would fail with "Cannot set
    NUMBA_NUM_THREADS to a different value once the threads have been launched". Each run sets
    its numba threads itself (:func:`execute_run` calls ``use_threads``) and BLAS runs
    single-threaded inside the kernels (``single_threaded_blas``).
    """
    return local_cluster(workers)


def _dashboard(client) -> str:
    try:
        import bokeh  # noqa: F401
    except ImportError:
        return f"{client.dashboard_link} (not served: install bokeh to see it)"
    return str(client.dashboard_link)

def _run_dask(pending, study_dir, scheduler, workers, threads, echo, bar):
    from distributed import Client, as_completed

    cluster = None
    if scheduler in (None, "local"):
        workers, threads = plan_workers(workers, threads)
        cluster = _start_local_cluster(workers)
        client = Client(cluster)
        where = f"local cluster: {workers} workers x {threads} numba threads"
        task_threads = threads
    else:
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT}s")
        except (OSError, TimeoutError) as exc:
            raise ParameterError(f"cannot connect to the Dask scheduler {scheduler}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}") from None
        where = f"scheduler {scheduler}"
        task_threads = threads  # None: the workers' own NUMBA_NUM_THREADS
    rows = {}
    try:
        echo(f"{where}; dashboard: {_dashboard(client)}")
        bar.start()
        futures = {}
        for spec in pending:
            future = client.submit(execute_run, spec, str(study_dir), task_threads, pure=False,
                                   key=f"{spec.study}-{spec.run_id}-{os.urandom(4).hex()}")
            futures[future] = spec
        for future in as_completed(futures):
            spec = futures[future]
            try:
                rows[spec.run_id] = future.result()
            except Exception as exc:  # the worker died or the task could not run
                rows[spec.run_id] = record_failure(spec, study_dir, exc)
            bar(rows[spec.run_id])
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return rows, {"scheduler": where, "workers": workers, "threads": task_threads}

#: Seconds to wait for an existing Dask scheduler before giving up.
CONNECT_TIMEOUT = 5
#: Address schemes of dask.distributed's communication back-ends.
_SCHEMES = ("tcp", "tls", "ucx", "inproc", "ws", "wss")


def check_scheduler(scheduler):
    """None, ``local``, ``serial`` or ``SCHEME://HOST:PORT`` (ParameterError otherwise)."""
    if scheduler is None or scheduler in ("local", "serial"):
        return scheduler
    text = str(scheduler)
    scheme, sep, rest = text.partition("://")
    host, colon, port = rest.rpartition(":")
    if not sep or scheme not in _SCHEMES or not host or not colon or not port.isdigit() \
            or not 0 < int(port) < 65536:
        raise ParameterError(f"--scheduler must be 'local', 'serial' or a Dask scheduler address "
                             f"such as tcp://HOST:8786; got {text!r}")
    return text


def probe_scheduler(address: str, timeout: float | None = None) -> None:
    """Fail fast (ParameterError) when nothing listens at a ``tcp://`` or ``tls://`` address."""
    scheme, _, rest = address.partition("://")
    if scheme not in ("tcp", "tls"):
        return
    host, _, port = rest.rpartition(":")
    host = host.strip("[]")
    try:
        with socket.create_connection((host, int(port)), timeout=timeout or CONNECT_TIMEOUT):
            pass
    except OSError as exc:
        reason = exc.strerror or str(exc) or type(exc).__name__
        raise ParameterError(f"cannot reach the Dask scheduler {address}: {reason}; start one "
                             f"with 'dask scheduler' or use --scheduler local") from None


def check_study_dir(out, name: str) -> pathlib.Path:
    """``out/name`` as an absolute path, refused if it or an ancestor is a file or is not
    writable (checked before anything is created)."""
    if not str(out).strip():
        raise ParameterError("--out must name a folder; got an empty string")
    study_dir = pathlib.Path(out).absolute() / name
    ancestor = study_dir
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        where = "exists and is not a folder" if ancestor == study_dir else f"is inside the file '{ancestor}'"
        raise ParameterError(f"study folder '{study_dir}' {where}; choose another --out")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ParameterError(f"study folder '{study_dir}' cannot be written: '{ancestor}' is not writable")
    return study_dir


def _run_serial(pending, study_dir, threads, echo, bar):
    echo("serial: one run after the other in this process")
    bar.start()
    rows = {}
    for spec in pending:
        rows[spec.run_id] = execute_run(spec, str(study_dir), threads)
        bar(rows[spec.run_id])
    return rows, {"scheduler": "serial", "workers": 1, "threads": threads}

# --------------------------------------------------------------------------- a study

def leave_out_unavailable(specs) -> tuple[list[RunSpec], list[dict]]:
    """(the runs whose method can run here, one note per method left out).

    A method whose optional extra is not installed (the ``neural`` method without
    ``npmrf3d[neural]``) is left out of the study rather than failing every one of its runs;
    each note has the method's name, algorithm, number of runs left out and the reason (which
    names the install command). Checked in this process: a remote cluster's workers must have
    the same extras.
    """
    kept, notes = [], {}
    for spec in specs:
        reason = spec.unavailable()
        if reason is None:
            kept.append(spec)
            continue
        note = notes.setdefault(spec.method, {"method": spec.method, "algorithm": spec.algorithm,
                                              "runs": 0, "reason": reason})
        note["runs"] += 1
    return kept, list(notes.values())


@dataclasses.dataclass
class StudyOutcome:
    """What :func:`run_study` did."""

    study_dir: pathlib.Path
    rows: list[dict]
    counts: dict[str, int]
    wall_seconds: float
    figures: list[pathlib.Path]

def run_study(study: Study, *, mode: str = "quick", out="study-results", scheduler: str | None = None,
              workers: int | None = None, threads: int | None = None, seeds=None, exemplars=None,
              sizes=None, levels: int | None = None, volume=None, slice_axis: int = 0,
              slice_index: int | None = None, slices: int = 1,
              progress: Callable[[dict | None, int, int], None] | bool | None = None,
              echo: Callable[[str], None] | None = None) -> StudyOutcome:
    """Run (or resume) a study and write its runs, ``results.csv``, figures and ``study.json``.

    Parameters
    ----------
    study : Study
    mode : {"quick", "full"}
    out : path
        Results root; the study writes into ``out/<study.name>``.
    scheduler : None, "local", "serial" or an address
        See the module docstring.
    workers, threads : int, optional
        Local cluster size and numba threads per worker (see :func:`plan_workers`); ``threads``
        also applies to serial runs (None: numba's default) and to an existing scheduler's
        workers (None: their ``NUMBA_NUM_THREADS``).
    seeds, exemplars, sizes, levels : optional
        Replace the variant's values.
    volume : path, optional
        The real volume of the ground-truth study.
    slice_axis, slice_index : int
        Which slice of ``volume`` is the exemplar (default: the middle one across axis 0).
    slices : {1, 3}
        3: each view's exemplar is the volume's middle slice in that view's plane instead
        (for an anisotropic material, which one slice cannot describe).
    progress : callable, optional
        Called as ``progress(row, done, total)`` after every finished run (its
        ``results.csv`` row) and once as ``progress(None, 0, total)`` when the runs start;
        ``npmrf3d study`` draws its bar with it. A bool (the former "draw a bar" switch) is
        accepted and ignored: the library draws nothing.
    echo : callable or None
        Where the one-line messages go (None: nowhere).

    Returns
    -------
    StudyOutcome
    """
    echo = echo or (lambda message: None)
    t_start = time.perf_counter()
    for name, value in (("workers", workers), ("threads", threads)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
            raise ParameterError(f"--{name} must be a positive integer; got {value!r}")
    scheduler = check_scheduler(scheduler)
    study_dir = check_study_dir(out, study.name)
    reference = None
    if volume is not None:
        reference = str(pathlib.Path(volume).absolute())
        shape = groundtruth.load_reference(reference).shape
        base_sizes = sizes if sizes is not None else study.scale(mode).sizes
        lv = levels if levels is not None else study.scale(mode).levels
        sizes = sorted({groundtruth.fit_size(shape, s, lv) for s in base_sizes})
    elif study.needs_volume:
        raise ParameterError(f"study {study.name} compares with a real 3-D volume: give one with "
                             f"--volume FILE (.npy or .tif)")
    specs = study.runs(mode, seeds=seeds, exemplars=exemplars, sizes=sizes, levels=levels,
                       reference=reference, slice_axis=slice_axis, slice_index=slice_index,
                       slices=slices)
    specs, left_out = leave_out_unavailable(specs)
    if not specs:
        raise ParameterError(f"study {study.name}: no method can run here: "
                             f"{'; '.join(item['reason'] for item in left_out)}")
    if scheduler not in (None, "local", "serial"):
        probe_scheduler(scheduler)
    try:
        study_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"study folder '{study_dir}' cannot be created: "
                             f"{exc.strerror or exc}") from None
    started = datetime.now(timezone.utc).isoformat(timespec="seconds")

    rows: dict[str, dict] = {}
    pending = []
    for spec in specs:
        run_dir = study_dir / spec.run_id
        if is_finished(run_dir):
            try:
                rows[spec.run_id] = load_row(spec, run_dir)
                continue
            except (OSError, ValueError, KeyError):  # unreadable: run it again
                pass
        pending.append(spec)
    echo(f"study {study.name} ({mode}): {len(specs)} runs, {len(specs) - len(pending)} already "
         f"finished, {len(pending)} to run -> {study_dir}")
    for item in left_out:
        echo(f"left out: method {item['method']} ({item['runs']} runs): {item['reason']}")

    info = {"scheduler": "none (nothing to run)", "workers": 0, "threads": threads}
    if pending:
        reporter = _Progress(progress, len(pending))
        if scheduler == "serial":
            new, info = _run_serial(pending, study_dir, threads, echo, reporter)
        else:
            new, info = _run_dask(pending, study_dir, scheduler, workers, threads, echo, reporter)
        rows.update(new)

    ordered = [rows[s.run_id] for s in specs]
    write_csv(study_dir / "results.csv", ordered, BASE_COLUMNS)
    figures = make_figures(study, study_dir, specs, ordered)
    counts = {status: sum(r["status"] == status for r in ordered) for status in ("done", "skipped", "failed")}
    wall = time.perf_counter() - t_start
    io.write_json(study_dir / "study.json", {
        "study": study.to_dict(),
        "mode": mode,
        "options": {"seeds": seeds, "exemplars": exemplars, "sizes": sizes, "levels": levels,
                    "volume": reference, "slice_axis": slice_axis, "slice_index": slice_index,
                    "slices": slices},
        "runs": [s.to_dict() for s in specs],
        "left_out": left_out,
        **info,
        "versions": io.package_versions(),
        "started": started,
        "finished": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "wall_seconds": wall,
        "counts": counts,
        "figures": [f.name for f in figures],
    })
    echo(f"study {study.name}: {counts['done']} done, {counts['skipped']} skipped, "
         f"{counts['failed']} failed in {wall:.1f} s; table {study_dir / 'results.csv'}")
    return StudyOutcome(study_dir=study_dir, rows=ordered, counts=counts, wall_seconds=wall,
                        figures=figures)
