"""Compiled smoothness prior of the coherent NP-MRF decision: a candidate colour that agrees with
the voxel's six face neighbours scores higher.

Private helpers of :func:`npmrf3d._kernels.kcoherence_solver.solve`. The slices of a material
that each look right need not connect through the third dimension: each view judges a voxel in
its own plane, so a phase's runs along a view's normal are left to chance and a pore throat
that two views disagree on is lost to the majority phase. The prior adds to a candidate's
log-score ``-beta * sum_n mean_c ((colour_c - previous_n,c) / span_c)^2`` over the six face
neighbours ``n`` (toroidal), read from the volume as it was before the pass (``previous``), so
a voxel depends on no other voxel decided in the same pass and the result on no thread count.
For two phases ``0`` and ``span`` it is ``-beta`` times the number of neighbours of the other
phase: a Potts prior that continues each phase's runs along every axis, the views' normals
included, and so smooths the interfaces and keeps thin throats open.
"""

from __future__ import annotations

import numpy as np

from ._jit import jit
from .candidate_decision import ML_H1A
from .kcoherence import wrap


@jit
def smoothness_prior(colour, previous, p0, p1, p2, inv_span, beta):
    """``-beta * sum_n mean_c ((colour_c - previous[n, c]) * inv_span_c)^2`` over the six face
    neighbours ``n`` of voxel ``(p0, p1, p2)`` in ``previous`` (N0, N1, N2, C), toroidal."""
    n0, n1, n2, channels = previous.shape
    total = 0.0
    for step in range(6):
        axis = step // 2
        shift = 1 if step % 2 else -1
        q0 = wrap(p0 + shift, n0) if axis == 0 else p0
        q1 = wrap(p1 + shift, n1) if axis == 1 else p1
        q2 = wrap(p2 + shift, n2) if axis == 2 else p2
        for ch in range(channels):
            gap = (np.float64(colour[ch]) - np.float64(previous[q0, q1, q2, ch])) * inv_span[ch]
            total += gap * gap
    return -beta * total / channels


@jit
def add_smoothness(ex_flat, vg, tops, n_try, previous, p0, p1, p2, inv_span, beta, likelihood, ranked,
                   products, prior_of, table, scores):
    """Add :func:`smoothness_prior` of each of the ``n_try`` candidates (texels ``vg[tops[a]]``)
    to what the solver ranks them by: the objective as a product and its prior (``ranked``:
    ``products[a] * exp(s)``, ``prior_of[a] + s``), every view's estimate of a per-view rule
    (``table[a] * exp(s)``), or the annealed log-score (``scores[a] + s``)."""
    for a in range(n_try):
        s = smoothness_prior(ex_flat[vg[tops[a]]], previous, p0, p1, p2, inv_span, beta)
        if ranked:
            products[a] *= np.exp(s)
            prior_of[a] += s
        elif likelihood >= ML_H1A:
            for v in range(table.shape[1]):
                table[a, v] *= np.exp(s)
        else:
            scores[a] += s
