"""The neural method's training checkpoint: what it must match, how it is written, and every
member checked before a run resumes from it (:mod:`npmrf3d.io.checkpoints` holds the file
format, the checksum and the one refusal message)."""

from __future__ import annotations

import io
import json
import math
import pickle

import numpy as np
import torch

from ...io.checkpoints import (
    KEY,
    as_bytes_array,
    check_array,
    check_members,
    check_rng_state,
    load_run_state,
    refusal,
    run_key,
    save_run_state,
)
from .config import NeuralConfig

__all__ = ["load_training_state", "restore_torch_state", "save_training_state", "training_key"]


def training_key(config: NeuralConfig, exemplars: dict) -> str:
    """What a checkpoint must match (:func:`npmrf3d.io.checkpoints.run_key`): the configuration
    and the exemplars. The volume size, the step count and the checkpoint interval are left out:
    a step's randomness does not depend on them, so a finished run's checkpoint extends to more
    ``iterations`` exactly as if it had been asked for from the start."""
    settings = config.to_dict()
    for name in ("size", "iterations", "checkpoint_every"):
        settings.pop(name)
    return run_key("neural", settings, exemplars)


def save_training_state(path, key, iteration, generator, optimizer, rng, history, seconds) -> None:
    """The torch state (weights, Adam's moments) as the bytes of ``torch.save``, the rest as arrays."""
    buffer = io.BytesIO()
    torch.save({"generator": generator.state_dict(), "optimizer": optimizer.state_dict()}, buffer)
    save_run_state(path, key, iteration=iteration, torch_state=as_bytes_array(buffer.getvalue()),
                   rng_state=json.dumps(rng.bit_generator.state),
                   history=np.asarray(history, dtype=np.float64), seconds=float(seconds))


def load_training_state(path, key, rng: np.random.Generator) -> dict | None:
    """The saved state (``torch_state`` loaded back into tensors), or None when there is none.

    Past its checksum and identity every member is checked (the step counter, one loss per step
    done, the generator state, the torch state's bytes); anything else is refused with the one
    checkpoint refusal (:func:`npmrf3d.io.checkpoints.refusal`)."""
    data = load_run_state(path, key)
    if data is None:
        return None
    check_members(path, data, [KEY, "iteration", "torch_state", "rng_state", "history", "seconds"])
    done = data["iteration"]
    if isinstance(done, bool) or not isinstance(done, int) or done < 0:
        raise refusal(path, f"'iteration' is {done!r}, not a count of steps done")
    check_array(path, data, "history", (done,), np.float64)
    seconds = data["seconds"]
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not 0 <= seconds < math.inf:
        raise refusal(path, f"'seconds' is {seconds!r}, not a finite time")
    check_rng_state(path, data["rng_state"], rng.bit_generator)
    raw = data["torch_state"]
    if not isinstance(raw, np.ndarray) or raw.dtype != np.uint8 or raw.ndim != 1:
        raise refusal(path, "'torch_state' is not the bytes of a torch state")
    try:
        state = torch.load(io.BytesIO(raw.tobytes()), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds on bytes it cannot read
        raise refusal(path, f"'torch_state' cannot be read: {torch_load_failure(exc)}") from None
    if not isinstance(state, dict) or not {"generator", "optimizer"} <= set(state):
        raise refusal(path, "'torch_state' holds no generator and optimizer state")
    data["torch_state"] = state
    return data


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


#: How a file written by ``torch.save`` begins: a zip archive, or a pickle (the legacy format).
TORCH_FILE_HEADS = (b"PK\x03\x04", b"\x80")


def file_head(source) -> bytes | None:
    """The first bytes of a file (a path) or of bytes; None when the file cannot be read."""
    if isinstance(source, (bytes, bytearray)):
        return bytes(source[:4])
    try:
        with open(source, "rb") as handle:
            return handle.read(4)
    except OSError:
        return None


def torch_load_failure(exc: BaseException, head: bytes | None = None) -> str:
    """Why ``torch.load(..., weights_only=True)`` refused a file, in one short clause: a file that
    does not begin as ``torch.save`` writes (``head``, its first bytes) is no torch file; a file
    with pickled objects besides tensors is refused as such (torch's own text would suggest
    loading it with ``weights_only=False``, which runs code from the file); other reasons keep
    their first sentence."""
    if head is not None and not head.startswith(TORCH_FILE_HEADS):
        return "it is not a file written by torch (no zip archive, no pickle)"
    if isinstance(exc, pickle.UnpicklingError):
        return "it holds Python objects besides tensors, which are never loaded"
    return _first_line(exc).split(". ", 1)[0]


def restore_torch_state(path, state: dict, generator, optimizer) -> None:
    """Load a checked checkpoint's weights and Adam state; one refusal if they do not fit."""
    try:
        generator.load_state_dict(state["torch_state"]["generator"])
        optimizer.load_state_dict(state["torch_state"]["optimizer"])
    except (RuntimeError, ValueError, KeyError, TypeError) as exc:
        raise refusal(path, f"'torch_state' does not fit this generator: {_first_line(exc)}") from None
