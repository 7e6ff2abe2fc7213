"""Checkpoints: a run's identity, atomic ``.npz`` files with a checksum, resuming.

Every method that resumes (the level loop of :mod:`npmrf3d.model.pyramid`, the neural trainer)
writes its state with :func:`save_run_state` and reads it back with :func:`load_run_state`:

* :func:`run_key` -- the identity of a run, a JSON text of the method's name, its configuration
  and a digest of its exemplars (and whatever else the state depends on); a checkpoint whose
  key differs is refused, never resumed.
* :func:`save_checkpoint` -- named arrays to an ``.npz`` file, written atomically, with the
  SHA-256 of every member stored beside them (:data:`CHECKSUM`).
* :func:`load_checkpoint` -- the arrays back; a missing, unreadable, foreign or damaged file is
  a :class:`npmrf3d.errors.ParameterError` that says what to do. A file that is not a
  checkpoint of npmrf3d at all (:func:`is_checkpoint_file`) is refused, never called damaged.
* :func:`refusal`, :func:`check_members`, :func:`check_array`, :func:`check_rng_state` -- the
  checks of a checkpoint's contents once its checksum holds (a file re-sealed by hand passes
  the checksum), all ending in the one refusal message.

State that is not an array (the neural trainer's torch state) is stored as its bytes, a uint8
array (:func:`as_bytes_array`).
"""

from __future__ import annotations

import hashlib
import json
import os
import pathlib
import zipfile
from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np

from ..errors import ParameterError
from .files import _existing_file, _reason, atomic_write

__all__ = ["CHECKSUM", "KEY", "as_bytes_array", "check_array", "check_members", "check_rng_state",
           "exemplar_digest", "is_checkpoint_file", "load_checkpoint", "load_run_state", "refusal",
           "run_key", "save_checkpoint", "save_run_state", "seal"]

#: Name of the member holding the SHA-256 of every other member (names, dtypes, shapes, bytes).
CHECKSUM = "npmrf3d_checksum"
#: Name of the member holding the run's identity (:func:`run_key`).
KEY = "run_key"


# --------------------------------------------------------------------------- the run's identity


def exemplar_digest(array: np.ndarray) -> str:
    """SHA-256 of an exemplar's shape and float32 values (what a run reads of it).

    >>> exemplar_digest(np.zeros((2, 2))) == exemplar_digest(np.zeros((2, 2), dtype=np.float32))
    True
    """
    array = np.ascontiguousarray(array, dtype=np.float32)
    digest = hashlib.sha256(repr(array.shape).encode())
    digest.update(array.tobytes())
    return digest.hexdigest()


def run_key(method: str, config: Any, exemplars: Mapping[str, np.ndarray], **extra: Any) -> str:
    """The identity of a run: JSON of ``method``, ``config`` (a dict or an object with
    ``to_dict()``), the :func:`exemplar_digest` of every named exemplar and ``extra`` (JSON-able
    values, e.g. the solver's decision rule).

    >>> run_key("m", {"size": 8}, {"front": np.zeros((2, 2))})[:40]
    '{"config": {"size": 8}, "exemplars": {"f'
    """
    settings = config if isinstance(config, Mapping) else config.to_dict()
    return json.dumps({"method": method, "config": settings,
                       "exemplars": {name: exemplar_digest(a) for name, a in exemplars.items()},
                       **extra}, sort_keys=True, default=str)


def as_bytes_array(data: bytes) -> np.ndarray:
    """Bytes as a uint8 array, the form a checkpoint member takes (``.tobytes()`` undoes it)."""
    return np.frombuffer(data, dtype=np.uint8)


# --------------------------------------------------------------------------- files


