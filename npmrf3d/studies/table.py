"""The numbers of a study: ``results.csv`` rows, finished-run detection, CSV files.

Used by the runner (which writes the rows), the figures (which write the numbers behind each
picture) and the report (which reads ``results.csv`` back), so none of those imports another.
"""

from __future__ import annotations

import csv
import json
import math
import pathlib
from collections.abc import Callable, Sequence
from typing import Any

from ..errors import ParameterError
from ..io.files import atomic_write
from .grid import RunSpec

__all__ = ["BASE_COLUMNS", "FINISHED_FILES", "as_float", "is_finished", "metric_columns", "unique", "load_row", "make_row", "read_results", "read_results_checked",
           "separations", "summarise", "write_csv"]

#: The files that mark a finished run.
FINISHED_FILES = ("run.json", "metrics.json")
#: Leading columns of results.csv; metric columns follow, ``error`` comes last.
BASE_COLUMNS = ("study", "run_id", "exemplar", "method", "algorithm", "seed", "size", "levels",
                "status", "seconds", "wall_seconds", "threads", "largest_value_share")


def is_finished(run_dir: pathlib.Path) -> bool:
    """True when ``run_dir`` holds a complete run (``run.json`` and ``metrics.json``)."""
    return all((pathlib.Path(run_dir) / name).is_file() for name in FINISHED_FILES)


def make_row(spec: RunSpec, status: str, record: dict | None, measured: dict | None, *,
             error: str = "") -> dict:
    """The ``results.csv`` row of a run (metric columns ``mean_<metric>``, ``<view>_<metric>``)."""
    record = record or {}
    timings = record.get("timings") or {}
    row: dict[str, Any] = {
        "study": spec.study, "run_id": spec.run_id, "exemplar": spec.exemplar,
        "method": spec.method, "algorithm": spec.algorithm, "seed": spec.seed,
        "size": spec.size, "levels": spec.levels, "status": status,
        "seconds": timings.get("total", math.nan),
        # methods that train, then generate (neural), time the two apart
        **{f"{phase}_seconds": timings[phase] for phase in ("train", "generate") if phase in timings},
        "wall_seconds": record.get("wall_seconds", math.nan),
        "threads": record.get("threads", ""),
        "largest_value_share": (measured or {}).get("largest_value_share", math.nan),
    }
    if measured:
        scores = measured.get("metrics") or {}
        for name, value in (scores.get("mean") or {}).items():
            row[f"mean_{name}"] = value
        for view, values in (scores.get("per_view") or {}).items():
            for name, value in values.items():
                row[f"{view}_{name}"] = value
        truth = measured.get("groundtruth")
        if truth:
            for axis, value in truth["two_point_l2"].items():
                row[f"two_point_l2_{axis}"] = value
            row["two_point_l2"] = truth["two_point_l2_mean"]
            if "two_point_shape_l2_mean" in truth:  # absent from older run records
                row["two_point_shape_l2"] = truth["two_point_shape_l2_mean"]
            row["fraction_l1"] = truth["fraction_l1"]
    row["error"] = error
    return row


def load_row(spec: RunSpec, run_dir: pathlib.Path) -> dict:
    record = json.loads((run_dir / "run.json").read_text(encoding="utf-8"))
    measured = json.loads((run_dir / "metrics.json").read_text(encoding="utf-8"))
    return make_row(spec, "skipped", record, measured)


#: Timing columns of methods that train, then generate (neural); in results.csv right after
#: ``seconds`` when a row has them.
PHASE_COLUMNS = ("train_seconds", "generate_seconds")


def write_csv(path: pathlib.Path, rows: list[dict], head: Sequence[str] = ()) -> pathlib.Path:
    columns = list(head)
    if "seconds" in columns:
        at = columns.index("seconds") + 1
        columns[at:at] = [c for c in PHASE_COLUMNS if any(c in row for row in rows)]
    for row in rows:
        columns += [k for k in row if k not in columns and k != "error"]
    if any("error" in row for row in rows):
        columns.append("error")

    def write(tmp):
        with open(tmp, "w", newline="", encoding="utf-8") as handle:
            writer = csv.DictWriter(handle, fieldnames=columns, restval="")
            writer.writeheader()
            for row in rows:
                writer.writerow({k: _csv_value(v) for k, v in row.items()})

    return atomic_write(path, write)


def _csv_value(value):
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return value


