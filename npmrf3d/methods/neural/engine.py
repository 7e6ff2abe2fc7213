"""The torch side of the neural method: the model object, training, generation, model files.

Imported only through :func:`npmrf3d.methods.neural._extra.engine` (the documented lazy import), so
``import npmrf3d`` never imports torch.

Training (Gutierrez et al. 2020, section 5): each step draws, per constrained view, ``batch`` single-slice
blocks of the unbounded volume at random integer origins (the slice orientation of the view,
:data:`npmrf3d.model.neighbourhood.VIEW_AXES`), and minimises the Gram loss of their descriptor
features against the view's exemplar (plus ``histogram_weight`` times the sorted-value distance
of the slice's values to the exemplar's, :func:`~npmrf3d.methods.neural.descriptor.histogram_loss`)
with Adam. Random origins are the paper's doubly
stochastic sampling (eq. 7-8): fresh noise, and every phase modulo ``2**(scales - 1)``.
All randomness comes from one numpy Generator (slice origins) and the config's seed (weights,
filter bank), so a checkpoint (weights, Adam state, normalisation statistics, the Generator's
state, the loss history) resumes bit for bit.
"""

from __future__ import annotations

import io
import itertools
import json
import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import torch

from ...errors import ParameterError
from ...io.files import atomic_write
from ...model.neighbourhood import VIEW_AXES
from .checkpoint import (
    file_head,
    load_training_state,
    restore_torch_state,
    save_training_state,
    torch_load_failure,
    training_key,
)
from .config import NeuralConfig
from .descriptor import gram, gram_loss, histogram_loss, histogram_target, make_descriptor
from .generator import SolidGenerator

__all__ = ["FORMAT", "NeuralModel", "apply_calibration", "colour_basis", "default_device", "fit_calibration", "generate_block",
           "load_model", "model_bytes", "save_model", "train_model"]

#: The ``format`` entry of a model file.
FORMAT = "npmrf3d-neural-1"
#: Slice origins are drawn uniformly in [0, ORIGIN_RANGE) per axis.
ORIGIN_RANGE = 2 ** 24
#: Factor on the default initial weights of the last convolution (outputs start close to the
#: mean colour; with the default initialisation the first losses are 10^4 times the exemplar's
#: Gram norms and Adam's first steps diverge).
INIT_GAIN = 0.1


@dataclass
class NeuralModel:
    """A trained generator with what made it.

    Attributes
    ----------
    generator : SolidGenerator
        The network (in evaluation mode once trained).
    config : NeuralConfig
        The training configuration.
    history : list of float
        Training loss after each step.
    timings : dict
        ``train`` seconds (total over resumed runs).
    exemplars : dict
        View -> (H, W, C) of the exemplar it was trained on.
    calibration : (C, 2, Q) float32 ndarray or None
        Per colour component, ``Q`` quantiles of the raw output (row 0, increasing) and the
        exemplars' (row 1): every generated value is mapped through the piecewise-linear map
        between them (:func:`fit_calibration`); None: the raw output.
    colour_basis : (C + 1, C) float32 ndarray or None
        The components the map works on: rows ``0 .. C-1`` an orthonormal basis (the principal
        axes of the exemplars' colours), row ``C`` their mean; None: the channels themselves
        (grey models, and model files from before the basis).
    """

    generator: SolidGenerator
    config: NeuralConfig
    history: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    exemplars: dict = field(default_factory=dict)
    calibration: np.ndarray | None = None
    colour_basis: np.ndarray | None = None

    @property
    def channels(self) -> int:
        return self.generator.out_channels

    @property
    def parameters(self) -> int:
        return sum(p.numel() for p in self.generator.parameters())


def default_device() -> torch.device:
    """A CUDA GPU when torch sees one, else the CPU."""
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def _slice_shape(view: str, side: int) -> tuple[int, int, int]:
    rows, cols = VIEW_AXES[view]
    shape = [1, 1, 1]
    shape[rows] = shape[cols] = side
    return tuple(shape)


def _as_image(block: torch.Tensor, view: str) -> torch.Tensor:
    """(1, C, N1, N2, N3) single-slice block -> (1, C, rows, cols) in the view's orientation."""
    rows, cols = VIEW_AXES[view]
    thin = 3 - rows - cols  # the axis the slice is orthogonal to
    return block.squeeze(2 + thin)


