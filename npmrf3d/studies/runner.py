"""Run a study's grid on Dask (or serially) and write its runs, table and figures.

Layout of the output (``OUT`` is ``--out``)::

    OUT/<study>/study.json            declaration, options, scheduler, versions, wall time,
                                      methods left out (``left_out``: optional extra missing)
    OUT/<study>/results.csv           one row per run (status, timings, metrics)
    OUT/<study>/*.png, *.csv          figures and the numbers behind them
    OUT/<study>/<run_id>/             volume.npy, volume.tif, preview.png, run.json, metrics.json
                                      or error.json for a failed run (:mod:`.execute`)

Behaviour
---------
* **Schedulers**: ``scheduler=None`` (or ``"local"``) starts a ``dask.distributed``
  ``LocalCluster`` (:func:`npmrf3d._cluster.local_cluster`) of ``workers`` single-threaded
  worker processes whose numba kernels use ``threads`` threads each, with ``workers x threads
  <= cores`` (each run sets its numba threads inside its task); an address
  (``tcp://host:8786``) connects to an existing scheduler, whose workers keep their own
  ``NUMBA_NUM_THREADS``; ``"serial"`` runs in this process, one run after the other. The
  dashboard address is printed (it needs ``bokeh`` to be served).
* **Input checked first**: a bad ``--workers``, ``--threads``, scheduler address or study
  folder, a real volume that is not 3-D or holds NaN, a slice index past it, an exemplar that
  cannot be loaded, or a run whose options its method refuses (a size too small for the
  window and levels ...) is refused as a whole, with one message naming the first problem,
  before the first run and before any folder is created (:mod:`.inputs`).
* **Same results everywhere**: every run is seeded by its own seed only and numba kernels do
  not depend on the thread count, so Dask and serial execution write identical volumes.
* **One study per folder**: the study folder is locked while the study runs
  (:func:`claim_study_dir`); a second study into it, from this or another process, is refused
  at once, and its runs and table are not mixed in.
* **Resumable**: a run whose folder holds ``run.json`` and ``metrics.json`` is finished and is
  skipped (its row is read back from disk); a failed run is tried again.
* **Failures**: an exception in a run writes ``error.json`` (message and traceback) into its
  folder and a ``failed`` row; the other runs go on.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import pathlib
import time
from collections.abc import Callable
from datetime import datetime, timezone

from .. import io
from .._cluster import check_scheduler, dashboard_link, dask_client, plan_workers, probe_scheduler
from ..errors import ParameterError
from ..io.runs import OutputLock
from . import groundtruth
from .execute import execute_run, record_failure
from .figures import make_figures
from .grid import RunSpec, Study
from .inputs import check_reference, check_runs
from .table import BASE_COLUMNS, is_finished, load_row, write_csv

__all__ = ["StudyOutcome", "leave_out_unavailable", "run_study"]


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


def _run_dask(pending, study_dir, scheduler, workers, threads, echo, bar):
    from distributed import as_completed

    if scheduler in (None, "local"):
        workers, threads = plan_workers(workers, threads)
        scheduler = None
        where = f"local cluster: {workers} workers x {threads} numba threads"
    else:
        where = f"scheduler {scheduler}"  # threads None: the workers' own NUMBA_NUM_THREADS
    rows = {}
    with dask_client(scheduler, workers) as client:
        echo(f"{where}; dashboard: {dashboard_link(client)}")
        bar.start()
        futures = {}
        for spec in pending:
            future = client.submit(execute_run, spec, str(study_dir), threads, pure=False,
                                   key=f"{spec.study}-{spec.run_id}-{os.urandom(4).hex()}")
            futures[future] = spec
        for future in as_completed(futures):
            spec = futures[future]
            try:
                rows[spec.run_id] = future.result()
            except Exception as exc:  # the worker died or the task could not run
                rows[spec.run_id] = record_failure(spec, study_dir, exc)
            bar(rows[spec.run_id])
    return rows, {"scheduler": where, "workers": workers, "threads": threads}


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
              echo: Callable[[str], None] | None = None, check: bool = True) -> StudyOutcome:
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
    check : bool
        Check the whole grid before the first run (:func:`.inputs.check_runs`: every exemplar,
        every run's options against its method's configuration); False leaves each run to
        fail on its own, as a ``failed`` row.

    Raises
    ------
    ParameterError
        The first problem of the input (options, scheduler, study folder, the real volume, an
        exemplar, a run's options), before any folder is created.

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
    if scheduler in (None, "local"):
        plan_workers(workers, threads)  # refused here, before any folder exists
    study.check_volume_options(volume, slice_axis=slice_axis, slice_index=slice_index, slices=slices)
    study_dir = check_study_dir(out, study.name)
    reference = real = None
    if volume is not None:
        reference = str(pathlib.Path(volume).absolute())
        real = check_reference(study.name, reference, slice_axis=slice_axis, slice_index=slice_index)
        base_sizes = sizes if sizes is not None else study.scale(mode).sizes
        lv = levels if levels is not None else study.scale(mode).levels
        try:
            sizes = sorted({groundtruth.fit_size(real.shape, s, lv) for s in base_sizes})
        except ParameterError as exc:
            raise ParameterError(f"study {study.name}: {exc}") from None
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
    if check:
        check_runs(study.name, specs, real, memory=scheduler in (None, "local", "serial"))
    del real
    if scheduler not in (None, "local", "serial"):
        probe_scheduler(scheduler)
    with claim_study_dir(study_dir):
        return _run_grid(study, study_dir, specs, left_out, mode=mode, scheduler=scheduler,
                         workers=workers, threads=threads, progress=progress, echo=echo,
                         t_start=t_start, options={
                             "seeds": seeds, "exemplars": exemplars, "sizes": sizes,
                             "levels": levels, "volume": reference, "slice_axis": slice_axis,
                             "slice_index": slice_index, "slices": slices})


@contextlib.contextmanager
def claim_study_dir(study_dir: pathlib.Path):
    """The study folder created and held for the block: a second study into the same folder
    (whose runs, ``results.csv`` and ``study.json`` would mix with these) is refused at once
    with a :class:`ParameterError`, as a second run into a run folder is
    (:class:`npmrf3d.io.runs.OutputLock`). The results root is created first, so that every
    claimant takes the same lock file in it."""
    try:
        study_dir.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f"study folder '{study_dir}' cannot be created: "
                             f"{exc.strerror or exc}") from None
    with OutputLock(study_dir, what="study folder",
                    advice="wait for that study to finish or choose another --out"):
        try:
            study_dir.mkdir(exist_ok=True)
        except OSError as exc:
            raise ParameterError(f"study folder '{study_dir}' cannot be created: "
                                 f"{exc.strerror or exc}") from None
        yield study_dir


def _run_grid(study: Study, study_dir: pathlib.Path, specs: list[RunSpec], left_out: list[dict], *,
              mode: str, scheduler, workers, threads, progress, echo, t_start: float,
              options: dict) -> StudyOutcome:
    """Run the grid's unfinished runs and write ``results.csv``, the figures and ``study.json``:
    the body of :func:`run_study`, in the claimed study folder."""
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
        "options": options,
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
