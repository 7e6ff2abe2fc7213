"""One level's search and solve passes of the k-coherence engine (:class:`LevelPass`).

:class:`npmrf3d.model.kcoherence_engine.KCoherenceLevels` relaxes each level through a
:class:`LevelPass`: every iteration searches every view's sites (:meth:`LevelPass.search`, then
optionally :meth:`LevelPass.global_matches` for the worst matched), orders the voxels
(:meth:`LevelPass.voxel_order`), sets the value histogram's target (:meth:`LevelPass.value_target`,
the phase control's or the pilot's) and solves every voxel (:meth:`LevelPass.solve`: the whole
level at once, or batch by batch with the pilot's histograms, :meth:`LevelPass.batch_histograms`),
then steps the phase control (:meth:`LevelPass.phase_step`). Each step is a method of its own, so
each path -- a whole level with fixed iterations, ICM with per-voxel temperatures, a block
reading its pilot's histograms, global matches, the phase control -- can be run and tested alone.

The random numbers, per iteration and in this order: one salt per view's search, the voxel order
(a permutation, or a salt for a block's hashed batches), and a salt for an annealed decision.

Also here, what the passes are made of: the decision codes of the solver kernel, the packed
exemplars (:func:`pack_exemplars`), the NP-MRF rule's kernel table (:func:`kernel_table`), a
block's shrinking box (:func:`active_box`) and its hashed batches (:func:`hashed_batches`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from .._kernels import candidate_decision as _decide
from .._kernels import kcoherence as _search
from .._kernels import kcoherence_solver as _solver
from . import kcoherence as coh
from .connectivity import attached_view
from .exemplar import pack_rows
from .kcoherence_histograms import PilotHistograms, ValueHistogram, position_histogram
from .kcoherence_icm import IcmLevel
from .neighbourhood import VIEW_AXES
from .phases import bin_phase_error, phase_prior_target

__all__ = ["CANDIDATE_HEURISTICS", "CANDIDATE_SAMPLERS", "COHERENT_HEURISTICS", "KERNEL_TABLE_COLOURS",
           "LevelPass", "MEDOID_CANDIDATES", "PER_VIEW_HEURISTICS", "SOLVE_CHUNK", "active_box", "hashed_batches",
           "kernel_table", "pack_exemplars"]

#: The NP-MRF heuristics with an objective, which rank candidates by a score and can be
#: annealed (docs/model.md, section 3), and the solver kernel's code of each
#: (:mod:`npmrf3d._kernels.candidate_decision`).
CANDIDATE_HEURISTICS = {"ML_H2b": _decide.ML_H2B, "ML_H2a": _decide.ML_H2A}
#: Urs et al. 2014's per-view argmax heuristics over the candidates: no objective, ICM only.
PER_VIEW_HEURISTICS = {"ML_H1a": _decide.ML_H1A, "ML_H1b": _decide.ML_H1B}
#: Every heuristic the solver decides among candidates by.
COHERENT_HEURISTICS = {**CANDIDATE_HEURISTICS, **PER_VIEW_HEURISTICS}
#: The annealed draws among the candidates, and the solver kernel's code of each.
CANDIDATE_SAMPLERS = {"heat-bath": _decide.HEAT_BATH, "metropolis": _decide.METROPOLIS}
#: The medoid solver tries the texels of the heaviest votes only; the energy sums over all votes.
MEDOID_CANDIDATES = 8
#: Voxels per parallel work item of the solver (any value gives the same result).
SOLVE_CHUNK = 512
#: The most distinct colours of a level's exemplars for which the NP-MRF rule's kernel is looked
#: up in a table (n * n float64, 8 MiB at 1024) instead of computed per vote (:func:`kernel_table`).
KERNEL_TABLE_COLOURS = 1024


def kernel_table(ex_flat: np.ndarray, h2c: float, most: int = KERNEL_TABLE_COLOURS) -> tuple[np.ndarray, np.ndarray]:
    """The NP-MRF rule's kernel between the distinct colours of the packed texels ``ex_flat``
    (:func:`npmrf3d._kernels.candidate_decision.kernel_table`) and every texel's colour index:
    ``(G,)`` int64 and ``(n, n)`` float64; both empty when there are more than ``most`` colours
    (the solver then computes the kernel per vote, with the same result)."""
    _, reps, ids = np.unique(ex_flat, axis=0, return_index=True, return_inverse=True)
    if len(reps) > most:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 0), dtype=np.float64)
    table = np.empty((len(reps), len(reps)), dtype=np.float64)
    _decide.kernel_table(ex_flat, reps.astype(np.int64), float(h2c), table)
    return np.ascontiguousarray(ids.reshape(-1), dtype=np.int64), table


def pack_exemplars(models) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The views' exemplars packed as rows of one array (an exemplar shared by views once,
    :func:`npmrf3d.model.exemplar.pack_rows`), each view's first row in it, and each view's first
    entry in the packed position histograms."""
    texels, offsets = pack_rows([m.exemplar for m in models])
    pixels = np.array([m.pixels for m in models], dtype=np.int64)
    return texels, offsets, np.cumsum(pixels) - pixels