def save_checkpoint(path: str | os.PathLike[str], /, **arrays: Any) -> pathlib.Path:
    """Save named arrays and scalars to an ``.npz`` file, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        Output file (conventionally ``*.npz``; no extension is appended).
    **arrays : array_like
        Arrays and scalars (numbers, strings, bools) to store; no Python objects.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    TypeError
        If a value is not numeric, boolean or string data (e.g. ``None`` or a dict), which
        :func:`load_checkpoint` could not read back without pickle; nothing is written then.
    """
    arrays = {name: np.asarray(value) for name, value in arrays.items()}
    for name, value in arrays.items():
        if value.dtype.hasobject:
            raise TypeError(
                f"checkpoint value {name!r} must be numeric, boolean or string data; "
                f"got {type(value.item() if value.ndim == 0 else value).__name__}"
            )

    if CHECKSUM in arrays:
        raise TypeError(f"checkpoint value name {CHECKSUM!r} is reserved")
    arrays = seal(arrays)

    def write(tmp: pathlib.Path) -> None:
        with open(tmp, "wb") as handle:  # a handle keeps np.savez from appending ".npz"
            np.savez(handle, **arrays)
            handle.flush()
            os.fsync(handle.fileno())

    return atomic_write(path, write)


def seal(arrays: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The members of a checkpoint file: ``arrays`` (as arrays, any old :data:`CHECKSUM`
    dropped) and the checksum of them, what :func:`save_checkpoint` writes.

    >>> sorted(seal({"level": 1}))
    ['level', 'npmrf3d_checksum']
    """
    arrays = {name: np.asarray(value) for name, value in arrays.items() if name != CHECKSUM}
    arrays[CHECKSUM] = np.asarray(_checksum(arrays))
    return arrays


def is_checkpoint_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a file that npmrf3d wrote as a checkpoint, intact or damaged: a zip
    archive (``.npz``) holding the :data:`CHECKSUM` member, or, when its directory cannot be
    read or lacks that member, a zip file whose bytes name it. Anything else is a file of
    someone else's, which is neither read as a checkpoint nor replaced by one."""
    try:
        with zipfile.ZipFile(path) as archive:
            if f"{CHECKSUM}.npy" in archive.namelist():
                return True
    except (zipfile.BadZipFile, ValueError, EOFError):
        pass
    except OSError:
        return False
    try:
        with open(path, "rb") as handle:
            data = handle.read()
    except OSError:
        return False
    return data.startswith(b"PK\x03\x04") and f"{CHECKSUM}.npy".encode() in data


def _checksum(arrays: Mapping[str, np.ndarray]) -> str:
    digest = hashlib.sha256()
    for name in sorted(n for n in arrays if n != CHECKSUM):
        value = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}|{value.dtype.str}|{value.shape}|".encode())
        digest.update(value.tobytes())
    return digest.hexdigest()


def load_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Load a checkpoint written by :func:`save_checkpoint`.

    Returns
    -------
    dict
        Name -> array; 0-d arrays (saved scalars) come back as Python scalars.

    Raises
    ------
    ParameterError
        If the file is missing or is not a readable checkpoint.
    """
    what = "checkpoint file"
    path = _existing_file(path, what)
    if not is_checkpoint_file(path):
        raise ParameterError(f"{what} '{path}' is not a checkpoint file of npmrf3d; "
                             f"choose another --checkpoint (the file is left untouched)")
    try:
        with open(path, "rb") as handle, np.load(handle, allow_pickle=False) as npz:
            items = {name: npz[name] for name in npz.files}
    except Exception as exc:
        raise ParameterError(f"{what} '{path}' cannot be read (damaged or not a checkpoint): "
                             f"{_reason(exc)}; delete it to start afresh") from exc
    stored = str(items.pop(CHECKSUM, ""))
    if _checksum(items) != stored:
        raise ParameterError(f"{what} '{path}' is damaged (its checksum does not match its "
                             f"contents); delete it to start afresh")
    return {name: value.item() if value.ndim == 0 else value for name, value in items.items()}


# --------------------------------------------------------------------------- resuming


def save_run_state(path: str | os.PathLike[str], key: str, /, **arrays: Any) -> pathlib.Path:
    """:func:`save_checkpoint` of a run's state under its identity ``key`` (:func:`run_key`)."""
    return save_checkpoint(path, **{KEY: key}, **arrays)


