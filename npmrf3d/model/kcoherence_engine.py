"""The k-coherence engine: Chen & Wang 2010's search and discrete solver, level by level.

The level loop of :mod:`npmrf3d.model.pyramid` runs it through :class:`KCoherenceLevels`; two
methods drive it: Chen–Wang (:mod:`npmrf3d.methods.chen_wang`, its own solver) and the coherent
NP-MRF sampler (:mod:`npmrf3d.methods.npmrf_coherent`, which decides among the candidates by
the NP-MRF likelihood, :class:`CandidateDecision`). The pieces it works with -- per-level
exemplar models, source maps, candidates -- are in :mod:`npmrf3d.model.kcoherence`, the
solver's position and value histograms here (:func:`position_histogram`,
:class:`ValueHistogram`); the compiled search in :mod:`npmrf3d._kernels.kcoherence`, the solver
in :mod:`npmrf3d._kernels.kcoherence_solver`.

A level's state (:class:`CoherentState`) is every voxel's colour and, per view, the exemplar
pixel it was copied from (its *source*). The coarsest level starts from uniformly random
sources, a finer one from the up-sampled sources (``2 * parent + offset``), the colours read
from the sources by :func:`initial_colours`. Each iteration of a level searches every view's
sites (best candidate under the index histogram, then optionally a global search for the worst
matched) and solves every voxel (copy one voted texel under the position and value
histograms). The random numbers, per iteration: one salt per view's search, the solver's voxel
order, and a salt for an annealed decision.

Each level's iterations are a :class:`npmrf3d.model.kcoherence_pass.LevelPass` (search, voxel
order, histogram target, solve, phase control, one method each); the histograms live in
:mod:`npmrf3d.model.kcoherence_histograms`, the ICM schedule (per-voxel temperatures) in
:mod:`npmrf3d.model.kcoherence_icm`.

A ``blockwise`` run's finer levels cut each pass into batches by a hash of the voxels' grid
positions and read, batch by batch, the histograms of a pilot block made once after the levels
that run whole (:meth:`KCoherenceLevels.run_pilot`,
:class:`npmrf3d.model.kcoherence_histograms.PilotHistograms`) instead of their own.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._kernels import kcoherence as _search
from ..io.checkpoints import run_key
from . import kcoherence as coh
from .kcoherence_histograms import (
    PilotHistograms,
    ValueHistogram,
    pack_pilot,
    pilot_length,
    position_histogram,
    unpack_pilot,
    value_counts,
    value_scale,
)
from .connectivity import minority_below
from .features import with_feature
from .kcoherence_icm import IcmSchedule, inherited_mask
from .kcoherence_pass import (
    CANDIDATE_HEURISTICS,
    CANDIDATE_SAMPLERS,
    COHERENT_HEURISTICS,
    KERNEL_TABLE_COLOURS,
    MEDOID_CANDIDATES,
    PER_VIEW_HEURISTICS,
    SOLVE_CHUNK,
    LevelPass,
    active_box,
    kernel_table,
    pack_exemplars,
)
from .neighbourhood import VIEW_AXES
from .phases import PhaseControl, bin_phases
from .pyramid import ArraySpec, Levels, run_pyramid
from .regions import plan_region

__all__ = ["CANDIDATE_HEURISTICS", "CANDIDATE_SAMPLERS", "COHERENT_HEURISTICS", "KERNEL_TABLE_COLOURS",
           "MEDOID_CANDIDATES", "PER_VIEW_HEURISTICS", "SOLVE_CHUNK", "CandidateDecision", "CoherentState",
           "KCoherenceLevels", "PilotHistograms", "ValueHistogram", "active_box", "block_aprons", "initial_colours",
           "kernel_table", "pack_exemplars", "position_histogram", "value_counts", "value_scale"]


@dataclass(frozen=True)
class CandidateDecision:
    """How the solver picks among a voxel's candidates (the texels of its heaviest votes).

    Attributes
    ----------
    heuristic : {"ML_H2b", "ML_H2a", "ML_H1a", "ML_H1b"} or None
        None: the configuration's own solver (Chen–Wang's medoid or mean). A heuristic: per view
        a Parzen estimate of each candidate's colour from the view's votes; ML_H2b and ML_H2a take
        the candidate of the highest product or minimum over views; ML_H1a lets each view pick
        its best candidate and copies the pick of the least confident view; ML_H1b gives the
        voxel the mean of the views' picks (a colour the exemplar generally does not have:
        Urs et al. 2014's averaging artefact). ML_H1a and ML_H1b are ICM only.
    centre_bandwidth : float
        Width of the Parzen estimate's kernel, times the exemplars' standard deviation.
    outlier : float
        Share of the uniform outlier density mixed into each view's estimate.
    temperatures : tuple of tuples of float, optional
        Per level (coarsest first), one temperature per iteration: a heat-bath draw among the
        candidates with probability proportional to ``exp(score / T)``; 0 or None: the highest
        score.
    sampler : {"heat-bath", "metropolis"}
        The annealed draw: the heat-bath step above, or a Metropolis step -- one candidate
        proposed uniformly, accepted if its score is at least the current colour's, else with
        probability ``exp((score_new - score_current) / T)``.
    smoothness : float
        Strength of the smoothness prior on every candidate's score: its colour's agreement with
        the voxel's six face neighbours (:mod:`npmrf3d._kernels.smoothness`; 0 = none). It runs
        on the levels that run whole (every level but a ``blockwise`` run's finer ones).
    attached : bool
        The smoothness prior reads the volume with the minority phase's pieces apart from its
        largest seen as the majority phase (:func:`npmrf3d.model.connectivity.attached_view`):
        it draws the phase towards its network and away from detached pieces.
    """

    heuristic: str | None = None
    centre_bandwidth: float = 0.0
    outlier: float = 0.0
    temperatures: tuple[tuple[float, ...], ...] | None = None
    sampler: str = "heat-bath"
    smoothness: float = 0.0
    attached: bool = False

    def temperature(self, level_index: int, iteration: int) -> float:
        """The temperature of an iteration of the level ``level_index`` (0 = the coarsest)."""
        return 0.0 if self.temperatures is None else float(self.temperatures[level_index][iteration])


@dataclass
class CoherentState:
    """A level of the k-coherence engine: every voxel's colour and, per view, its source pixel;
    with ICM (:mod:`npmrf3d.model.kcoherence_icm`) its temperature and whether it is inherited
    (without: all at 1, none inherited, every voxel re-decided in every iteration)."""

    volume: np.ndarray  # (N1, N2, N3, C) float32
    sources: np.ndarray  # (V, N1, N2, N3) int32 flat pixel indices into each view's exemplar
    widths: list[int]  # each view's exemplar width at this level (the sources' row stride)
    temps: np.ndarray  # (N1, N2, N3) float32 temperatures in [0, 1], 0 = fully trusted
    inherited: np.ndarray  # (N1, N2, N3) bool, the voxels at 2 * parent of a finer level


def initial_colours(src: np.ndarray, exemplars) -> np.ndarray:
    """Colour of every voxel from its sources: among the views' source texels, the one nearest to
    their mean (the views' first on ties).

    One view's up-sampled sources repeat along that view's normal axis (``2 * parent + offset``
    has no offset there), so copying one view's texels would duplicate slices in pairs; taking
    the most central of the views' texels keeps the colours exemplar colours without that.

    Parameters
    ----------
    src : (V, N1, N2, N3) int32 flat sources per view
    exemplars : V arrays (H, W, C)

    Returns
    -------
    (N1, N2, N3, C) float32
    """
    texels = np.stack([ex.reshape(-1, ex.shape[2])[s] for ex, s in zip(exemplars, src)])  # (V, ..., C)
    if len(texels) == 1:
        return np.ascontiguousarray(texels[0], dtype=np.float32)
    out = np.empty(texels.shape[1:], dtype=np.float32)
    channels = texels.shape[-1]
    _search.central_texels(np.ascontiguousarray(texels, dtype=np.float32).reshape(len(texels), -1, channels),
                           out.reshape(-1, channels))
    return out


# --------------------------------------------------------------------------- the level loop's side


def block_aprons(config, icm: IcmSchedule | None = None) -> tuple[int, ...] | None:
    """Per level (0 the finest), a ``blockwise`` configuration's iterations times the reach of
    one iteration (:meth:`KCoherenceLevels.aprons`); None for the levels that run whole with
    every histogram, once for all blocks: the coarsest, and every level of at most
    ``config.whole_voxels`` voxels (with the levels coarser than it). None without ``blockwise``
    or with ICM's per-voxel temperatures (whose stop rule reads the whole level).

    One iteration reaches ``window - 1`` voxels: a site's match reads the window at the site
    (``anchor`` before it, ``window - 1 - anchor`` after) and the neighbours' shifted sources
    one step away, and a voxel is decided by the sites of every window that holds it. A window
    of 2 (anchor 0) reaches one further, to the source one step before the site.

    >>> from npmrf3d.methods.chen_wang import make_chen_wang_config
    >>> block_aprons(make_chen_wang_config(size=32, blockwise=True, whole_voxels=1))
    (9, 20, None)
    >>> block_aprons(make_chen_wang_config(size=512, blockwise=True))
    (9, None, None)
    """
    if not getattr(config, "blockwise", False) or icm is not None:
        return None
    last = config.levels - 1
    reach = [w - 1 + (w < 3) for w in config.window]
    whole = [level == last or int(np.prod([n // 2 ** level for n in config.size])) <= config.whole_voxels
             for level in range(config.levels)]
    return tuple(None if whole[level] else config.iterations[last - level] * reach[last - level]
                 for level in range(config.levels))


def crop_box(array: np.ndarray, index, first: int = 0) -> np.ndarray:
    """``array[np.ix_(*index)]`` on the axes ``first, first + 1, first + 2`` (contiguous), each
    axis whose indices are a run ``i, i + 1, ...`` cut by a slice instead of gathered."""
    out = array
    for axis, idx in enumerate(index, start=first):
        idx = np.asarray(idx)
        if idx.size and np.all(np.diff(idx) == 1):
            out = out[(slice(None),) * axis + (slice(int(idx[0]), int(idx[-1]) + 1),)]
        else:
            out = np.take(out, idx, axis=axis)
    return np.ascontiguousarray(out)


class KCoherenceLevels(Levels):
    """The k-coherence engine's side of :func:`npmrf3d.model.pyramid.run_pyramid`: per level the
    views' exemplar models, random or up-sampled sources, then search + solve iterations.

    Parameters
    ----------
    method : str
        The method's name (part of the checkpoint's identity).
    config : the k-coherence settings
        A :class:`npmrf3d.methods.chen_wang.ChenWangConfig` (the fields it reads: ``size``,
        ``levels``, ``views``, ``window``, ``iterations``, ``k``, ``pca_dims``, ``r``, ``grid``,
        the histogram weights, ``coherence_exclude``, ``random_candidates``, ``global_share``,
        ``coherence_bias``, ``value_*``, ``phase_weight``, ``batches``, ``solver``,
        ``balance_views``).
    per_view_exemplars : dict view -> (H, W, C) float32
    decision : CandidateDecision
        The solver's rule (default: the configuration's own solver).
    icm : IcmSchedule, optional
        ICM with per-voxel temperatures (:mod:`npmrf3d.model.kcoherence_icm`) instead of the
        configuration's ``iterations``: sweeps until the stop rule, trusted search and votes,
        and its up-sampling.
    feature : float
        Above 0: every exemplar gets the feature-distance channel of
        :func:`npmrf3d.model.features.with_feature` of this weight, which the search and the
        decision read as a colour; :meth:`colours` takes it off the volume.

    The phase control (``phase_weight``) carries over from level to level; its state goes into
    the checkpoint with the level's.
    """

    def __init__(self, method: str, config: Any, per_view_exemplars: Mapping[str, np.ndarray],
                 decision: CandidateDecision = CandidateDecision(), icm: IcmSchedule | None = None,
                 feature: float = 0.0):
        self.config, self.decision, self.icm = config, decision, icm
        self.size, self.levels = config.size, config.levels
        views = self.views = config.views
        given = {v: np.ascontiguousarray(per_view_exemplars[v], dtype=np.float32) for v in views}
        self.colour_channels = next(iter(given.values())).shape[2]
        self.labels = np.unique(np.concatenate([a.reshape(-1, self.colour_channels) for a in
                                                {id(a): a for a in given.values()}.values()]),
                                axis=0).astype(np.float32)
        if feature > 0.0:
            featured = {id(a): with_feature(a, feature) for a in given.values()}
            given = {v: featured[id(a)] for v, a in given.items()}
        self.per_view = given
        self.distinct = list({id(a): a for a in self.per_view.values()}.values())
        channels = self.distinct[0].shape[2]
        pooled = np.concatenate([a.reshape(-1, channels) for a in self.distinct])
        self.sigma = float(pooled.astype(np.float64).std()) or 1.0
        self.value_lo = pooled.min(axis=0).astype(np.float64)
        self.value_span = pooled.max(axis=0).astype(np.float64) - self.value_lo
        self.view_axes = np.array([VIEW_AXES[v] for v in views], dtype=np.int64)
        #: with ``decision.attached``: whether the exemplars' minority phase lies below the middle of their values
        self.minority_below = decision.attached and minority_below(self.distinct, self.value_lo, self.value_span)
        self.key = run_key(method, config, self.per_view, decision=dataclasses.asdict(decision),
                           **({} if icm is None else {"icm": dataclasses.asdict(icm)}),
                           **({"feature": float(feature)} if feature > 0.0 else {}))
        self.phases = self.control = None
        if config.phase_weight > 0.0 and config.value_prior > 0.0:
            self.phases = bin_phases(value_counts(
                pooled, self.value_lo, value_scale(self.value_span, config.value_bins), config.value_bins)[1])
            self.control = [PhaseControl.start(2) for _ in range(channels)]
        self.level_ex = self.vmodels = None
        self.blockwise = bool(getattr(config, "blockwise", False))
        #: blockwise: the pilot's histograms of every finer level (:class:`PilotHistograms`)
        self.pilot: dict[int, PilotHistograms] | None = None
        #: while this engine *is* the pilot: the records it is making, by level
        self.recording: dict[int, PilotHistograms] | None = None
        #: blockwise: the finest level that runs whole, with every histogram
        aprons = block_aprons(config, icm)
        self.lowest_whole = config.levels - 1 if aprons is None else aprons.index(None)

    def colours(self, volume: np.ndarray) -> np.ndarray:
        """The volume's colour channels (without the feature channel, if any)."""
        return volume if volume.shape[3] == self.colour_channels else \
            np.ascontiguousarray(volume[..., :self.colour_channels])

    def aprons(self):
        """With ``blockwise`` (the pilot's histograms, random numbers hashed from grid positions)
        and fixed iterations, per level (0 the finest) its iterations times its window: a voxel
        after one search and solve depends on voxels at most ``window - 1`` away (the search
        reads a window around each site, the solve the sites of every window that holds the
        voxel), plus one for the neighbours' shifted sources. None otherwise."""
        return block_aprons(self.config, self.icm)

    def _exemplar_shape(self, view: str, level: int) -> tuple[int, int]:
        """The view's exemplar's (H, W) at ``level`` (:func:`npmrf3d.model.kcoherence.downsample_exemplar`)."""
        f = 2 ** level
        return self.per_view[view].shape[0] // f, self.per_view[view].shape[1] // f

    def after_level(self, level, state, rng):
        """``blockwise``: after the finest level that runs whole, the pilot (:meth:`run_pilot`),
        unless a checkpoint already held its records."""
        if self.blockwise and level == self.lowest_whole and level > 0 and self.recording is None \
                and self.pilot is None:
            self.pilot = self.run_pilot(state, rng)

    def run_pilot(self, state, rng) -> dict[int, PilotHistograms]:
        """The records of the finer levels' pilot: the dependency cone of the block of side
        ``config.pilot`` at the grid's first corner, made from the finished whole ``state``
        with its histograms live (a copy of this engine, of ``rng`` and of the phase control, so
        the run itself goes on as if the pilot had not been made)."""
        pilot = copy.copy(self)
        pilot.recording, pilot.pilot = {}, None
        pilot.control = copy.deepcopy(self.control)
        side = tuple(min(int(self.config.pilot), n) for n in self.size)
        plan = plan_region(self.size, self.levels, self.aprons(), (0, 0, 0), side)
        run_pyramid(pilot, copy.deepcopy(rng), region=plan, after=(self.lowest_whole, state))
        return pilot.recording

    def _pilot_layout(self):
        """Per finer level of a ``blockwise`` run, the shape of its pilot record: (level,
        iterations, batches, position bins, channels, value bins)."""
        config, channels = self.config, self.distinct[0].shape[2]
        return [(level, config.iterations[config.levels - 1 - level], config.batches,
                 sum(h * w for h, w in (self._exemplar_shape(v, level) for v in self.views)), channels,
                 config.value_bins) for level in range(self.lowest_whole - 1, -1, -1)]

    def crop(self, state, index):
        return CoherentState(crop_box(state.volume, index), crop_box(state.sources, index, first=1), state.widths,
                             crop_box(state.temps, index), crop_box(state.inherited, index))

    def _grid(self):
        """The current frame's origin and extent as the kernels take them."""
        return np.array(self.frame.origin, dtype=np.int64), np.array(self.frame.extent, dtype=np.int64)

    def prepare(self, level, shape):
        window = self.config.window[self.config.levels - 1 - level]
        self.level_ex = {id(a): coh.downsample_exemplar(a, level) for a in self.distinct}
        models = {key: coh.build_level_model(ex, window, dims=self.config.pca_dims, k=self.config.k,
                                             exclude=self.config.coherence_exclude)
                  for key, ex in self.level_ex.items()}
        self.vmodels = [models[id(self.per_view[v])] for v in self.views]

    def initial(self, shape, rng):
        src = np.empty((len(self.views), *shape), dtype=np.int32)
        drawn = {key: coh.random_sources(shape, ex.shape, rng) for key, ex in self.level_ex.items()}
        for vi, v in enumerate(self.views):
            src[vi] = drawn[id(self.per_view[v])]
        return self._state(src)

    def upsample(self, state, rng):
        src = np.stack([coh.upsample_sources(state.sources[vi], v, state.widths[vi], self.vmodels[vi].exemplar.shape)
                        for vi, v in enumerate(self.views)])
        if self.icm is None:
            return self._state(src)
        inherited = inherited_mask(src.shape[1:])
        if self.icm.upsample == "1/8":
            drawn = self.initial(src.shape[1:], rng).sources
            src = np.where(inherited, src, drawn)
        return self._state(src, np.where(inherited, 0.0, 1.0).astype(np.float32), inherited)

    def _state(self, src, temps=None, inherited=None):
        shape = src.shape[1:]
        return CoherentState(initial_colours(src, [m.exemplar for m in self.vmodels]), src,
                             [m.exemplar.shape[1] for m in self.vmodels],
                             np.ones(shape, dtype=np.float32) if temps is None else temps,
                             np.zeros(shape, dtype=bool) if inherited is None else inherited)

    def start(self, level, state):
        if self.icm is not None:
            return self.icm.max_sweeps, float("nan")
        return self.config.iterations[self.config.levels - 1 - level], float("nan")

    def relax(self, level, state, rng, on_step):
        history, stats = LevelPass(self, level, state).run(rng, on_step)
        return state, history, stats

    def to_arrays(self, state):
        control = {} if self.control is None else {"phase_control": np.stack([c.to_array() for c in self.control])}
        if self.blockwise:
            control["pilot"] = pack_pilot(self.pilot, self._pilot_layout())
        return {"volume": state.volume, "sources": state.sources,
                "widths": np.asarray(state.widths, dtype=np.int64), "temps": state.temps,
                "inherited": state.inherited, **control}

    def from_arrays(self, arrays):
        if self.control is not None and "phase_control" in arrays:
            self.control = [PhaseControl.from_array(a, 2)
                            for a in np.asarray(arrays["phase_control"], dtype=np.float64)]
        if self.blockwise and "pilot" in arrays:
            self.pilot = unpack_pilot(np.asarray(arrays["pilot"]), self._pilot_layout())
        volume = np.ascontiguousarray(arrays["volume"], dtype=np.float32)
        temps = arrays["temps"] if "temps" in arrays else np.ones(volume.shape[:3])  # no ICM: all hot
        inherited = arrays["inherited"] if "inherited" in arrays else np.zeros(volume.shape[:3])
        return CoherentState(volume, np.ascontiguousarray(arrays["sources"], dtype=np.int32),
                             [int(w) for w in np.atleast_1d(arrays["widths"])],
                             np.ascontiguousarray(temps, dtype=np.float32), np.asarray(inherited, dtype=bool))

    def array_specs(self, level, shape):
        f = 2 ** level  # each view's exemplar at this level (coh.downsample_exemplar)
        heights = np.array([self.per_view[v].shape[0] // f for v in self.views], dtype=np.int64)
        widths = np.array([self.per_view[v].shape[1] // f for v in self.views], dtype=np.int64)
        last = (heights * widths - 1).reshape(-1, 1, 1, 1)
        specs = {"volume": ArraySpec((*shape, self.distinct[0].shape[2]), np.float32),
                 "sources": ArraySpec((len(self.views), *shape), np.int32, 0, last),
                 "widths": ArraySpec((len(self.views),), np.int64, widths, widths),
                 "temps": ArraySpec(shape, np.float32, 0.0, 1.0), "inherited": ArraySpec(shape, np.bool_)}
        if self.control is not None:
            specs["phase_control"] = ArraySpec(np.stack([c.to_array() for c in self.control]).shape,
                                               np.float64)
        if self.blockwise:  # made after the coarsest level, kept with every level
            made = level <= self.lowest_whole  # the pilot follows the finest whole level
            specs["pilot"] = ArraySpec((pilot_length(self._pilot_layout()) if made else 0,), np.float64)
        return specs