def active_box(frame, window: int, iteration: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The part of a block's region that pass ``iteration`` (1 for the first) of a level must get
    exact (:func:`npmrf3d.model.kcoherence_engine.block_aprons`): the region shrunk by
    ``iteration`` reaches of one pass along every axis it does not wrap whole. Returns the sites to
    search, ``search_lo <= index < search_hi`` per axis (the voxels' box grown by one reach: every
    site whose votes the voxels take), and the voxels to decide, ``lo <= index < hi``.

    The region starts exact (up-sampled from the coarser level's exact core), and a voxel after
    one pass depends on voxels at most a reach away, so pass ``t`` is exact on the region shrunk
    by ``t`` reaches from exact inputs alone; the last pass's box still holds the block (the
    region is the block grown by the level's apron, iterations times the reach).

    >>> from npmrf3d.model.regions import Frame
    >>> box = active_box(Frame((0, 0, 0), (40, 64, 40), (128, 64, 128)), 7, 2)
    >>> [b.tolist() for b in box]
    [[6, 0, 6], [34, 64, 34], [12, 0, 12], [28, 64, 28]]
    """
    reach = window - 1 + (window < 3)
    shape = np.array(frame.shape, dtype=np.int64)
    whole = np.array([n == e for n, e in zip(frame.shape, frame.extent)])
    shrink = np.where(whole, 0, np.minimum(iteration * reach, shape // 2))
    lo, hi = shrink, shape - shrink
    grow = np.where(whole, 0, reach)
    return np.maximum(lo - grow, 0), np.minimum(hi + grow, shape), lo, hi


def hashed_batches(shape, origin, extent, salt, batches, lo, hi):
    """A block-local pass's voxel order and batch bounds: the voxels of the box ``lo <= p <
    hi`` of each batch (:func:`npmrf3d._kernels.kcoherence.voxel_batches`, a hash of their
    grid positions) in memory order, batch after batch."""
    ids = np.empty(shape, dtype=np.int16)
    _search.voxel_batches(np.array(shape, dtype=np.int64), origin, extent, salt, batches, lo, hi, ids)
    order = np.empty(int(np.prod(hi - lo)), dtype=np.int64)
    bounds = np.empty(batches + 1, dtype=np.int64)
    _search.group_by_batch(ids.ravel(), batches, order, bounds)
    return order, bounds


def _salt(rng: np.random.Generator) -> int:
    return int(rng.integers(0, 2**31))


class LevelPass:
    """One level of :class:`npmrf3d.model.kcoherence_engine.KCoherenceLevels` (``engine``, after
    its ``prepare`` for ``level``) relaxed from ``state``, whose volume and sources it updates in
    place: :meth:`run` does every iteration, :meth:`iterate` one.

    Three kinds of level: a whole level (every voxel, its own histograms); with ``blockwise``
    below the finest whole level, a *local* one, batches hashed from grid positions and no index
    histogram, either the pilot's (``record``: its histograms live and kept batch by batch) or a
    block's (``replay``: it reads the pilot's before each batch, and decides at each pass only the
    voxels the next pass still needs exact, :func:`active_box`).
    """

    def __init__(self, engine, level: int, state):
        config, vmodels = engine.config, engine.vmodels
        self.engine, self.config, self.state, self.vmodels = engine, config, state, vmodels
        self.li = config.levels - 1 - level
        self.window = config.window[self.li]
        self.shape = shape = state.volume.shape[:3]
        self.n_vox = shape[0] * shape[1] * shape[2]
        self.local = engine.blockwise and level < engine.lowest_whole
        self.replay = engine.pilot[level] if self.local and engine.recording is None else None
        self.record = None
        if self.local and self.replay is None:
            layout = {lev: shape_of for lev, *shape_of in engine._pilot_layout()}
            self.record = engine.recording[level] = PilotHistograms.empty(*layout[level])
        self.grid_voxels = float(np.prod(engine.frame.extent if self.replay is not None else shape))
        self.origin, self.extent = (engine._grid() if self.local
                                    else (np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64)))
        self.icm = None if engine.icm is None else IcmLevel(engine.icm, state.temps, state.inherited,
                                                             engine.view_axes, self.window, int(vmodels[0].anchor))
        self.n_iter = config.iterations[self.li] if self.icm is None else engine.icm.max_sweeps
        self.shrinking = (self.replay is not None and config.global_share == 0.0
                          and engine.frame.shape != engine.frame.extent)
        self.batches = config.batches if self.local else min(config.batches, self.n_vox)
        self.bounds = np.linspace(0, self.n_vox, self.batches + 1).astype(np.int64)
        self.floor = 1e-3 * engine.sigma * math.sqrt(self.window * self.window * state.volume.shape[3])
        self._search_inputs()
        self._solver_inputs()
        self.history, self.changed, self.global_counts = [], [], []
        self.t_search = self.t_solve = 0.0
        self.sites = self.decided = 0

    def _search_inputs(self):
        shape, n_views = self.shape, len(self.vmodels)
        self.exemplars = [coh.search_exemplar(m) for m in self.vmodels]
        self.assign = np.full((n_views, *shape), -1, dtype=np.int32)
        self.fresh = np.empty(shape, dtype=np.int32)
        self.omega = np.zeros((n_views, *shape), dtype=np.float32)
        self.index_hist = [np.zeros(m.pixels, dtype=np.float64) for m in self.vmodels]
        self.index_weight = 0.0 if self.local else self.config.index_weight

    def _solver_inputs(self):
        engine, config, vmodels, decision = self.engine, self.config, self.vmodels, self.engine.decision
        volume, src = self.state.volume, self.state.sources
        ex_flat, ex_off, hist_off = pack_exemplars(vmodels)
        values = ValueHistogram.build([m.exemplar for m in vmodels], ex_flat, volume,
                                      bins=config.value_bins, lo=engine.value_lo, span=engine.value_span)
        self.values = values if self.replay is None else values._replace(unit=self.grid_voxels / config.value_bins)
        self.packed = _solver.PackedViews(engine.view_axes, ex_flat, ex_off,
                                          np.array(self.state.widths, dtype=np.int64), self.window,
                                          int(vmodels[0].anchor), config.grid)
        # a block reads the pilot's position histograms before each batch
        positions = np.zeros(sum(m.pixels for m in vmodels)) if self.replay is not None else np.concatenate(
            [position_histogram(src[vi], m.pixels) for vi, m in enumerate(vmodels)])
        theta = np.array([self.grid_voxels / m.pixels for m in vmodels])
        values = self.values
        self.histograms = _solver.SolverHistograms(
            positions, hist_off, theta, config.position_weight, config.position_boost, values.ex_bins,
            values.hist, values.target, config.value_weight, config.value_prior, values.lo, values.scale,
            values.unit, follow=self.replay is None)
        self.likelihood = (_decide.OWN_SOLVER if decision.heuristic is None
                           else COHERENT_HEURISTICS[decision.heuristic])
        self.medoid = MEDOID_CANDIDATES if config.solver == "medoid" or decision.heuristic is not None else 0
        self.h2c = 2.0 * (decision.centre_bandwidth * engine.sigma) ** 2 or 1.0
        self.colour_ids, self.kernel = (kernel_table(ex_flat, self.h2c) if self.likelihood != _decide.OWN_SOLVER
                                        else (np.zeros(0, dtype=np.int64), np.zeros((0, 0), dtype=np.float64)))

    # ------------------------------------------------------------------ the iterations

    def run(self, rng: np.random.Generator, on_step):
        """Every iteration (fixed, or ICM's sweeps until its stop rule), ``on_step`` after each;
        ``(history, stats)`` of the level."""
        it = 0
        while it < self.n_iter if self.icm is None else self.icm.warm(it):
            self.iterate(rng, it)
            it += 1
            if self.icm is None:
                on_step(it, self.history[-1])
            else:
                self.icm.cool()
                on_step(it, self.history[-1], self.icm.expected() if self.icm.warm(it) else it)
        return self.history, self.stats(it)

    def iterate(self, rng: np.random.Generator, it: int) -> None:
        """Iteration ``it`` (0 first): search, order, target, solve, phase control; the mean
        energy of its matches goes to ``history``."""
        ts = time.perf_counter()
        box_lo, box_hi, decide_lo, decide_hi = self.boxes(it)
        energy, self.sites, n_global = self.search(rng, box_lo, box_hi)
        self.global_counts.append(n_global)
        self.t_search += time.perf_counter() - ts
        ts = time.perf_counter()
        order, bounds = self.voxel_order(rng, decide_lo, decide_hi)
        target = self.value_target(it)
        rule = self.solver_rule(rng, it)
        self.histograms = self.histograms._replace(value_target=target)
        self.changed.append(self.solve(order, bounds, rule, it))
        self.t_solve += time.perf_counter() - ts
        self.phase_step()
        self.history.append(energy / max(1, self.sites))

    def boxes(self, it: int):
        """The sites to search and the voxels to decide in iteration ``it`` (:func:`active_box`
        for a shrinking block; else every site and every voxel)."""
        if self.shrinking:
            return active_box(self.engine.frame, self.window, it + 1)
        lo, hi = np.zeros(3, dtype=np.int64), np.array(self.shape, dtype=np.int64)
        return lo, hi, lo, hi

    def search(self, rng, box_lo, box_hi) -> tuple[float, int, int]:
        """Every view's search of the sites in the box, then its global matches when
        ``global_share`` asks for them: the energy summed, the sites searched, the global matches."""
        trust = _search.NO_TRUST if self.icm is None else self.icm.search_trust()
        energy_sum, sites, n_global = 0.0, 0, 0
        for vi in range(len(self.vmodels)):
            energy, n_sites, phi = self.search_view(rng, vi, box_lo, box_hi, trust)
            energy_sum += energy
            if self.config.global_share > 0.0:
                count, change = self.global_matches(vi, phi)
                energy_sum += change
                n_global += count
            sites += n_sites
        return energy_sum, sites, n_global

    def search_view(self, rng, vi: int, box_lo, box_hi, trust) -> tuple[float, int, float]:
        """View ``vi``'s search (:func:`npmrf3d._kernels.kcoherence.search_view`): its energy, its
        sites and ``phi``, their share of the view's exemplar centres (the index histogram's; a
        block's pass has no index histogram, so phi then matters to nothing)."""
        config, m, shape = self.config, self.vmodels[vi], self.shape
        ra, ca = VIEW_AXES[self.engine.views[vi]]
        na = 3 - ra - ca
        energy = np.zeros(shape[na], dtype=np.float64)
        n_sites = int(box_hi[na] - box_lo[na])
        for axis in (ra, ca):
            first = _search.first_site(self.origin, self.extent, axis, config.grid)
            lo, hi = _search.lattice_span(box_lo[axis], box_hi[axis], first, config.grid,
                                           len(range(first, shape[axis], config.grid)))
            n_sites *= max(0, hi - lo)
        phi = n_sites / m.centres
        rule = _search.SearchRule(config.grid, min(config.batches, shape[na]), phi, self.index_weight,
                                  config.r, self.floor, config.random_candidates, _salt(rng),
                                  self.origin, self.extent, box_lo, box_hi,
                                  follow=self.index_weight > 0.0 or config.global_share > 0.0)
        _search.search_view(self.state.volume, self.state.sources[vi], ra, ca, self.exemplars[vi], rule,
                            self.index_hist[vi], self.assign[vi], self.fresh, self.omega[vi], energy, trust)
        return float(energy.sum()), n_sites, phi

    def global_matches(self, vi: int, phi: float) -> tuple[int, float]:
        """View ``vi``'s global search for its worst matched sites
        (:func:`npmrf3d.model.kcoherence.global_matches`): the sites re-matched, the energy change."""
        config = self.config
        return coh.global_matches(self.state.volume, self.engine.views[vi], self.vmodels[vi], self.assign[vi],
                                  self.omega[vi], self.index_hist[vi], share=config.global_share,
                                  bias=config.coherence_bias, phi=phi, index_weight=config.index_weight,
                                  r=config.r, floor=self.floor)

    def voxel_order(self, rng, decide_lo, decide_hi) -> tuple[np.ndarray, np.ndarray]:
        """The voxels this iteration decides and its batch bounds: a local pass's hashed batches
        (in memory order), else a random permutation sorted within each batch (the histograms are
        frozen within a batch, so memory order gives the same volume faster); ICM keeps the warm
        voxels only."""
        if self.local:
            order, bounds = hashed_batches(self.shape, self.origin, self.extent, _salt(rng), self.batches,
                                           decide_lo, decide_hi)
        else:
            order, bounds = rng.permutation(self.n_vox).astype(np.int64), self.bounds
        if self.icm is not None:
            order = self.icm.visit(order)
            bounds = np.linspace(0, len(order), min(self.config.batches, len(order)) + 1).astype(np.int64)
        if not self.local:
            _search.sort_within_batches(order, bounds, self.n_vox)
        return order, bounds

    def value_target(self, it: int) -> np.ndarray:
        """The value histogram's target in iteration ``it``: a block's, the pilot's; else the
        exemplars', moved by the phase control when it runs (the pilot records it)."""
        engine = self.engine
        if self.replay is not None:
            target = self.replay.targets[it]
        elif engine.control is None:
            target = self.values.target
        else:
            costs = np.stack([c.phase_costs(self.config.phase_weight) for c in engine.control])
            target = phase_prior_target(self.values.target, engine.phases, costs, self.config.value_prior)
        if self.record is not None:
            self.record.targets[it] = target
        return target

    def solver_rule(self, rng, it: int) -> _solver.SolverRule:
        """The solver's rule in iteration ``it``: the decision's temperature, and a salt when it
        anneals; on a whole level, the smoothness prior with the volume as it is now."""
        engine = self.engine
        decision = engine.decision
        temperature = decision.temperature(self.li, it)
        salt = _salt(rng) if temperature > 0.0 else 0
        smooth = {} if decision.smoothness == 0.0 or self.local else {
            "smoothness": decision.smoothness, "previous": self.previous(),
            "inv_span": 1.0 / np.where(engine.value_span > 0, engine.value_span, 1.0)}
        return _solver.SolverRule(self.medoid, self.config.balance_views, self.likelihood, self.h2c, decision.outlier,
                                  temperature, salt, CANDIDATE_SAMPLERS[decision.sampler], self.origin, self.extent,
                                  self.colour_ids, self.kernel, **smooth)

    def previous(self) -> np.ndarray:
        """The volume the smoothness prior reads: a copy of the level's as it is now, with the
        minority phase's detached pieces seen as the majority phase when the decision asks
        (:func:`npmrf3d.model.connectivity.attached_view`)."""
        engine, volume = self.engine, self.state.volume
        if engine.decision.attached:
            return attached_view(volume, engine.value_lo, engine.value_span, engine.minority_below)
        return volume.copy()

    def solve(self, order, bounds, rule, it: int) -> int:
        """Decide the voxels of ``order`` (:func:`npmrf3d._kernels.kcoherence_solver.solve`): a
        whole level at once, a local one batch by batch (:meth:`batch_histograms` before each);
        the voxels changed."""
        trust = _solver.NO_TRUST if self.icm is None else self.icm.vote_trust()
        if not self.local:
            self.decided += len(order)
            return self._solve(order, bounds, rule, trust)
        changed = 0
        for b in range(self.batches):
            self.batch_histograms(it, b)
            part = order[bounds[b]:bounds[b + 1]]
            self.decided += len(part)
            changed += self._solve(part, np.array([0, len(part)], dtype=np.int64), rule, trust)
        return changed

    def _solve(self, order, bounds, rule, trust) -> int:
        state = self.state
        return int(_solver.solve(state.volume, state.sources, self.assign, self.omega, self.packed, self.histograms,
                                 trust, rule, order, bounds, SOLVE_CHUNK))

    def batch_histograms(self, it: int, batch: int) -> None:
        """Before batch ``batch`` of iteration ``it`` of a local pass: the pilot records its
        position and value histograms, a block takes the pilot's in place of its own."""
        h = self.histograms
        if self.replay is None:
            self.record.positions[it, batch] = h.positions / self.grid_voxels
            self.record.values[it, batch] = h.values
        else:
            h.positions[:] = self.replay.positions[it, batch] * self.grid_voxels
            h.values[:] = self.replay.values[it, batch]

    def phase_step(self) -> None:
        """One step of the phase control from the volume's phase shares (not in a block, which
        reads the pilot's targets)."""
        engine = self.engine
        if engine.control is not None and self.replay is None:
            for c, e in zip(engine.control, bin_phase_error(self.values.hist, self.values.target, engine.phases)):
                c.step(e)

    def stats(self, iterations: int) -> dict:
        """The level's statistics after ``iterations`` iterations."""
        config, views, vmodels, src = self.config, self.engine.views, self.vmodels, self.state.sources
        # a block's share of the exemplar says nothing of the volume's: not counted
        used = [None if self.replay is not None else float((position_histogram(src[vi], m.pixels) > 0).mean())
                for vi, m in enumerate(vmodels)]
        stats = {
            "shape": list(self.shape), "window": self.window, "grid": config.grid, "iterations": iterations,
            "candidates_per_site": 9 * (1 + config.k) + config.random_candidates, "sites_per_iteration": self.sites,
            "voxels_decided": self.decided,
            "pca_dims": {v: int(vmodels[vi].basis.shape[1]) for vi, v in enumerate(views)},
            "centres": {v: int(vmodels[vi].centres) for vi, v in enumerate(views)},
            "search_seconds": self.t_search, "solve_seconds": self.t_solve, "changed": self.changed,
            "global_matches": self.global_counts,
            "exemplar_pixels_used": {v: used[vi] for vi, v in enumerate(views)},
        }
        if self.icm is not None:
            stats["temperature"], stats["updates"] = self.icm.history, self.icm.updates
        if self.engine.control is not None:
            stats["phase_error"] = [c.last_error.tolist() for c in self.engine.control]
            stats["phase_gain"] = [c.gain for c in self.engine.control]
        return stats
