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
import socket
import stat
import tempfile
from collections.abc import Mapping
from datetime import datetime, timezone
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..options import options_of, recorded
from .. import plotting  # a module: plotting reads io.files, whose package imports this module
from .files import as_volume, json_text, package_versions, to_jsonable, write_npy, write_volume_tiff

__all__ = ["OutputLock", "RUN_DERIVED", "RUN_FILES", "check_replaceable", "clean_stale_staging",
           "config_dict", "new_staging", "replace_folder", "run_record", "write_run"]

#: The files that make up one run folder, in the order they are moved into place
#: (``run.json`` last, so its presence marks a complete run).
RUN_FILES = ("volume.npy", "volume.tif", "preview.png", "run.json")


def config_dict(result) -> Any:
    """The JSON-able configuration of a result (None for a run without one): for a configuration
    made of options (:mod:`npmrf3d.options`), the options its run read."""
    config = getattr(result, "config", None)
    if config is None:
        return None
    if options_of(type(config)):  # only what the run read
        return to_jsonable(recorded(config))
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


#: Files of an old run that an overwrite drops with it (they describe the old volume).
RUN_DERIVED = ("metrics.json", "histograms.png")


def _pid_alive(pid: int) -> bool:
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def _anchor(target: pathlib.Path) -> pathlib.Path:
    """The nearest existing ancestor of ``target`` (where locks and staging folders go)."""
    anchor = target.parent
    while not anchor.exists():
        anchor = anchor.parent
    return anchor


def _lock_path(target: pathlib.Path) -> pathlib.Path:
    anchor = _anchor(target)
    relative = target.relative_to(anchor)
    return anchor / ("." + "_".join(relative.parts) + ".lock")


#: Locks this process holds: path -> depth (a run's CLI holds it, write_run takes it again).
_HELD: dict[pathlib.Path, int] = {}


class OutputLock:
    """An exclusive claim on an output folder: a lock file created with ``O_EXCL`` beside it
    (``.NAME.lock`` in its nearest existing ancestor) holding the owner's PID and host.

    A second run into the same folder, in this or another process, is refused with a
    :class:`ParameterError` while the owner lives; a lock left by a killed run on this host (its
    PID is dead) is taken over; a lock from another host (a shared file system) is never taken
    over. Re-entrant within one process. Use as a context manager.

    Parameters
    ----------
    out_dir : path
    what : str
        What the folder is to the caller, for the refusal (a writer's ``output folder``, a
        reader's ``run folder``).
    advice : str
        What to do about a live owner, ending the refusal.
    """

    def __init__(self, out_dir: str | os.PathLike[str], *, what: str = "output folder",
                 advice: str = "wait for it to finish or choose another --out"):
        self.target = pathlib.Path(out_dir).absolute()
        self.what, self.advice = what, advice
        self.path = None

    def __enter__(self) -> "OutputLock":
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    def acquire(self) -> None:
        path = _lock_path(self.target)
        if path in _HELD:
            _HELD[path] += 1
            self.path = path
            return
        for _ in range(3):
            try:
                fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                owner, host = _lock_owner(path)
                if owner is None or host != socket.gethostname() or _pid_alive(owner):
                    who = f"PID {owner}" if owner is not None else "another run"
                    who += f" on {host}" if host and host != socket.gethostname() else ""
                    raise ParameterError(
                        f"{self.what} '{self.target}' is in use by another run ({who}, lock "
                        f"file '{path}'); {self.advice}") from None
                try:  # the owner died: its lock is stale
                    path.unlink()
                except FileNotFoundError:
                    pass
                continue
            except OSError as exc:
                raise ParameterError(f"{self.what} '{self.target}' cannot be locked: "
                                     f"{exc.strerror or exc}") from None
            try:  # the lock is ours from here: interrupted or failed before it is held, it goes
                _HELD[path], self.path = 1, path
                with os.fdopen(fd, "w", encoding="ascii") as handle:
                    handle.write(f"{os.getpid()} {socket.gethostname()}\n")
                clean_stale_staging(self.target)
            except BaseException:
                self.release()
                raise
            return
        raise ParameterError(f"{self.what} '{self.target}' cannot be locked (lock file '{path}' "
                             f"keeps reappearing); {self.advice}")

    def release(self) -> None:
        path, self.path = self.path, None
        if path is None or path not in _HELD:
            return
        _HELD[path] -= 1
        if _HELD[path] == 0:
            del _HELD[path]
            try:
                path.unlink()
            except FileNotFoundError:
                pass


