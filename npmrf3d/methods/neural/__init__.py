"""On-demand solid textures from a compact 3D convolutional generator (Gutierrez et al. 2020).

A small network (about 85,000 parameters with the paper's settings) turns coordinate-seeded,
multi-scale noise into a colour volume; trained on single slices against the exemplar of each
constrained view, it then produces **any block of an unbounded volume on its own**, and blocks
tile exactly. Needs the optional extra ``npmrf3d[neural]`` (PyTorch; a GPU is used when
present); this module itself imports no torch, so ``import npmrf3d`` stays light and a missing
extra is one clear message (:class:`MissingExtraError`).

Public API
----------
train(exemplar=None, *, exemplars=None, rng=None, progress=None, checkpoint=None, **options)
    Train a generator; ``options`` are the fields of :class:`NeuralConfig`.
generate(model, origin=(0, 0, 0), shape=32, *, seed=None)
    The block at ``origin`` of the model's volume, float32 ``(N1, N2, N3, C)``.
save_model, load_model
    Model files (``.pt``; atomic writes).
write_zarr(model_path, out, *, size, ...)
    A big volume into a Zarr array block by block on a Dask cluster (resumable).

Examples
--------
>>> cfg = make_neural_config(iterations=20, slice_size=32)
>>> cfg.tile
64
"""

from __future__ import annotations

import hashlib
import os
import pathlib
import time

import numpy as np

from ... import _validation as check
from ..._cluster import check_scheduler, probe_scheduler
from ...config import DEFAULT_SIZE, SynthesisMethod, SynthesisResult
from ...errors import ParameterError
from ...model.exemplar import resolve_exemplars
from ...resources import check_memory, generate_estimate, neural_estimate
from .._api import prepare, seed_of
from . import _extra
from ._extra import MissingExtraError
from .config import ORIGIN_LIMIT, ZARR_BLOCK, ZARR_WORKERS, NeuralConfig, make_neural_config

__all__ = ["METHOD", "MissingExtraError", "NeuralConfig", "generate", "load_model",
           "make_neural_config", "model_identity", "save_model", "train", "write_zarr"]

#: What every exemplar must fit (a 3x3 window at one level: the descriptor needs some pixels).
_FIT = {"window": 3, "levels": 1, "toroidal": False}


def _fit(config) -> dict:
    return dict(_FIT)


def train(exemplar=None, *, exemplars=None, rng=None, progress=None, checkpoint=None, **options):
    """Train the on-demand generator on one exemplar per constrained view.

    Parameters
    ----------
    exemplar : path, array or None
        Used for every view without its own entry in ``exemplars`` (None: the bundled default).
    exemplars : mapping view -> path or array, optional
    rng : None, int or numpy Generator
        Seeds everything: the training slices' positions and, when an integer, the model's
        weights, filter bank and noise (unless ``options["seed"]`` gives those their own seed).
    progress : callable, optional
        ``progress(step, steps, loss)`` after each optimiser step.
    checkpoint : path, optional
        Written every ``checkpoint_every`` steps; resumed from when it exists and matches.
    **options
        Fields of :class:`NeuralConfig` (``iterations``, ``slice_size``, ``views``, ...).

    Returns
    -------
    NeuralModel
        ``generator``, ``config``, ``history`` (loss per step), ``timings``.
    """
    config = make_neural_config(**{"seed": seed_of(rng), **options})
    rng = check.rng(rng)
    per_view = resolve_exemplars(exemplar, exemplars, config.views, **_fit(config))
    check_memory(neural_estimate(config, per_view), hint="lower --size (the slice side) or --batch")
    eng = _extra.engine("training the neural generator")
    return eng.train_model(per_view, config, rng, progress=progress,
                           checkpoint=None if checkpoint is None else pathlib.Path(checkpoint))


def generate(model, origin=(0, 0, 0), shape=32, *, seed=None) -> np.ndarray:
    """The block ``origin + [0, shape)`` of the unbounded volume a trained model describes.

    Parameters
    ----------
    model : NeuralModel
        From :func:`train` or :func:`load_model`.
    origin : int or three ints
        Integer voxel coordinate of the block's first voxel (negative allowed).
    shape : int or three ints
        Block size per axis (>= 1).
    seed : int, optional
        Another volume of the same texture (default: the model's own seed).

    Returns
    -------
    (N1, N2, N3, C) float32 ndarray
        Blocks of one model and seed tile exactly: the block at ``o`` of shape ``n`` equals the
        ``[o - p, o - p + n)`` part of any larger block at ``p`` that contains it, bit for bit.
    """
    origin = tuple(check.integer("origin", o, low=-ORIGIN_LIMIT, high=ORIGIN_LIMIT)
                   for o in check.triple("origin", origin))
    shape = check.triple("shape", shape, low=1)
    if seed is not None:
        seed = check.integer("seed", seed, low=0, high=2**62)
    check_memory(generate_estimate(model, shape), hint="ask for a smaller shape, or write a Zarr "
                 "volume block by block (write_zarr, 'npmrf3d neural generate --out vol.zarr')")
    return _extra.engine("generating with the neural generator").generate_block(model, origin, shape, seed=seed)