def train_model(per_view: dict, config: NeuralConfig, rng: np.random.Generator, *, progress=None,
                checkpoint=None) -> NeuralModel:
    """Train a generator on validated float32 (H, W, C) exemplars, one per constrained view.

    ``progress(step, steps, loss)`` is called after each step (and with step 0 first);
    ``checkpoint``: a file written every ``config.checkpoint_every`` steps and at the end, and
    resumed from when it exists and matches this run.
    """
    channels = next(iter(per_view.values())).shape[2]
    torch.manual_seed(config.seed or 0)
    generator = SolidGenerator(out_channels=channels, seed=config.seed or 0, **config.architecture)
    mean = np.mean([a.reshape(-1, channels).mean(axis=0) for a in per_view.values()], axis=0)
    with torch.no_grad():  # start near the exemplars' mean colour: a loss of sane size from step 1
        generator.final.weight.mul_(INIT_GAIN)
        generator.final.bias.copy_(torch.as_tensor(mean, dtype=torch.float32))
    device = default_device()
    generator.to(device)
    descriptor = make_descriptor(config, channels, mean).to(device)
    sides = {v: config.slice_side(a.shape) for v, a in per_view.items()}
    targets, values = {}, {}
    with torch.no_grad():
        for view, exemplar in per_view.items():
            image = torch.from_numpy(np.ascontiguousarray(exemplar.transpose(2, 0, 1)))[None].to(device)
            targets[view] = [gram(f) for f in descriptor(image)]
            values[view] = [t.to(device) for t in histogram_target(image[0].cpu(), sides[view] ** 2)]
    optimizer = torch.optim.Adam(generator.parameters(), lr=config.learning_rate)
    key = training_key(config, per_view)
    start, history, seconds = 0, [], 0.0
    state = load_training_state(checkpoint, key, rng)
    if state is not None:
        restore_torch_state(checkpoint, state, generator, optimizer)
        rng.bit_generator.state = json.loads(str(state["rng_state"]))
        start, seconds = int(state["iteration"]), float(state["seconds"])
        history = [float(x) for x in state["history"]]
    generator.train()
    if progress is not None:
        progress(start, config.iterations, history[-1] if history else math.nan)
    t0 = time.perf_counter()
    for step in range(start, config.iterations):
        origins = rng.integers(0, ORIGIN_RANGE, size=(len(per_view), config.batch, 3))
        optimizer.zero_grad(set_to_none=True)
        total = 0.0
        for v, view in enumerate(per_view):
            for b in range(config.batch):
                block = generator(tuple(int(o) for o in origins[v, b]), _slice_shape(view, sides[view]))
                image = _as_image(block, view)
                loss = gram_loss(descriptor, image, targets[view])
                if config.histogram_weight:
                    loss = loss + config.histogram_weight * histogram_loss(image, *values[view])
                loss = loss / (len(per_view) * config.batch)
                loss.backward()  # one slice at a time: memory of one slice, as in the paper
                total += float(loss.detach())
        optimizer.step()
        history.append(total)
        done = step + 1
        if checkpoint is not None and (done % config.checkpoint_every == 0 or done == config.iterations):
            save_training_state(checkpoint, key, done, generator, optimizer, rng, history,
                             seconds + time.perf_counter() - t0)
        if progress is not None:
            progress(done, config.iterations, total)
    generator.eval()
    timings = {"train": seconds + time.perf_counter() - t0}
    model = NeuralModel(generator, config, history, timings,
                        {v: tuple(int(n) for n in a.shape) for v, a in per_view.items()})
    if config.calibrate:
        t1 = time.perf_counter()
        model.calibration, model.colour_basis = fit_calibration(model, per_view)
        model.timings["calibrate"] = time.perf_counter() - t1
    return model


# --------------------------------------------------------------------------- calibration

#: Side of the block of raw output the calibration map is fitted on, and the quantiles kept.
CALIBRATION_SIDE = 48
CALIBRATION_QUANTILES = 257


def colour_basis(colours: np.ndarray) -> np.ndarray | None:
    """The ``(C + 1, C)`` principal axes (rows, largest variance first) and mean of ``colours``
    ``(N, C)``; None for one channel. Each axis's sign makes its largest entry positive."""
    colours = np.asarray(colours, dtype=np.float64)
    if colours.shape[1] < 2:
        return None
    mean = colours.mean(axis=0)
    _, vectors = np.linalg.eigh(np.cov(colours - mean, rowvar=False))
    axes = vectors[:, ::-1].T
    axes *= np.where(axes[np.arange(len(axes)), np.abs(axes).argmax(axis=1)] < 0, -1.0, 1.0)[:, None]
    return np.vstack([axes, mean]).astype(np.float32)


