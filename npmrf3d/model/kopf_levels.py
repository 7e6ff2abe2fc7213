"""NP_K's side of the shared level loop (:func:`npmrf3d.model.pyramid.run_pyramid`): a level's
state is the volume itself; each iteration searches (:mod:`npmrf3d.model.kopf_search`) and
optimises (:mod:`npmrf3d.model.kopf_optimise`), and a finer level starts from the coarser one
up-sampled (:func:`upsample_volume`).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping

import numpy as np

from .kcoherence import downsample_exemplar
from .kopf_constraints import coarsen_constraint
from .kopf_optimise import channel_histograms, optimisation_phase, pack_exemplars
from .kopf_search import NeighbourhoodIndex, search_view
from .neighbourhood import VIEW_AXES
from .pyramid import ArraySpec, Levels, LevelState
from .pyramid import upsample as pyramid_upsample

__all__ = ["KopfLevels", "upsample_volume"]


def upsample_volume(volume: np.ndarray, mode: str, pixels: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The finer level's volume by :data:`npmrf3d.model.pyramid.UPSAMPLERS` ``mode``; ``1/8`` draws the
    7 new children uniformly from the level's exemplar ``pixels``."""
    shape = volume.shape[:3]
    parent = LevelState(volume=volume, labels_volume=np.zeros(shape, dtype=np.int32),
                        temps=np.zeros(shape, dtype=np.float32), inherited=np.zeros(shape, dtype=bool))
    freq = None if pixels is None else np.full(len(pixels), 1.0 / len(pixels))
    return np.ascontiguousarray(pyramid_upsample(parent, mode, pixels, freq, rng).volume, dtype=np.float32)


class KopfLevels(Levels):
    """NP_K's side of :func:`npmrf3d.model.pyramid.run_pyramid`; the state is the volume itself."""

    def __init__(self, config, per_view: Mapping[str, np.ndarray], constraint,
                 constraint_weight):
        self.config, self.per_view = config, per_view
        self.constraint, self.constraint_weight = constraint, constraint_weight
        self.size, self.levels = config.size, config.levels
        self.key = json.dumps(config.to_dict(), sort_keys=True, default=str)
        self.distinct = list({id(a): a for a in (per_view[v] for v in config.views)}.values())
        self.channels = self.distinct[0].shape[2]
        pooled = np.concatenate([a.reshape(-1, self.channels) for a in self.distinct]).astype(np.float64)
        self.lo = pooled.min(axis=0)
        span = pooled.max(axis=0) - self.lo
        self.scale = np.where(span > 0, config.histogram_bins / np.where(span > 0, span, 1.0), 0.0)
        self.sigma = float(pooled.std()) or 1.0
        self.view_axes = np.array([VIEW_AXES[v] for v in config.views], dtype=np.int64)
        # the volume's bytes depend on the exemplars and the constraint too
        self.fingerprint = {"exemplars": np.concatenate([a.ravel() for a in self.distinct])}
        if constraint is not None:
            self.fingerprint["constraint"] = constraint
            self.fingerprint["constraint_weight"] = constraint_weight

    def prepare(self, level, shape):
        config, views, per_view = self.config, self.config.views, self.per_view
        level_ex = {id(a): downsample_exemplar(a, level) for a in self.distinct}
        indices = {key: NeighbourhoodIndex(ex, config.window, config.variance) for key, ex in level_ex.items()}
        self.view_index = [indices[id(per_view[v])] for v in views]
        self.pixels = np.concatenate([ex.reshape(-1, self.channels) for ex in level_ex.values()])
        self.hist_target = np.mean(
            [channel_histograms(level_ex[id(per_view[v])], self.lo, self.scale, config.histogram_bins)
             / (level_ex[id(per_view[v])].shape[0] * level_ex[id(per_view[v])].shape[1])
             for v in views], axis=0)
        self.packed = pack_exemplars(self.view_index, self.lo, self.scale, config.histogram_bins)
        self.target, self.tau = coarsen_constraint(self.constraint, self.constraint_weight, level)
        self.floor = 1e-3 * self.sigma * math.sqrt(config.window ** 2 * self.channels)
        self.n_iter = config.iterations[config.levels - 1 - level]

    def initial(self, shape, rng):
        return np.ascontiguousarray(self.pixels[rng.integers(0, len(self.pixels), size=shape)],
                                    dtype=np.float32)

    def upsample(self, state, rng):
        return upsample_volume(state, self.config.upsample, self.pixels, rng)

    def start(self, level, state):
        return self.n_iter, float("nan")

    def relax(self, level, volume, rng, on_step):
        config, views, n_iter = self.config, self.config.views, self.n_iter
        shape = volume.shape[:3]
        level_history = []
        t_search = t_opt = 0.0
        queries = 0
        for it in range(n_iter):
            ts = time.perf_counter()
            assign = np.empty((len(views), *shape), dtype=np.int32)
            omega = np.empty((len(views), *shape), dtype=np.float32)
            energy = 0.0
            for vi, view in enumerate(views):
                assign[vi], omega[vi], e, q = search_view(
                    volume, view, self.view_index[vi], grid=config.grid, eps=config.eps, r=config.r,
                    floor=self.floor, offset=int(self.packed.offsets[vi]))
                energy += e
                queries += q
            t_search += time.perf_counter() - ts
            ts = time.perf_counter()
            if config.mean_shift is None:
                bandwidth = 0.0
            else:
                h0, h1 = config.mean_shift
                frac = it / (n_iter - 1) if n_iter > 1 else 1.0
                bandwidth = self.sigma * h0 * (h1 / h0) ** frac
            order = rng.permutation(volume.shape[0] * volume.shape[1] * volume.shape[2]).astype(np.int64)
            hist = channel_histograms(volume, self.lo, self.scale, config.histogram_bins)
            optimisation_phase(volume, assign, omega, self.view_axes, self.packed,
                               window=config.window, grid=config.grid, order=order, hist=hist,
                               hist_target=self.hist_target, histogram_weight=config.histogram_weight,
                               lo=self.lo, scale=self.scale, bins=config.histogram_bins,
                               bandwidth=bandwidth, constraint=self.target, tau=self.tau)
            t_opt += time.perf_counter() - ts
            sites = sum(int((assign[vi] >= 0).sum()) for vi in range(len(views)))
            level_history.append(energy / max(1, sites))
            on_step(it + 1, level_history[-1])
        stats = {
            "shape": list(shape), "iterations": n_iter, "queries": queries,
            "search_seconds": t_search, "optimise_seconds": t_opt,
            "pca_dims": {v: self.view_index[vi].dims for vi, v in enumerate(views)},
            "patches": {v: int(self.view_index[vi].patches.shape[0]) for vi, v in enumerate(views)},
        }
        return volume, level_history, stats

    def to_arrays(self, volume):
        return {"volume": volume}

    def from_arrays(self, arrays):
        return np.ascontiguousarray(arrays["volume"], dtype=np.float32)

    def array_specs(self, level, shape):
        return {"volume": ArraySpec((*shape, self.channels), np.float32)}
