"""Nearest-neighbour search over exemplar patch vectors that stays bounded on repeated patches.

``scipy.spatial.cKDTree`` cannot split a set of identical points: they stay in one leaf, and
every query that reaches the leaf measures its distance to each of them. An exemplar with ``m``
identical patches (a flat background, a constant image, a label map) costs about ``m**2``
distance evaluations to query its own points: measured 0.5 s, 2.2 s and 5.8 s for the
10 000, 22 500 and 40 000 patches of a constant exemplar (3x3 window), 3.6 ns per pair, so a
3000 x 3000 constant image would have needed days.

:class:`PatchIndex` counts the repeats first (exact equality of the vectors, :func:`repeats`).
While the work they add, ``sum(m**2) - n`` over the groups of identical vectors, stays within
:data:`REPEAT_BUDGET` (a quarter second at the rate above), it is a plain ``cKDTree`` of all
points, so exemplars with few repeats give exactly the results they always gave (every bundled
photograph: at most 100 identical 3x3 patches, 10 000 extra pairs). Beyond the budget the tree
holds each distinct vector once; a query finds the nearest distinct vectors and lists each
one's points in index order, so identical points tie by their index (as a ``cKDTree`` leaf
scanned in order would rank them).

Queries run in chunks of :data:`QUERY_CHUNK` points: between two chunks Python runs, so Ctrl-C
and SIGTERM act within one chunk's time rather than after the whole search.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .._kernels._jit import thread_count

__all__ = ["QUERY_CHUNK", "REPEAT_BUDGET", "PatchIndex", "first_valid", "nearest_others", "repeats"]

#: Extra distance evaluations that repeated vectors may cost a plain tree before the index keeps
#: only distinct ones: 2**26 pairs, about 0.25 s at the 3.6 ns per pair measured above.
REPEAT_BUDGET = 1 << 26
#: Points per ``cKDTree.query`` call. Queries get slow on patches of uniform noise (a 9-d tree
#: has no structure to use): 0.7 ms each measured for the 490 000 3x3 patches of a 700 x 700
#: noise image on the loaded 2-core machine, so 2048 of them answer a signal within about 1.5 s;
#: on a 128 x 128 photograph a chunk takes a few milliseconds.
QUERY_CHUNK = 1 << 11


class PatchIndex:
    """The ``k`` nearest points of query vectors among the rows of ``points`` (Euclidean).

    Parameters
    ----------
    points : (n, D) array-like, converted to float64
    budget : int
        :data:`REPEAT_BUDGET` unless given (0: always keep distinct vectors only when some repeat).

    Attributes
    ----------
    points : (n, D) float64 ndarray
    distinct : int
        The vectors the tree holds: ``n`` for a plain tree, else the distinct ones.
    repeat_work : int
        ``sum(m**2) - n`` over the groups of identical vectors (0 when none repeats).
    deduplicated : bool
        Whether the tree holds the distinct vectors only.
    """

    def __init__(self, points, *, budget: int | None = None, chunk: int = QUERY_CHUNK):
        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self.chunk = max(1, int(chunk))
        n = len(self.points)
        budget = REPEAT_BUDGET if budget is None else int(budget)
        first, group, counts = repeats(self.points)
        self.repeat_work = int((counts * counts).sum()) - n
        self.deduplicated = self.repeat_work > budget
        if self.deduplicated:
            self.group = group                                             # point -> distinct vector
            self.counts = counts
            self.members = np.argsort(group, kind="stable")                # points by group, index order
            self.starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
            self.tree = cKDTree(self.points[first])
        else:
            self.group = self.counts = self.members = self.starts = None
            self.tree = cKDTree(self.points)
        self.distinct = int(self.tree.n)

    def __len__(self) -> int:
        return len(self.points)

    def query(self, vectors, k: int, *, eps: float = 0.0, workers: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(dist, idx)``, both ``(q, k)``: the ``k`` (at most ``n``) nearest points of every
        row of ``vectors``, nearest first; identical points in index order when deduplicated.
        ``eps`` and ``workers`` as in ``cKDTree.query`` (an approximate search; threads, which
        do not change the answer; None: numba's thread count)."""
        workers = thread_count() if workers is None else workers
        vectors = np.ascontiguousarray(vectors, dtype=np.float64).reshape(-1, self.points.shape[1])
        k = min(int(k), len(self.points))
        dist = np.empty((len(vectors), k), dtype=np.float64)
        idx = np.empty((len(vectors), k), dtype=np.int64)
        for lo in range(0, len(vectors), self.chunk):
            hi = min(lo + self.chunk, len(vectors))
            dist[lo:hi], idx[lo:hi] = self._query(vectors[lo:hi], k, eps, workers)
        return dist, idx

    def _query(self, vectors, k, eps=0.0, workers=1):
        if not self.deduplicated:
            d, i = self.tree.query(vectors, k=k, eps=eps, workers=workers)
            return np.reshape(d, (len(vectors), k)), np.reshape(i, (len(vectors), k))
        # the k nearest points lie among the k nearest distinct vectors, each listing its first
        # k points (fewer when the group is smaller)
        groups = min(k, self.distinct)
        d, g = self.tree.query(vectors, k=groups, eps=eps, workers=workers)
        d = np.reshape(d, (len(vectors), groups))
        g = np.reshape(np.asarray(g, dtype=np.int64), (len(vectors), groups))
        take = np.minimum(self.counts[g], k)                                  # (q, groups)
        slot = np.arange(k)
        valid = slot[None, None, :] < take[:, :, None]                        # (q, groups, k)
        cand = self.members[np.minimum(self.starts[g][:, :, None] + slot, len(self.members) - 1)]
        cand_d = np.broadcast_to(d[:, :, None], cand.shape)
        return first_valid(cand_d.reshape(len(vectors), -1), valid.reshape(len(vectors), -1), k), \
            first_valid(cand.reshape(len(vectors), -1), valid.reshape(len(vectors), -1), k)


