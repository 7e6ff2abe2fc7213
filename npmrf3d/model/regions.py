"""Regions of a pyramid: what part of every level a block of the finest level depends on.

A multi-scale method whose steps reach a bounded distance -- a voxel after one iteration depends
only on voxels at most ``r`` away in the iteration before, and its random numbers are hashes of
its position in the level's whole grid -- can make any block of the final volume from the
block's **dependency cone** alone: at the finest level the block grown by the level's *apron*
(its iterations times ``r``), at the next coarser level the parents of that region grown by
that level's apron, and so on to the coarsest level. The region's edge is wrong (it lacks its
outer neighbours) but the error moves inwards by at most ``r`` per iteration, so after the
level's iterations the region minus its apron -- the part the finer level needs -- is exactly
what the whole grid gives there. Where a region would cover a level's whole axis it is that
axis (the grid is toroidal, so the result is then exact everywhere).

A region is a :class:`Frame`: the level's whole grid (``extent``), the region's ``shape`` and
the grid position of its first voxel (``origin``; the region wraps around the torus). The
:class:`RegionPlan` of a block lists one frame per level and the indices that cut a finished
coarser level down to the parents of the finer level's region (:meth:`RegionPlan.parents`).
A method may also run its coarsest levels whole (their statistics are global), once for all
blocks: those levels have no frame, and the plan names the checkpoint that holds them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Frame", "RegionPlan", "plan_region", "whole_frame"]


@dataclass(frozen=True)
class Frame:
    """A region of one level's toroidal grid: array index ``i`` along axis ``a`` is grid position
    ``(origin[a] + i) % extent[a]``."""

    origin: tuple[int, int, int]
    shape: tuple[int, int, int]
    extent: tuple[int, int, int]

    @property
    def whole(self) -> bool:
        """Whether the region is the level's whole grid in grid order."""
        return self.shape == self.extent and self.origin == (0, 0, 0)

    def positions(self, axis: int) -> np.ndarray:
        """Grid positions of the region's indices along ``axis``."""
        return (self.origin[axis] + np.arange(self.shape[axis])) % self.extent[axis]

    def indices_of(self, origin, shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Per axis, the region's array indices of the grid positions ``origin .. origin + shape - 1``
        (toroidal), which must lie inside the region."""
        out = []
        for a in range(3):
            offset = (origin[a] - self.origin[a] + np.arange(shape[a])) % self.extent[a]
            if offset.size and offset.max() >= self.shape[a]:
                raise ValueError(f"positions {origin[a]}..{origin[a] + shape[a] - 1} of axis {a} are "
                                 f"not in the region {self.origin[a]}+{self.shape[a]} of {self.extent[a]}")
            out.append(offset)
        return tuple(out)


def whole_frame(extent) -> Frame:
    """The frame of a level's whole grid."""
    extent = tuple(int(n) for n in extent)
    return Frame((0, 0, 0), extent, extent)


@dataclass(frozen=True)
class RegionPlan:
    """The frames of a block's dependency cone, one per level (index 0 the finest), and the
    block inside the finest frame.

    ``frames[level]`` is the region the method runs at ``level``, or None for a level that runs
    whole (the coarsest ones, shared by all blocks through the checkpoint ``start``); the
    finished level ``l + 1`` is cut to :meth:`parents` ``(l)`` before it is up-sampled into
    level ``l``; the finest frame is cut to the block by :meth:`block_indices`.
    """

    frames: tuple[Frame | None, ...]
    origin: tuple[int, int, int]
    shape: tuple[int, int, int]
    start: str | None = None

    def parents(self, level: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Indices into the finished level ``level + 1`` of the parents of ``frames[level]``."""
        child = self.frames[level]
        coarse = self.frames[level + 1]
        if coarse is None:
            coarse = whole_frame(tuple(n // 2 for n in child.extent))
        return coarse.indices_of(tuple(o // 2 for o in child.origin), tuple(n // 2 for n in child.shape))

    def block_indices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Indices into the finished finest frame of the block (the whole grid when every level
        runs whole)."""
        if self.frames[0] is None:
            return tuple(o + np.arange(n) for o, n in zip(self.origin, self.shape))
        return self.frames[0].indices_of(self.origin, self.shape)


def plan_region(size, levels: int, aprons, origin, shape, start=None) -> RegionPlan:
    """The dependency cone of the block ``origin .. origin + shape - 1`` of the finest grid
    ``size`` for a pyramid of ``levels`` levels whose level ``l`` (0 the finest) has grid
    ``size // 2**l`` and reaches ``aprons[l]`` voxels over its iterations (None: the level runs
    whole, from the checkpoint ``start``, and so do the coarser ones).

    Every region starts and ends on even grid positions below the coarsest level, so that its
    parents are whole voxels of the coarser level (:meth:`RegionPlan.parents`); a region at
    least as long as its axis becomes the whole axis.

    >>> plan = plan_region((64, 64, 64), 2, (6, 4), (0, 0, 0), (16, 16, 16))
    >>> [(f.origin, f.shape) for f in plan.frames]
    [((58, 58, 58), (28, 28, 28)), ((25, 25, 25), (22, 22, 22))]
    >>> plan_region((32, 32, 32), 2, (20, 4), (0, 0, 16), (32, 32, 16)).frames[0].shape
    (32, 32, 32)
    >>> plan_region((64, 64, 64), 2, (6, None), (0, 0, 0), (16, 16, 16)).frames[1] is None
    True
    """
    size = tuple(int(n) for n in size)
    origin = tuple(int(o) for o in origin)
    shape = tuple(int(n) for n in shape)
    frames = []
    core_origin, core_shape = origin, shape
    for level in range(levels):
        extent = tuple(n // 2 ** level for n in size)
        if aprons[level] is None:
            frames += [None] * (levels - level)
            break
        coarser = level + 1 < levels
        o_list, n_list = [], []
        for a in range(3):
            lo = core_origin[a] - int(aprons[level])
            hi = core_origin[a] + core_shape[a] + int(aprons[level])
            if coarser:
                lo, hi = lo - lo % 2, hi + hi % 2
            if hi - lo >= extent[a]:
                lo, hi = 0, extent[a]
            o_list.append(lo % extent[a])
            n_list.append(hi - lo)
        frame = Frame(tuple(o_list), tuple(n_list), extent)
        frames.append(frame)
        core_origin = tuple(o // 2 for o in frame.origin)
        core_shape = tuple(n // 2 for n in frame.shape)
    return RegionPlan(tuple(frames), origin, shape, None if start is None else str(start))