def save_model(model, path) -> None:
    """Write ``model`` to ``path`` (a ``.pt`` file, atomically)."""
    _extra.engine("saving a neural model").save_model(model, path)


def load_model(path):
    """Read a model written by :func:`save_model` (``ParameterError`` if it is not one)."""
    if not os.path.isfile(path):
        check.fail(f"model must be an existing model file (from 'npmrf3d neural train'); got {str(path)!r}")
    return _extra.engine("loading a neural model").load_model(path)


def model_identity(model_path) -> dict:
    """The identity of a model's Zarr volumes (the model file's SHA-256), which their attributes
    keep: a folder made by another model is refused, not mixed."""
    return {"npmrf3d_model_sha256": hashlib.sha256(pathlib.Path(model_path).read_bytes()).hexdigest()}


def write_zarr(model_path, out, *, size, block: int = ZARR_BLOCK, scheduler: str | None = None,
               workers: int = ZARR_WORKERS, overwrite: bool = False, progress=None) -> dict:
    """Write the ``size`` volume at the origin into the Zarr array ``out``, block by block on
    a Dask cluster (see :func:`npmrf3d.methods.neural.zarr_volume.write_zarr`); ``block`` must be a
    multiple of the model's tile. The output is locked for the run, and a volume replaced with
    ``overwrite`` stays until the new one is complete
    (:func:`npmrf3d.io.zarr_blocks.write_volume`)."""
    size = check.triple("size", size, low=1)
    block = check.integer("block", block, low=1)
    workers = check.integer("workers", workers, low=1)
    if not os.path.isfile(model_path):
        check.fail(f"model must be an existing model file (from 'npmrf3d neural train'); got {str(model_path)!r}")
    if scheduler == "local":  # as the study's option: a local cluster
        scheduler = None
    if scheduler is not None:
        # checked before the Zarr folder is made: a wrong or silent address leaves nothing behind
        try:
            if not isinstance(scheduler, str) or scheduler == "serial":
                raise ParameterError(scheduler)
            check_scheduler(scheduler)
        except ParameterError:
            check.fail(f"scheduler must be 'local' or a Dask scheduler address such as "
                       f"'tcp://HOST:8786'; got {scheduler!r}")
        probe_scheduler(scheduler)
    return _extra.zarr_writer().write_zarr(model_path, out, size=size, block=block,
                                           scheduler=scheduler, workers=workers,
                                           overwrite=overwrite, progress=progress)


def neural_method(per_view, config: NeuralConfig, rng: np.random.Generator, *, progress=None,
                  checkpoint=None, t_start=None) -> SynthesisResult:
    """The registered method: train on the exemplars, then generate ``config.size`` at the origin
    (timings ``train`` and ``generate`` apart). ``progress(0, step, steps, loss)``."""
    eng = _extra.engine("the neural method")
    t0 = time.perf_counter() if t_start is None else t_start
    step = None if progress is None else (lambda i, n, loss: progress(0, i, n, loss))
    model = eng.train_model(per_view, config, rng, progress=step,
                            checkpoint=None if checkpoint is None else pathlib.Path(checkpoint))
    t1 = time.perf_counter()
    volume = eng.generate_block(model, (0, 0, 0), config.size)
    t2 = time.perf_counter()
    channels = volume.shape[3]
    timings = {"train": model.timings["train"], "generate": t2 - t1, "total": t2 - t0}
    stats = {"parameters": model.parameters, "iterations": config.iterations}
    return SynthesisResult(volume=volume, history=[list(model.history)], config=config,
                           timings=timings, labels=np.zeros((0, channels), np.float32), stats=stats)


def neural_synthesize(exemplar=None, *, size=DEFAULT_SIZE, rng=None, progress=None, checkpoint=None,
                      exemplars=None, **options) -> SynthesisResult:
    """Train and generate in one call: ``options`` as :func:`train`, ``size`` the volume made;
    ``rng`` seeds everything (an integer is also the model's seed: weights, filter bank, noise)."""
    t_start = time.perf_counter()
    config, generator, per_view = prepare(METHOD, exemplar, exemplars, size=size, rng=rng,
                                          progress=progress, checkpoint=checkpoint, options=options)
    return neural_method(per_view, config, generator, progress=progress, checkpoint=checkpoint,
                         t_start=t_start)


METHOD = SynthesisMethod(
    name="neural", run=neural_method, make_config=make_neural_config, config_class=NeuralConfig,
    synthesize=neural_synthesize, fit=_fit,
    description="on-demand 3D CNN generator (Gutierrez et al. 2020): trained on slices, any block on "
                "demand; needs npmrf3d[neural]",
    resources=neural_estimate, unavailable=_extra.missing,
)
