"""Run folders and their records: what ``synth``, ``baseline`` and the studies write.

A run folder holds :data:`RUN_FILES`: the volume (``.npy`` and an ImageJ TIFF), a preview
picture and ``run.json``, the record of what was asked (configuration, seed, exemplars), what
ran (versions, threads, host) and what happened (timings, history, stats). :func:`run_record`
builds that record for every command and study alike; :func:`write_run` writes the folder
atomically. This module sits above :mod:`npmrf3d.io` (files) and :mod:`npmrf3d.plotting`
(the preview), so neither of those needs the other.
"""

from __future__ import annotations

import os
import pathlib
import shutil
import tempfile
from collections.abc import Mapping
from datetime import datetime, timezone
from typing import Any

import numpy as np

from npmrf3d.errors import ParameterError
from npmrf3d._files import json_text, as_volume, package_versions, to_jsonable, write_volume_tiff
from npmrf3d.plotting import preview_figure, save_figure

__all__ = ["RUN_FILES", "config_dict", "run_record", "write_run"]

#: The files that make up one run folder, in the order they are moved into place
#: (``run.json`` last, so its presence marks a complete run).
RUN_FILES = ("volume.npy", "volume.tif", "preview.png", "run.json")


def config_dict(result) -> Any:
    """The JSON-able configuration of a result (None for a run without one)."""
    config = getattr(result, "config", None)
    if config is None:
        return None
    if hasattr(config, "to_dict"):
        return config.to_dict()
    try:
        return to_jsonable(config)
    except TypeError:
        return repr(config)


def run_record(command: str, result, *, exemplars: Mapping[str, str], threads: int | None = None,
               method: str | None = None, **extra: Any) -> dict[str, Any]:
    """The ``run.json`` record of one run.

    Parameters
    ----------
    command : str
        ``synth``, ``baseline`` or ``study``.
    result : SynthesisResult or None
        None for the study-only controls (no configuration, timings or history).
    exemplars : mapping view -> str
        What each constrained view's exemplar was (a file name or ``bundled:NAME``).
    threads : int, optional
        Numba threads of the run (default: the result's ``stats["threads"]``).
    method : str, optional
        Name of the method in :data:`npmrf3d.methods.METHODS`.
    **extra
        Further fields, placed after ``exemplars`` (e.g. ``argv``, ``labels``, ``spec``).
    """
    stats = getattr(result, "stats", None)
    if threads is None and stats is not None:
        threads = stats.get("threads")
    record: dict[str, Any] = {"command": command}
    if method is not None:
        record["method"] = method
    config = config_dict(result)
    record.update({
        "config": config,
        "seed": config.get("seed") if isinstance(config, dict) else None,
        "exemplars": dict(exemplars),
        **extra,
        "versions": package_versions(),
        "threads": threads,
        "timings": getattr(result, "timings", None),
        "history": getattr(result, "history", None),
        "stats": stats,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
    })
    return record


def write_run(
    out_dir: str | os.PathLike[str],
    *,
    volume: np.ndarray,
    exemplars: Mapping[str, np.ndarray],
    record: Mapping[str, Any],
    overwrite: bool = False,
    title: str | None = None,
) -> pathlib.Path:
    """Write a complete run folder: ``volume.npy``, ``volume.tif``, ``preview.png``, ``run.json``.

    The four files are written into a staging folder ``.<name>.partial-<random>`` next to
    ``out_dir`` and then moved into ``out_dir`` (``run.json`` last); the staging folder is
    always removed, so a failure never leaves partial output. Other files in ``out_dir`` are
    left alone.

    Parameters
    ----------
    out_dir : str or os.PathLike
        Output folder; created (with its parents) if missing.
    volume : numpy.ndarray
        Synthesised volume of shape ``(N1, N2, N3, C)``.
    exemplars : Mapping[str, numpy.ndarray]
        View name (``"front"``, ``"right"``, ``"top"``) -> exemplar of shape ``(H, W, C)``;
        several views may share one array. Used for the preview only.
    record : Mapping[str, Any]
        Run description saved as ``run.json`` (converted with :func:`to_jsonable`).
    overwrite : bool, optional
        Replace the files of a previous run in ``out_dir``.
    title : str, optional
        Title of the preview figure.

    Returns
    -------
    pathlib.Path
        ``out_dir``.

    Raises
    ------
    ParameterError
        If ``out_dir`` is an existing file, or already holds a run and ``overwrite`` is False.
    TypeError
        If ``record`` cannot be converted to JSON (checked before anything is written).
    """
    out_dir = pathlib.Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ParameterError(f"output folder '{out_dir}' exists and is not a folder")
    previous = [name for name in RUN_FILES if (out_dir / name).exists()]
    if previous and not overwrite:
        raise ParameterError(
            f"output folder '{out_dir}' already holds a run ({', '.join(previous)}); "
            "pass overwrite=True (--overwrite) or choose another --out"
        )
    volume = as_volume(volume)
    text = json_text(record)  # fail on a bad record before touching the disk

    target = out_dir.absolute()
    # stage in the nearest existing ancestor, so that a failure leaves no new folders behind
    anchor = target.parent
    while not anchor.exists():
        anchor = anchor.parent
    staging = pathlib.Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-", dir=anchor))
    try:
        np.save(staging / "volume.npy", volume, allow_pickle=False)
        write_volume_tiff(staging / "volume.tif", volume)
        save_figure(preview_figure(volume, exemplars, title=title), staging / "preview.png")
        (staging / "run.json").write_text(text, encoding="utf-8")
        out_dir.mkdir(parents=True, exist_ok=True)
        for name in RUN_FILES:
            os.replace(staging / name, out_dir / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out_dir