def repeats(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The groups of identical rows of ``points`` (float64): ``(first, group, counts)``, the
    lowest point index of each group, every point's group and each group's size (int64).

    Rows are grouped by a 64-bit hash of their bytes (a sort of n integers: 1 000 000 rows in
    about 0.2 s where ``numpy.unique(axis=0)`` took 9 s) and every row is then compared with its
    group's first; a hash collision falls back to ``numpy.unique(axis=0)``. ``-0.0`` counts as
    ``0.0``.

    >>> [a.tolist() for a in repeats(np.array([[1.0, 2.0], [3.0, 4.0], [1.0, 2.0]]))]
    [[0, 1], [0, 1, 0], [2, 1]]
    """
    points = np.ascontiguousarray(points, dtype=np.float64) + 0.0  # -0.0 -> 0.0
    n = len(points)
    if n == 0:
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    words = points.view(np.uint64).reshape(n, -1)
    mult = np.random.default_rng(0x5EED).integers(1, 2**63, size=words.shape[1], dtype=np.uint64) | np.uint64(1)
    h = np.zeros(n, dtype=np.uint64)
    with np.errstate(over="ignore"):
        for j in range(words.shape[1]):
            w = words[:, j]
            h = (h ^ ((w ^ (w >> np.uint64(31))) * mult[j])) * np.uint64(0x9E3779B97F4A7C15)
    _, first, group, counts = np.unique(h, return_index=True, return_inverse=True, return_counts=True)
    group = np.asarray(group, dtype=np.int64).reshape(-1)
    if not np.array_equal(points, points[first[group]]):  # a collision: compare whole rows
        _, first, group, counts = np.unique(points, axis=0, return_index=True, return_inverse=True,
                                            return_counts=True)
        group = np.asarray(group, dtype=np.int64).reshape(-1)
    # number the groups by their first point, so the numbering does not depend on the hash
    rank = np.empty(len(first), dtype=np.int64)
    by_first = np.argsort(first, kind="stable")
    rank[by_first] = np.arange(len(first))
    return (np.asarray(first, dtype=np.int64)[by_first], rank[group],
            np.asarray(counts, dtype=np.int64)[by_first])


def first_valid(values: np.ndarray, valid: np.ndarray, k: int) -> np.ndarray:
    """Per row, the first ``k`` entries of ``values`` where ``valid`` holds, in order (rows
    with fewer repeat their last valid entry; rows with none keep their first entry).

    >>> first_valid(np.array([[5, 6, 7, 8]]), np.array([[False, True, False, True]]), 2)
    array([[6, 8]])
    """
    picked = np.repeat(values[:, :1], k, axis=1)
    rows, cols = np.nonzero(valid)                       # row-major: columns ascend in each row
    rank = np.cumsum(valid, axis=1)[rows, cols] - 1
    keep = rank < k
    picked[rows[keep], rank[keep]] = values[rows[keep], cols[keep]]
    have = np.minimum(valid.sum(axis=1), k)
    for row in np.flatnonzero((have < k) & (have > 0)):
        picked[row, have[row]:] = picked[row, have[row] - 1]
    return picked


def nearest_others(index: PatchIndex, k: int, *, exclude: float = 0.0,
                   coords: np.ndarray | None = None) -> np.ndarray:
    """For a deduplicated ``index``: the ``k`` nearest other points of every point, skipping
    those whose ``coords`` lie within Chebyshev distance ``exclude`` (see
    :func:`npmrf3d.model.kcoherence.k_coherence_sets`), ``(n, k)`` int64, nearest first.

    Identical points share their query: each distinct vector is looked up once, for
    ``k + (2 floor(exclude) + 1)**2`` points (the point itself and the points it excludes
    cannot leave fewer than ``k`` eligible among them), then each point drops itself and its
    excluded points from its group's list. A point with fewer than ``k`` eligible points
    repeats its last one (itself when none)."""
    n = len(index)
    reach = math.floor(exclude) if exclude > 0 else 0
    want = min(n, k + (2 * reach + 1) ** 2)
    unique = index.tree.data                                  # distinct vector g = group g
    out = np.empty((n, k), dtype=np.int64)
    _, lists = index.query(unique, want)                     # (distinct, want) points
    chunk = max(1, index.chunk // max(1, want // 8))
    for lo in range(0, n, chunk):
        points = np.arange(lo, min(lo + chunk, n))
        cand = lists[index.group[points]]
        ok = cand != points[:, None]
        if exclude > 0:
            cheb = np.abs(coords[cand] - coords[points][:, None, :]).max(axis=2)
            ok &= cheb > exclude
        picked = first_valid(cand, ok, k)
        none = ~ok.any(axis=1)
        picked[none] = points[none, None]
        out[lo:lo + len(points)] = picked
    return out