def _lock_owner(path: pathlib.Path) -> tuple[int | None, str | None]:
    """(PID, host) written in a lock file; a lock without a host is this host's."""
    try:
        parts = path.read_text(encoding="ascii").split()
        return int(parts[0]), (parts[1] if len(parts) > 1 else socket.gethostname())
    except (OSError, ValueError, IndexError, UnicodeError):
        return None, None


def _staging_owner(name: str) -> int | None:
    """PID in a staging name ``.NAME.partial-PID-RANDOM`` (or ``.NAME.old-PID-RANDOM``)."""
    for marker in (".partial-", ".old-"):
        if marker in name:
            head = name.rsplit(marker, 1)[1].split("-", 1)[0]
            return int(head) if head.isdigit() else None
    return None


def clean_stale_staging(out_dir: str | os.PathLike[str]) -> list[pathlib.Path]:
    """Remove the hidden staging folders ``.NAME.partial-PID-*`` (and swapped-away old runs
    ``.NAME.old-PID-*``) that killed runs into ``out_dir`` left behind; only those whose owner
    PID is dead. Returns what was removed."""
    target = pathlib.Path(out_dir).absolute()
    anchor = _anchor(target)
    removed = []
    for prefix in (f".{target.name}.partial-", f".{target.name}.old-"):
        for entry in anchor.glob(glob_escape(prefix) + "*"):
            owner = _staging_owner(entry.name)
            if owner is None or owner == os.getpid() or _pid_alive(owner):
                continue
            shutil.rmtree(entry, ignore_errors=True)
            removed.append(entry)
    return removed


def glob_escape(text: str) -> str:
    return "".join(f"[{c}]" if c in "*?[" else c for c in text)


def check_replaceable(out_dir: str | os.PathLike[str]) -> None:
    """Refuse to replace ``out_dir`` by a new run folder (an overwrite swaps the whole folder)
    when it is the current working folder, one of its parents, or the home folder: the calling
    shell would be left in a deleted folder (and a home folder is nobody's run folder)."""
    target = pathlib.Path(out_dir).resolve()
    try:
        cwd = pathlib.Path.cwd().resolve()
    except OSError:  # the working folder is gone already
        cwd = None
    try:
        home = pathlib.Path.home().resolve()
    except (RuntimeError, KeyError, OSError):  # no home folder known
        home = None
    reason = None
    if target == home:
        reason = "the home folder"
    elif cwd is not None and target == cwd:
        reason = "the current working folder"
    elif cwd is not None and target in cwd.parents:
        reason = "a parent of the current working folder"
    if reason is not None:
        raise ParameterError(f"output folder '{out_dir}' is {reason}; --overwrite replaces the "
                             "whole folder, so choose a folder of its own with --out")


