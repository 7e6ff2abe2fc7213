"""ICM with per-voxel temperatures over coherent candidates (Urs et al. 2014, docs/model.md
sections 4 and 7), the k-coherence engine's alternative to a fixed number of iterations.

Every voxel has a temperature ``t`` in [0, 1] (0: fully trusted). A level runs sweeps of the
engine's search and decision (:class:`npmrf3d.model.kcoherence_engine.KCoherenceLevels`) with:

* **trust in the search**: a neighbourhood's distance to a candidate is the full-dimensional
  one with every pixel's term weighted by its trust ``1 - t`` (the PCA space has no per-pixel
  weights; :func:`npmrf3d._kernels.kcoherence.search_view`);
* **trust in the votes**: a neighbourhood votes with its weight times the mean trust of its
  pixels other than the voxel decided (:func:`npmrf3d._kernels.kcoherence_solver._votes`;
  the window sums by :func:`window_trust`);
* **visiting**: only warm voxels (``t > 0``) are re-decided, and the inherited ones with
  ``resynth`` (:meth:`IcmLevel.visit`);
* **cooling**: after the decisions every visited voxel that is not inherited cools to
  ``max(0, (xi + sum_{r in N_s} t_r) / |N_s|)`` over its **6 face neighbours** ``N_s``, all
  from the temperatures at the end of the sweep's decisions (a Jacobi step: the result depends
  on no visiting order or thread count) (:func:`cool`). The paper's ``N_s`` is the union of the
  views' windows; with ~3 w^2 neighbours a level that starts all hot cools by ``|xi| / (3 w^2)``
  per Jacobi sweep (0.7 % for ``w = 7``, ``xi = -1``), which ``max_sweeps`` would cut short.

A level stops when the global temperature ``sum_s t_s`` has fallen by the fraction ``stop`` of
its first value (or reached 0), or after ``max_sweeps`` sweeps. A finer level's inherited voxels
(at ``2 * parent``) keep the parent's source at temperature 0; the other 7 children copy the
parent's shifted source (``8/8``) or get random ones (``1/8``), at temperature 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._kernels import kcoherence_solver as _solver
from .relax.icm import expected_sweeps

__all__ = ["FACE_NEIGHBOURS", "IcmLevel", "IcmSchedule", "cool", "inherited_mask", "visit_mask", "window_trust"]

#: |N_s| of the cooling rule: the 6 face neighbours.
FACE_NEIGHBOURS = 6


@dataclass(frozen=True)
class IcmSchedule:
    """The ICM options of the coherent sampler (validated by
    :func:`npmrf3d.methods.npmrf_coherent.make_coherent_config`)."""

    xi: float = -1.0
    stop: float = 0.95
    max_sweeps: int = 30
    upsample: str = "8/8"
    inherit: str = "resynth"


def inherited_mask(shape) -> np.ndarray:
    """The inherited voxels of a finer level (even indices along all three axes)."""
    mask = np.zeros(shape, dtype=bool)
    mask[::2, ::2, ::2] = True
    return mask


def visit_mask(temps: np.ndarray, inherited: np.ndarray, resynth: bool) -> np.ndarray:
    """The voxels a sweep re-decides: the warm ones, and the inherited ones with ``resynth``."""
    return (temps > 0.0) | (inherited & resynth)


def cool(temps: np.ndarray, visited: np.ndarray, inherited: np.ndarray, xi: float) -> None:
    """Cool the visited voxels that are not inherited, in place, all from ``temps`` as it is:
    ``t_s = max(0, (xi + sum of the 6 face neighbours' t) / 6)`` on the torus (float64 sums,
    stored as float32)."""
    t = temps.astype(np.float64)
    total = sum(np.roll(t, shift, axis) for axis in range(3) for shift in (1, -1))
    cooled = np.maximum(0.0, (xi + total) / FACE_NEIGHBOURS)
    mask = visited & ~inherited
    temps[mask] = cooled[mask].astype(np.float32)


def window_trust(trust: np.ndarray, view_axes: np.ndarray, window: int, anchor: int) -> np.ndarray:
    """Per view (plane axes ``view_axes[v]``), the sum of ``trust`` over the window of every
    site ``u`` (plane positions ``u - anchor .. u - anchor + window - 1``, toroidal):
    ``(V, N1, N2, N3)`` float32 (float64 sums)."""
    t = trust.astype(np.float64)
    out = np.empty((len(view_axes), *trust.shape), dtype=np.float32)
    for v, (ra, ca) in enumerate(view_axes):
        rows = sum(np.roll(t, anchor - i, int(ra)) for i in range(window))
        out[v] = sum(np.roll(rows, anchor - i, int(ca)) for i in range(window))
    return out


class IcmLevel:
    """One level's ICM bookkeeping: the temperatures (updated in place), the stop rule, the
    trust handed to the search and the votes, the visited voxels and their cooling."""

    def __init__(self, schedule: IcmSchedule, temps: np.ndarray, inherited: np.ndarray, view_axes: np.ndarray,
                 window: int, anchor: int):
        self.schedule, self.temps, self.inherited = schedule, temps, inherited
        self.view_axes, self.window, self.anchor = view_axes, window, anchor
        self.history = [float(temps.sum(dtype=np.float64))]
        self.target = (1.0 - schedule.stop) * self.history[0]
        self.visited = np.zeros(temps.shape, dtype=bool)
        self.updates = 0

    def warm(self, sweeps: int) -> bool:
        """Whether another sweep is due after ``sweeps`` sweeps."""
        return sweeps < self.schedule.max_sweeps and self.history[-1] > self.target

    def expected(self) -> int:
        """The sweeps the stop rule will need (for progress)."""
        s = self.schedule
        return expected_sweeps(self.history, n_voxels=self.temps.size, xi=s.xi, stop=s.stop,
                               max_sweeps=s.max_sweeps, n_union=FACE_NEIGHBOURS)

    def search_trust(self) -> np.ndarray:
        """Every voxel's trust ``1 - t`` (float32), for this sweep's search."""
        return np.ascontiguousarray(1.0 - self.temps, dtype=np.float32)

    def vote_trust(self) -> _solver.VoteTrust:
        """The trust of this sweep's votes (after its search, before its decisions)."""
        trust = self.search_trust()
        return _solver.VoteTrust(trust, window_trust(trust, self.view_axes, self.window, self.anchor))

    def visit(self, order: np.ndarray) -> np.ndarray:
        """The voxels of ``order`` (flat indices) this sweep re-decides, in that order."""
        self.visited = visit_mask(self.temps, self.inherited, self.schedule.inherit == "resynth")
        order = order[self.visited.ravel()[order]]
        self.updates += len(order)
        return order

    def cool(self) -> float:
        """Cool the sweep's visited voxels (:func:`cool`); the new global temperature."""
        cool(self.temps, self.visited, self.inherited, self.schedule.xi)
        self.history.append(float(self.temps.sum(dtype=np.float64)))
        return self.history[-1]