def read_results(path) -> list[dict]:
    """Rows of a ``results.csv`` (numbers stay strings)."""
    with open(path, newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


#: Columns of results.csv that every reader of it needs.
REQUIRED_COLUMNS = ("run_id", "exemplar", "method", "seed", "size", "levels", "status")
#: Columns of results.csv that hold text; every other column holds numbers.
TEXT_COLUMNS = ("study", "run_id", "exemplar", "method", "algorithm", "status", "error")


def read_results_checked(path, warn: Callable[[str], None] | None = None) -> list[dict]:
    """:func:`read_results`, read defensively (for the report).

    A file without the :data:`REQUIRED_COLUMNS` is refused (:class:`ParameterError` naming the
    file and the columns). A cell of a number column that is not a finite number (text,
    ``nan``, ``inf``) becomes empty, shown as missing, and ``warn`` gets one line naming the
    file, the row and the column (an empty cell is a missing number as written, no warning).

    >>> import pathlib, tempfile
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "results.csv"
    >>> _ = path.write_text("run_id,exemplar,method,seed,size,levels,status,mean_kl" + chr(10)
    ...                     + "a,e,m,0,8,1,done,oops" + chr(10))
    >>> [r["mean_kl"] for r in read_results_checked(path, print)]  # doctest: +ELLIPSIS
    warning: ...results.csv: row 1 (a), column mean_kl: 'oops' is not a number; shown as missing
    ['']
    """
    with open(path, newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        rows = list(reader)
        columns = list(reader.fieldnames or ())
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise ParameterError(f"results file '{path}' lacks the column{'s' if len(missing) > 1 else ''} "
                             f"{', '.join(missing)} (it was not written by 'npmrf3d study')")
    for number, row in enumerate(rows, start=1):
        for column in columns:
            value = row.get(column)
            if column in TEXT_COLUMNS or value is None or value == "":
                continue
            if not math.isfinite(as_float(value)):
                row[column] = ""
                if warn is not None:
                    warn(f"warning: {path}: row {number} ({row.get('run_id') or '?'}), column "
                         f"{column}: {value!r} is not a number; shown as missing")
    return rows


def as_float(value) -> float:
    """``float(value)``, NaN for an empty or non-numeric CSV cell."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def metric_columns(rows: list[dict]) -> list[str]:
    """The metric columns of ``results.csv`` rows: every ``mean_*``, then the ground-truth ones."""
    names = []
    for row in rows:
        for key in row:
            if key.startswith("mean_") and key not in names:
                names.append(key)
    extra = [k for k in ("two_point_l2", "two_point_shape_l2", "fraction_l1") if any(k in r for r in rows)]
    return names + extra


def unique(values) -> list:
    """The distinct values in first-seen order."""
    out = []
    for v in values:
        if v not in out:
            out.append(v)
    return out


def summarise(rows: list[dict]) -> list[dict]:
    """Mean and standard deviation over seeds of every metric column, per exemplar and method:
    rows ``{"metric", "exemplar", "method", "n", "mean", "std"}`` (failed runs and missing
    values left out; ``std`` is the population standard deviation, 0 for one seed, nan for none).

    Examples
    --------
    >>> rows = [{"exemplar": "e", "method": "m", "status": "ok", "mean_ac": x} for x in ("1", "3")]
    >>> [(r["n"], r["mean"], r["std"]) for r in summarise(rows)]
    [(2, 2.0, 1.0)]
    """
    columns = metric_columns(rows)
    values: dict = {}
    for r in rows:
        if r.get("status") == "failed":
            continue
        for c in columns:
            x = as_float(r.get(c))
            if math.isfinite(x):
                values.setdefault((c, r["exemplar"], r["method"]), []).append(x)
    out = []
    for c in columns:
        for e in unique(r["exemplar"] for r in rows):
            for m in unique(r["method"] for r in rows):
                xs = values.get((c, e, m), [])
                mean = sum(xs) / len(xs) if xs else math.nan
                std = math.sqrt(sum((x - mean) ** 2 for x in xs) / len(xs)) if xs else math.nan
                out.append({"metric": c, "exemplar": e, "method": m, "n": len(xs), "mean": mean, "std": std})
    return out


def separations(summary: list[dict]) -> list[dict]:
    """Per metric and exemplar: the best method (lowest mean) and, against the runner-up, whether
    the difference exceeds the spread over seeds (``|mean_1 - mean_2| > std_1 + std_2``, both
    with at least two seeds; ``None`` when either has fewer, i.e. the spread is unknown).

    Examples
    --------
    >>> s = [{"metric": "ac", "exemplar": "e", "method": m, "n": 3, "mean": mu, "std": 0.1}
    ...      for m, mu in (("a", 1.0), ("b", 1.5), ("c", 1.05))]
    >>> [(r["best"], r["runner_up"], r["exceeds_spread"]) for r in separations(s)]
    [('a', 'c', False)]
    """
    groups: dict = {}
    for r in summary:
        if r["n"] and math.isfinite(r["mean"]):
            groups.setdefault((r["metric"], r["exemplar"]), []).append(r)
    out = []
    for (metric, exemplar), items in groups.items():
        items = sorted(items, key=lambda r: r["mean"])
        best, second = items[0], (items[1] if len(items) > 1 else None)
        exceeds = None
        if second is not None and best["n"] > 1 and second["n"] > 1:
            exceeds = bool(second["mean"] - best["mean"] > best["std"] + second["std"])
        out.append({"metric": metric, "exemplar": exemplar, "best": best["method"],
                    "runner_up": second["method"] if second else None,
                    "difference": (second["mean"] - best["mean"]) if second else math.nan,
                    "spread": (best["std"] + second["std"]) if second else math.nan,
                    "exceeds_spread": exceeds})
    return out
