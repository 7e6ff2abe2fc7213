"""The volume-lh method's side of the shared level loop (:func:`npmrf3d.model.pyramid.run_pyramid`):
a level's state is every voxel's exemplar coordinate; the steps are in
:mod:`npmrf3d.model.volume_appearance`, :mod:`npmrf3d.model.volume_coordinates` and
:mod:`npmrf3d.model.volume_correction`.
"""

from __future__ import annotations

import time

import numpy as np

from ..io.checkpoints import run_key
from .fields import level_frames
from .phases import PhaseControl, phase_footprint, phase_membership
from .pyramid import ArraySpec, Levels
from .volume_appearance import appearance_space, similarity_sets, smoothed, valid_box
from .volume_coordinates import initial_coordinates, jittered, upsample
from .volume_correction import NEIGHBOURHOODS, correction_pass, parzen_pass

__all__ = ["CoordinateLevels"]


class CoordinateLevels(Levels):
    """The coordinate pyramid's side of :func:`npmrf3d.model.pyramid.run_pyramid`: the state of a
    level is every voxel's exemplar coordinate ``(*shape, 3)`` int64. ``config`` is a
    :class:`npmrf3d.methods.volume_lh.VolumeConfig` (its fields are read), ``parzen`` None or
    ``(adaptive, centre_bandwidth)`` as :func:`npmrf3d.methods.volume_lh.run` takes it.

    A level's appearance space samples its PCA voxels from ``rng`` before the level's
    coordinates are drawn, so it is built at the start of :meth:`initial` and :meth:`upsample`
    (:meth:`prepare` draws nothing). The phase control (``balance``) carries over from level to
    level; its prices go into the checkpoint with the coordinates.
    """

    def __init__(self, config, exemplar: np.ndarray, vector_field, parzen):
        self.config, self.exemplar, self.vector_field, self.parzen = config, exemplar, vector_field, parzen
        self.size, self.levels = config.size, config.levels
        self.lo, self.hi = valid_box(exemplar.shape[:3], config.window)
        self.membership = phase_membership(exemplar, self.lo, self.hi) if config.balance else None
        self.control = None if self.membership is None else PhaseControl.start(len(self.membership[1]))
        self.sigma = float(exemplar.astype(np.float64).std()) or 1.0
        inputs = {"volume": exemplar, **({} if vector_field is None else {"vector_field": vector_field})}
        self.key = run_key("volume-lh", config, inputs, parzen=None if parzen is None else list(parzen))

    def prepare(self, level, shape):
        config, membership = self.config, self.membership
        self.level, self.shape, self.h = level, shape, 2 ** level
        self.frames = level_frames(config.vector_field, self.vector_field, config.size, level, config.angle)
        self.phases = None if membership is None else (
            phase_footprint(membership[0], len(membership[1]), self.h), membership[1])

    def _model(self, rng):
        """The level's appearance space and similarity sets (draws the PCA sample from ``rng``)."""
        t0 = time.perf_counter()
        self.feat = appearance_space(self.exemplar, self.level, self.config.window, self.config.pca_dims, rng)
        self.kset = similarity_sets(self.feat, self.lo, self.hi, self.config.k, self.config.exclude)
        self.model_seconds = time.perf_counter() - t0

    def initial(self, shape, rng):
        self._model(rng)
        return initial_coordinates(shape, self.h, self.lo, self.hi, self.config.start, self.config.jitter, rng)

    def upsample(self, coords, rng):
        self._model(rng)
        coords = upsample(coords, self.frames, self.h, self.lo, self.hi)
        uniforms = rng.uniform(-1.0, 1.0, size=self.shape + (3,)).astype(np.float32)
        jitter = self.config.jitter if self.level else self.config.fine_jitter
        return jittered(coords, self.h, jitter, uniforms, self.lo, self.hi)

    def start(self, level, coords):
        return self.config.passes, float("nan")

    def relax(self, level, coords, rng, on_step):
        config, h, lo, hi = self.config, self.h, self.lo, self.hi
        t0 = time.perf_counter()
        history = []
        values = None if self.parzen is None else smoothed(self.exemplar, level)
        for p in range(config.passes):
            if self.parzen is None:
                coords, mean_cost = correction_pass(coords, self.frames, self.feat, self.kset, h, lo, hi,
                                                    NEIGHBOURHOODS[config.neighbourhood],
                                                    usage=config.usage, balance=config.balance,
                                                    phases=self.phases, control=self.control)
            else:
                coords, mean_cost = parzen_pass(coords, self.frames, self.feat, values, self.kset, h, lo, hi,
                                                NEIGHBOURHOODS[config.neighbourhood], config.window,
                                                self.parzen[0], (self.parzen[1] * self.sigma) ** 2)
            history.append(mean_cost)
            on_step(p + 1, mean_cost)
        return coords, history, {"shape": list(self.shape), "spacing": h, "model_seconds": self.model_seconds,
                                 "correction_seconds": time.perf_counter() - t0,
                                 "pca_dims": int(self.feat.shape[3])}

    def to_arrays(self, coords):
        return {"coords": coords, "prices": np.zeros(0) if self.control is None else self.control.to_array()}

    def from_arrays(self, arrays):
        prices = np.asarray(arrays["prices"], dtype=np.float64)
        if self.control is not None and prices.size:
            self.control = PhaseControl.from_array(prices, len(self.membership[1]))
        return np.asarray(arrays["coords"], dtype=np.int64)

    def array_specs(self, level, shape):
        prices = (0,) if self.control is None else self.control.to_array().shape
        return {"coords": ArraySpec((*shape, 3), np.int64, self.lo, self.hi),
                "prices": ArraySpec(prices, np.float64)}