def _to_components(values: np.ndarray, basis: np.ndarray | None) -> np.ndarray:
    if basis is None:
        return values
    c = values.shape[-1]
    return (values.astype(np.float64) - basis[c]) @ basis[:c].astype(np.float64).T


def fit_calibration(model: NeuralModel, per_view: dict) -> tuple[np.ndarray, np.ndarray | None]:
    """The ``(C, 2, Q)`` quantile map of :attr:`NeuralModel.calibration` and the colour basis
    it works in (:attr:`NeuralModel.colour_basis`).

    Raw output: the block ``[0, CALIBRATION_SIDE)^3`` of the model's own noise (110,592 voxels).
    Target: every pixel of every view's exemplar, pooled. Colour models are mapped per
    principal component of the exemplars' colours (:func:`colour_basis`), not per channel: the
    components of a natural image's colours are nearly independent, its channels are not, so
    a per-channel map can make colours the exemplar never has (a red channel at its maximum
    where green is at its minimum: magenta), while a map per component keeps the chroma within
    the exemplar's range. Row 0 is made strictly increasing (flat stretches of the raw quantiles
    are spread by a few float32 steps) so that the map is a function; values outside the raw
    range map to the exemplars' extremes.
    """
    raw = _raw_block(model, (0, 0, 0), (CALIBRATION_SIDE,) * 3, None)
    channels = raw.shape[-1]
    levels = np.linspace(0.0, 1.0, CALIBRATION_QUANTILES)
    target = np.concatenate([a.reshape(-1, channels) for a in per_view.values()]).astype(np.float64)
    basis = colour_basis(target)
    raw, target = _to_components(raw.reshape(-1, channels), basis), _to_components(target, basis)
    out = np.empty((channels, 2, CALIBRATION_QUANTILES), dtype=np.float32)
    for c in range(channels):
        xs = np.quantile(raw[:, c].astype(np.float64), levels).astype(np.float32)
        for q in range(1, len(xs)):
            if not xs[q] > xs[q - 1]:
                xs[q] = np.nextafter(xs[q - 1], np.float32(np.inf))
        out[c, 0] = xs
        out[c, 1] = np.quantile(target[:, c], levels)
    return out, basis


def apply_calibration(values: np.ndarray, calibration: np.ndarray | None,
                      basis: np.ndarray | None = None) -> np.ndarray:
    """``values`` (..., C) float32 through the map of each component (in place, pointwise):
    the channels themselves, or the components in ``basis`` (:func:`colour_basis`)."""
    if calibration is None:
        return values
    if basis is None:
        for c in range(values.shape[-1]):
            values[..., c] = np.interp(values[..., c], calibration[c, 0], calibration[c, 1])
        return values
    c = values.shape[-1]
    comps = _to_components(values.reshape(-1, c), basis)
    for i in range(c):
        comps[:, i] = np.interp(comps[:, i], calibration[i, 0], calibration[i, 1])
    values[...] = (comps @ basis[:c].astype(np.float64) + basis[c]).reshape(values.shape)
    return values


# --------------------------------------------------------------------------- generation


def _tiles(origin, shape, tile: int):
    """Lattice ranges of the canonical tiles (multiples of ``tile``) covering the block, per axis."""
    per_axis = []
    for o, n in zip(origin, shape):
        first, last = o // tile, (o + n - 1) // tile
        per_axis.append(range(first, last + 1))
    return per_axis


def _tile_values(generator: SolidGenerator, t0, tile: int, seed) -> np.ndarray:
    with torch.no_grad():
        return generator(t0, (tile,) * 3, seed=seed)[0].permute(1, 2, 3, 0).cpu().numpy()


def generate_block(model: NeuralModel, origin, shape, *, seed: int | None = None) -> np.ndarray:
    """The block ``origin + [0, shape)`` of the model's volume, float32 ``(N1, N2, N3, C)``:
    the generator's raw values (:func:`_raw_block`) through the model's calibration map."""
    return apply_calibration(_raw_block(model, origin, shape, seed), model.calibration,
                             model.colour_basis)