def _umask() -> int:
    """The process's umask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


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

    The four files are written into a staging folder ``.<name>.partial-<pid>-<random>`` next to
    ``out_dir`` (``run.json`` last), under an exclusive :class:`OutputLock` on ``out_dir``. A new
    folder is the staging folder renamed; an existing folder without a run receives the files
    (``run.json`` last, so its presence marks a complete run); with ``overwrite``, a folder
    holding a run is swapped away only once the new one is complete (its other files move
    along, except the old run's ``metrics.json`` and ``histograms.png``). The staging folder is
    always removed, so a failure never leaves partial output; staging folders of killed runs
    (dead owner PID) are removed by the next run into the same place.

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
        Replace a previous run in ``out_dir``.
    title : str, optional
        Title of the preview figure.

    Returns
    -------
    pathlib.Path
        ``out_dir``.

    Raises
    ------
    ParameterError
        If ``out_dir`` is an existing file, already holds a run and ``overwrite`` is False, or
        another run holds its lock; or ``overwrite`` is set and ``out_dir`` is the working
        folder, one of its parents or the home folder (:func:`check_replaceable`).
    TypeError
        If ``record`` cannot be converted to JSON (checked before anything is written).
    """
    out_dir = pathlib.Path(out_dir)
    volume = as_volume(volume)
    text = json_text(record)  # fail on a bad record before touching the disk
    if overwrite:
        check_replaceable(out_dir)
    with OutputLock(out_dir):
        if out_dir.exists() and not out_dir.is_dir():
            raise ParameterError(f"output folder '{out_dir}' exists and is not a folder")
        previous = [name for name in RUN_FILES if (out_dir / name).exists()]
        if previous and not overwrite:
            raise ParameterError(
                f"output folder '{out_dir}' already holds a run ({', '.join(previous)}); "
                "pass overwrite=True (--overwrite) or choose another --out"
            )
        target = out_dir.absolute()
        anchor = _anchor(target)
        staging = new_staging(target)
        try:
            # mkdtemp makes 0700; the folder gets the mode mkdir would give it, or keeps its own
            mode = (stat.S_IMODE(target.stat().st_mode) if previous and overwrite
                    else 0o777 & ~_umask())
            os.chmod(staging, mode)
            write_npy(staging / "volume.npy", volume)
            write_volume_tiff(staging / "volume.tif", volume)
            plotting.save_figure(plotting.preview_figure(volume, exemplars, title=title), staging / "preview.png")
            (staging / "run.json").write_text(text, encoding="utf-8")
            _move_into_place(staging, target, anchor, replace_run=bool(previous))
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return out_dir


def _move_into_place(staging: pathlib.Path, target: pathlib.Path, anchor: pathlib.Path,
                     replace_run: bool) -> None:
    if not target.exists():
        target.parent.mkdir(parents=True, exist_ok=True)
        if target.parent == anchor or target.parent.samefile(anchor):
            os.rename(staging, target)  # the complete folder appears at once
            return
        target.mkdir()
    if not replace_run:
        for name in RUN_FILES:  # run.json last
            os.replace(staging / name, target / name)
        return
    # overwrite: the new folder is complete; carry the old folder's other files over, then swap
    carried = [e.name for e in target.iterdir()
               if e.name not in RUN_FILES and e.name not in RUN_DERIVED]
    for name in carried:
        os.rename(target / name, staging / name)
    try:
        replace_folder(staging, target)
    except OSError:
        for name in carried:
            os.rename(staging / name, target / name)
        raise


def new_staging(target: str | os.PathLike[str]) -> pathlib.Path:
    """A new empty hidden folder ``.NAME.partial-PID-RANDOM`` in the nearest existing ancestor of
    ``target`` (so that a failure leaves no new folders behind), where a complete output is made
    before :func:`replace_folder` puts it in place; the next run into ``target`` removes it if
    its owner died (:func:`clean_stale_staging`)."""
    target = pathlib.Path(target).absolute()
    return pathlib.Path(tempfile.mkdtemp(prefix=f".{target.name}.partial-{os.getpid()}-",
                                         dir=_anchor(target)))


def replace_folder(new: str | os.PathLike[str], target: str | os.PathLike[str]) -> None:
    """Put the complete folder ``new`` at ``target`` (same file system): renamed into place, its
    parents created, when ``target`` is missing or an empty folder; else the old ``target`` is
    renamed away first (``.NAME.old-PID-RANDOM`` beside it), put back if ``new`` cannot take
    its place, and removed once it has."""
    new, target = pathlib.Path(new), pathlib.Path(target).absolute()
    if not target.exists() or (target.is_dir() and not any(target.iterdir())):
        target.parent.mkdir(parents=True, exist_ok=True)
        os.rename(new, target)  # the complete folder appears at once (over an empty one too)
        return
    old = pathlib.Path(tempfile.mkdtemp(prefix=f".{target.name}.old-{os.getpid()}-", dir=target.parent))
    try:
        os.rename(target, old / "run")
        try:
            os.rename(new, target)
        except OSError:
            os.rename(old / "run", target)
            raise
    finally:
        shutil.rmtree(old, ignore_errors=True)