def load_run_state(path: str | os.PathLike[str] | None, key: str, *,
                   fingerprint: Mapping[str, np.ndarray] | None = None) -> dict[str, Any] | None:
    """The state a checkpoint holds, or None when there is none to resume (no path, no file).

    Parameters
    ----------
    path : path or None
    key : str
        The run's identity (:func:`run_key`); the file's must be the same.
    fingerprint : dict of arrays, optional
        Further arrays the file must hold equal (e.g. the label set of the exemplars).

    Raises
    ------
    ParameterError
        If the file cannot be read or is damaged (:func:`load_checkpoint`), or was written by
        another run: a different method, configuration or exemplar.
    """
    if path is None or not pathlib.Path(path).exists():
        return None
    data = load_checkpoint(path)
    same = str(data.get(KEY)) == key and all(
        name in data and np.array_equal(data[name], value) for name, value in (fingerprint or {}).items())
    if not same:
        raise ParameterError(f"checkpoint '{path}' was written by a different configuration or "
                             f"exemplar; delete it or choose another checkpoint path")
    return data


# --------------------------------------------------------------------------- checking the contents


def refusal(path: str | os.PathLike[str], reason: str) -> ParameterError:
    """The one refusal of a checkpoint whose checksum holds but whose contents this run cannot
    resume from (``reason`` names the member and what is wrong with it)."""
    return ParameterError(f"checkpoint '{path}' does not hold a state this run can resume "
                          f"({reason}); delete it or choose another checkpoint path")


def check_members(path, data: Mapping[str, Any], required: Iterable[str],
                  optional: Iterable[str] = ()) -> None:
    """Every ``required`` member present and none beyond ``required`` and ``optional``."""
    required = set(required)
    missing = sorted(required - set(data))
    if missing:
        raise refusal(path, f"member '{missing[0]}' is missing")
    extra = sorted(set(data) - required - set(optional))
    if extra:
        raise refusal(path, f"member '{extra[0]}' is not part of this run's state")


def check_array(path, data: Mapping[str, Any], name: str, shape: tuple[int, ...], dtype: Any,
                low: Any = None, high: Any = None) -> np.ndarray:
    """Member ``name`` as an array of exactly ``shape`` and ``dtype`` with finite values within
    ``[low, high]`` (bounds broadcast against the array; None: no bound). Returns it."""
    value = data.get(name)
    dtype = np.dtype(dtype)
    if not isinstance(value, np.ndarray):
        raise refusal(path, f"'{name}' is {type(value).__name__}, not an array of shape {tuple(shape)}")
    if value.shape != tuple(shape):
        raise refusal(path, f"'{name}' has shape {value.shape}; this run's level needs {tuple(shape)}")
    if value.dtype != dtype:
        raise refusal(path, f"'{name}' has dtype {value.dtype}; this run needs {dtype}")
    if value.dtype.kind == "f" and not np.isfinite(value).all():
        raise refusal(path, f"'{name}' holds NaN or infinite values")
    if value.size and low is not None and np.any(value < low):
        raise refusal(path, f"'{name}' holds values below {_bound(low)}")
    if value.size and high is not None and np.any(value > high):
        raise refusal(path, f"'{name}' holds values above {_bound(high)}")
    return value


def _bound(bound: Any) -> str:
    bound = np.asarray(bound)
    return str(bound.item()) if bound.size == 1 else f"the allowed range ({bound.min()}..{bound.max()})"


def check_rng_state(path, text: Any, bit_generator: np.random.BitGenerator) -> dict[str, Any]:
    """The generator state stored as JSON ``text``: a valid state of the same kind as
    ``bit_generator`` (e.g. PCG64), checked on a fresh generator of that kind. Returns it."""
    kind = type(bit_generator).__name__
    try:
        state = json.loads(text) if isinstance(text, str) else None
    except ValueError:
        state = None
    if not isinstance(state, dict):
        raise refusal(path, f"'rng_state' is not a {kind} generator state")
    if state.get("bit_generator") != kind:
        raise refusal(path, f"'rng_state' is a state of {state.get('bit_generator')!r}, not of {kind}")
    probe = type(bit_generator)()
    try:
        probe.state = state
    except (TypeError, ValueError, KeyError, IndexError, OverflowError, AttributeError) as exc:
        raise refusal(path, f"'rng_state' is not a valid {kind} state: {_reason(exc)}") from None
    if probe.state != state or state.get("has_uint32", 0) not in (0, 1):
        raise refusal(path, f"'rng_state' is not a valid {kind} state")
    return state