def _raw_block(model: NeuralModel, origin, shape, seed) -> np.ndarray:
    """The generator's own values of the block ``origin + [0, shape)``, float32 ``(N1, N2, N3, C)``.

    Computed tile by tile on the canonical grid of ``model.config.tile``: every tile is one
    forward pass of the same shape, cut to the block, so a block's values are the same whatever
    blocks a volume is split into, bit for bit (the convolution library's summation order
    depends on the shape of a call, so uncut blocks of other shapes would differ in the last
    bits). Tiles run in parallel on ``torch.get_num_threads()`` threads, each tile on one
    (the library's own threading also changes the last bits), so the values do not depend on
    the thread count either. The tiles are computed by :meth:`SolidGenerator.for_inference`
    (normalisations folded into the convolutions, channels-last: the layout a CPU convolves
    fastest).
    """
    generator, tile = model.generator, model.config.tile
    generator.eval()
    if generator.device.type == "cuda":  # one algorithm per tile shape, run the same way each time
        torch.backends.cudnn.benchmark = False
        torch.backends.cudnn.deterministic = True
    out = np.empty((*shape, model.channels), dtype=np.float32)
    corners = [(a * tile, b * tile, c * tile) for a, b, c in itertools.product(*_tiles(origin, shape, tile))]
    generator = generator.for_inference()  # norms folded, channels-last: a copy
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            for first in range(0, len(corners), threads):
                batch = corners[first:first + threads]
                for t0, values in zip(batch, pool.map(lambda t: _tile_values(generator, t, tile, seed), batch)):
                    lo = [max(o, t) for o, t in zip(origin, t0)]
                    hi = [min(o + n, t + tile) for o, n, t in zip(origin, shape, t0)]
                    out[tuple(slice(l - o, h - o) for l, h, o in zip(lo, hi, origin))] = \
                        values[tuple(slice(l - t, h - t) for l, h, t in zip(lo, hi, t0))]
    finally:
        torch.set_num_threads(threads)
    return out


# --------------------------------------------------------------------------- model files


def _payload(model: NeuralModel) -> dict:
    return {"format": FORMAT, "config": json.dumps(model.config.to_dict()),
            "out_channels": model.channels, "state": model.generator.state_dict(),
            "history": list(model.history), "timings": json.dumps(model.timings),
            "exemplars": json.dumps(model.exemplars),
            "calibration": None if model.calibration is None else model.calibration.tolist(),
            "colour_basis": None if model.colour_basis is None else model.colour_basis.tolist()}


def model_bytes(model: NeuralModel) -> bytes:
    """The model file's content (what :func:`save_model` writes)."""
    buffer = io.BytesIO()
    torch.save(_payload(model), buffer)
    return buffer.getvalue()


def save_model(model: NeuralModel, path) -> None:
    """Write the model file atomically."""
    data = model_bytes(model)
    atomic_write(path, lambda tmp: tmp.write_bytes(data))


def load_model(source) -> NeuralModel:
    """Read a model file (a path or its bytes) written by :func:`save_model`."""
    what = f"model file '{source}'" if not isinstance(source, bytes) else "model data"
    try:
        payload = torch.load(io.BytesIO(source) if isinstance(source, bytes) else source,
                             map_location="cpu", weights_only=True)
    except Exception as exc:
        raise ParameterError(f"{what} cannot be read as a neural model: "
                             f"{torch_load_failure(exc, file_head(source))}") from exc
    if not isinstance(payload, dict) or payload.get("format") != FORMAT:
        raise ParameterError(f"{what} is not an npmrf3d neural model (written by 'npmrf3d neural train')")
    try:
        return _model_from_payload(payload)
    except Exception as exc:  # a damaged file: missing entries, wrong shapes, bad settings
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise ParameterError(f"{what} is damaged or not a model of this npmrf3d version "
                             f"({type(exc).__name__}: {reason[:160]}); train it again with "
                             "'npmrf3d neural train'") from exc


def _model_from_payload(payload: dict) -> NeuralModel:
    settings = json.loads(payload["config"])
    settings["size"] = tuple(settings["size"])
    settings["views"] = tuple(settings["views"])
    settings.setdefault("histogram_weight", 0.0)  # model files from before the histogram term
    settings.setdefault("calibrate", False)  # and from before the calibration map
    config = NeuralConfig(**settings)
    generator = SolidGenerator(out_channels=int(payload["out_channels"]), seed=config.seed or 0,
                               **config.architecture)
    generator.load_state_dict(payload["state"])
    generator.to(default_device()).eval()
    exemplars = {v: tuple(s) for v, s in json.loads(payload["exemplars"]).items()}
    calibration, basis = payload.get("calibration"), payload.get("colour_basis")
    return NeuralModel(generator, config, list(payload["history"]), json.loads(payload["timings"]),
                       exemplars, None if calibration is None else np.asarray(calibration, dtype=np.float32),
                       None if basis is None else np.asarray(basis, dtype=np.float32))
