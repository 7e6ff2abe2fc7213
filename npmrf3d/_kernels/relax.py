"""The class updates of the relaxations, and the heuristic choice of one value from the per-view
LCPDFs they apply.

A class update changes every site of one colour class (sites that never interact): ICM
(:data:`icm_update_class`) or one annealing step (:data:`anneal_update_class`: heat-bath, or
Metropolis when given proposals). Each comes in two compiled forms from one definition,
``serial`` (the calling thread: small classes) and ``parallel`` (chunks of sites on numba's
threads), and computes its sites' neighbour distances by direct sums or matrix products
(:mod:`npmrf3d._kernels.gemm`, chosen by ``ops``). Numba compiles what an argument's type decides
(``ops`` or the proposals None or not) as separate specialisations, so a run compiles only the
update it takes. The arguments come in bundles (:class:`ViewModels`, :class:`LevelArrays`,
:class:`npmrf3d._kernels.parzen.LcpdfOptions`, :class:`IcmRule`, :class:`AnnealRule`).

Heuristic codes (docs/model.md, section 3): 0 = ML_H1a, 1 = ML_H1b, 2 = ML_H2a, 3 = ML_H2b.
Decision codes: 0 = argmax (the paper's ICM), 1 = draw from ``exp(score / tau)`` with a
pre-drawn uniform (this project's stochastic decision, see docs/full_parzen.md, "The levers").
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._jit import jit, serial_and_parallel
from .gemm import chunk_count, chunk_sites, rows_log_lcpdfs

H1A, H1B, H2A, H2B = 0, 1, 2, 3
ARGMAX, SAMPLE = 0, 1
#: Classes with fewer sites run in the calling thread: starting a parallel region costs more
#: than it saves there (milliseconds when the cores are busy), and the result is the same.
PARALLEL_MIN_SITES = 64


class ViewModels(NamedTuple):
    """Everything the kernels need about the constrained views (V views, K labels).

    offsets : (V, M, 3) int64, volume offsets of each view's window (centre excluded)
    patches_t : (V, M*C, n_max) float32, transposed exemplar neighbour vectors
    centre_labels : (V, n_max) int32, label index of each patch centre (patches are grouped by
        it: non-decreasing over the valid patches)
    label_starts : (V, K + 1) int64, the patches of label ``j`` are ``label_starts[v, j] ..
        label_starts[v, j + 1] - 1``
    n_patches : (V,) int64, valid patches per view
    inv_two_h2 : (V,) float64, 1 / (2 h^2) for the neighbour term
    inv_two_hc2 : (V,) float64, 1 / (2 h_c^2) for the centre term
    log_norm_const : (V, K) float64, log c_j per view
    kernel_tables : (V, K, K) float64 label kernel tables, or (V, 0, 0) when too large
    labels : (K, C) float32
    union_offsets : (U, 3) int64, the 3D neighbourhood N_s (union of the views' windows)
    """

    offsets: np.ndarray
    patches_t: np.ndarray
    centre_labels: np.ndarray
    label_starts: np.ndarray
    n_patches: np.ndarray
    inv_two_h2: np.ndarray
    inv_two_hc2: np.ndarray
    log_norm_const: np.ndarray
    kernel_tables: np.ndarray
    labels: np.ndarray
    union_offsets: np.ndarray


class LevelArrays(NamedTuple):
    """The arrays of one level that a class update reads and writes in place.

    volume : (N1, N2, N3, C) float32
    labels_volume : (N1, N2, N3) int32 label index of each voxel (-1: not a label)
    temps : (N1, N2, N3) float32 voxel temperatures (the neighbours' trust)
    inherited : (N1, N2, N3) bool, voxels inherited from the coarser level
    """

    volume: np.ndarray
    labels_volume: np.ndarray
    temps: np.ndarray
    inherited: np.ndarray


class IcmRule(NamedTuple):
    """The ICM update's rule: heuristic and decision codes, ``tau`` of the ``sample`` decision,
    cooling step ``xi`` (< 0), ``resynth`` (inherited sites are revisited) and ``penalty`` (K,)
    float64 added to the ML_H2a/ML_H2b score."""

    heuristic: int
    decision: int
    tau: float
    xi: float
    resynth: bool
    penalty: np.ndarray


class AnnealRule(NamedTuple):
    """An annealing step's rule: heuristic code (ML_H2a or ML_H2b), ``temperature``,
    ``resynth`` (inherited sites may change) and ``penalty`` (K,) float64 added to the
    objective."""

    heuristic: int
    temperature: float
    resynth: bool
    penalty: np.ndarray


@jit
def choose_label(log_l, heuristic, decision, tau, u, penalty, labels, value_out, score):
    """Combine per-view log-LCPDFs ``log_l`` (V, K) into one value.

    Writes the chosen value into ``value_out`` (C,) and returns its label index (-1 for
    ML_H1b, whose average is generally not a label). ``penalty`` (K,) is added to the
    ML_H2a/ML_H2b score; ``score`` (K,) is scratch.
    """
    n_views, n_labels = log_l.shape
    nc = labels.shape[1]
    if heuristic == H1A or heuristic == H1B:
        chosen = -1
        lowest = np.inf
        for c in range(nc):
            value_out[c] = 0.0
        for v in range(n_views):
            kv = 0
            for kl in range(1, n_labels):
                if log_l[v, kl] > log_l[v, kv]:
                    kv = kl
            if log_l[v, kv] < lowest:
                lowest = log_l[v, kv]
                chosen = kv
            for c in range(nc):
                value_out[c] += labels[kv, c] / n_views
        if heuristic == H1B:
            return -1
        for c in range(nc):
            value_out[c] = labels[chosen, c]
        return chosen
    objective_scores(log_l, heuristic, penalty, score)
    if decision == SAMPLE:
        chosen = sample_index(score, tau, u)
    else:
        chosen = argmax_index(score)
    for c in range(nc):
        value_out[c] = labels[chosen, c]
    return chosen


@jit
def objective_scores(log_l, heuristic, penalty, score):
    """The ML_H2a (min over views) or ML_H2b (sum over views) objective of every label.

    ``score[k] = combine_v(log_l[v, k]) + penalty[k]``; ``log_l`` (V, K), ``score`` (K,) out.
    """
    n_views, n_labels = log_l.shape
    for kl in range(n_labels):
        if heuristic == H2A:
            s = np.inf
            for v in range(n_views):
                x = log_l[v, kl]
                if x < s:
                    s = x
        else:
            s = 0.0
            for v in range(n_views):
                s += log_l[v, kl]
        score[kl] = s + penalty[kl]


@jit
def argmax_index(score):
    """Index of the largest score (the first one on ties)."""
    best = 0
    for kl in range(1, score.shape[0]):
        if score[kl] > score[best]:
            best = kl
    return best


@jit
def sample_index(score, tau, u):
    """Index drawn from ``exp(score / tau) / Z`` with the uniform ``u`` in [0, 1).

    ``score`` is overwritten with the unnormalised probabilities. ``tau <= 0`` is the limit
    ``tau -> 0``: the argmax.
    """
    best = argmax_index(score)
    if not tau > 0.0:
        return best
    top = score[best]
    total = 0.0
    for kl in range(score.shape[0]):
        score[kl] = math.exp((score[kl] - top) / tau)
        total += score[kl]
    target = u * total
    acc = 0.0
    for kl in range(score.shape[0]):
        acc += score[kl]
        if acc > target:
            return kl
    return best  # reached only if rounding leaves acc <= target at the end


@jit
def metropolis_accept(delta, temperature, u):
    """Metropolis rule: accept a change of the objective by ``delta`` at ``temperature``.

    Always when ``delta >= 0``; otherwise with probability ``exp(delta / temperature)``,
    decided by the pre-drawn uniform ``u`` in [0, 1). At ``temperature <= 0`` a worse value
    is never accepted (greedy).
    """
    if delta >= 0.0:
        return True
    if not temperature > 0.0:
        return False
    return u < math.exp(delta / temperature)


@jit
def cool_site(temps, i, j, k, union_offsets, xi):
    """The ICM temperature update of site ``(i, j, k)`` after its decision: the mean of ``xi``
    and its union neighbourhood's temperatures, ``max(0, (xi + sum_r T[x + o_r]) / n_union)``
    (docs/model.md, section 6; toroidal volume)."""
    n1, n2, n3 = temps.shape
    n_union = union_offsets.shape[0]
    total = 0.0
    for r in range(n_union):
        total += temps[(i + union_offsets[r, 0]) % n1, (j + union_offsets[r, 1]) % n2,
                       (k + union_offsets[r, 2]) % n3]
    temps[i, j, k] = max(0.0, (xi + total) / n_union)


@jit
def penalty_pair(penalty, pair, out):
    """``out[q] = penalty[pair[q]]``: the penalty of the labels a Metropolis step compares."""
    for q in range(pair.shape[0]):
        out[q] = penalty[pair[q]]
    return out


@jit
def set_voxel(level, i, j, k, label, value):
    """Voxel ``(i, j, k)`` takes label index ``label`` and value ``value`` (C,)."""
    level.labels_volume[i, j, k] = label
    for c in range(value.shape[0]):
        level.volume[i, j, k, c] = value[c]


@jit
def icm_update_chunk(start, level, sites, uniforms, models, ops, lcpdf, rule, old_labels,
                     new_labels):
    """The ICM update of the chunk of sites from ``start`` on (of one class, see
    :data:`icm_update_class`): their LCPDFs first, then their decisions (sites of a class never
    interact, so this equals updating them one by one)."""
    stop = min(sites.shape[0], start + chunk_sites(ops))
    rows = np.empty(stop - start, dtype=np.int64)
    n_rows = 0
    for q in range(start, stop):
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        if level.temps[i, j, k] > 0.0 or (rule.resynth and level.inherited[i, j, k]):
            rows[n_rows] = q
            n_rows += 1
        else:
            old_labels[q] = -2
            new_labels[q] = -2
    if n_rows == 0:
        return
    n_labels = models.labels.shape[0]
    log_l = np.empty((n_rows, models.offsets.shape[0], n_labels), dtype=np.float64)
    rows_log_lcpdfs(level.volume, level.temps, sites, rows[:n_rows], models, ops, lcpdf, None,
                    log_l)
    score = np.empty(n_labels, dtype=np.float64)
    value = np.empty(level.volume.shape[3], dtype=np.float32)
    for b in range(n_rows):
        q = rows[b]
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        chosen = choose_label(log_l[b], rule.heuristic, rule.decision, rule.tau, uniforms[q],
                              rule.penalty, models.labels, value, score)
        old_labels[q] = level.labels_volume[i, j, k]
        new_labels[q] = chosen
        set_voxel(level, i, j, k, chosen, value)
        if not level.inherited[i, j, k]:
            cool_site(level.temps, i, j, k, models.union_offsets, rule.xi)


@serial_and_parallel
def icm_update_class(loop):
    def icm_update_class(level, sites, uniforms, models, ops, lcpdf, rule, old_labels,
                         new_labels):
        """Update every site of one colour class (sites never interact, so order is irrelevant).

        ``level``: :class:`LevelArrays`, updated in place; ``sites`` (S, 3) int64; ``ops``:
        :class:`npmrf3d._kernels.gemm.GemmOperands` or None (how distances are computed);
        ``rule``: :class:`IcmRule`. A site is visited when its temperature is positive, or when
        it is inherited and ``rule.resynth`` is set. Its new value is the heuristic's choice;
        afterwards a non-inherited site cools as ``t_s = max(0, (xi + sum_{r in N_s} t_r) /
        |N_s|)``. ``old_labels``/``new_labels`` (S,) receive the label indices (-2 where not
        visited), so the caller can update label counts. Randomness comes only from
        ``uniforms`` (S,), drawn by the caller before this call: the result does not depend on
        the number of threads.
        """
        for chunk in loop(chunk_count(sites.shape[0], ops)):
            icm_update_chunk(chunk * chunk_sites(ops), level, sites, uniforms, models, ops, lcpdf,
                             rule, old_labels, new_labels)
    return icm_update_class


@jit
def anneal_update_chunk(start, level, sites, candidates, uniforms, models, ops, lcpdf, rule,
                        old_labels, new_labels):
    """The annealing step of the chunk of sites from ``start`` on (of one class, see
    :data:`anneal_update_class`): their LCPDFs first, then their decisions."""
    stop = min(sites.shape[0], start + chunk_sites(ops))
    rows = np.empty(stop - start, dtype=np.int64)
    pairs = np.empty((stop - start, 2), dtype=np.int64)  # Metropolis: current, proposed label
    n_rows = 0
    for q in range(start, stop):
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        if level.inherited[i, j, k] and not rule.resynth:
            old_labels[q] = -2
            new_labels[q] = -2
            continue
        current = level.labels_volume[i, j, k]
        old_labels[q] = current
        new_labels[q] = current
        if candidates is None:  # heat-bath: every visited site draws
            rows[n_rows] = q
            n_rows += 1
        elif current >= 0 and candidates[q] != current:
            rows[n_rows] = q
            pairs[n_rows, 0] = current
            pairs[n_rows, 1] = candidates[q]
            n_rows += 1
        elif candidates[q] != current:  # a voxel without a label takes the proposal as it is
            new_labels[q] = candidates[q]
            set_voxel(level, i, j, k, candidates[q], models.labels[candidates[q]])
    if n_rows == 0:
        return
    n_labels = models.labels.shape[0]
    log_l = np.empty((n_rows, models.offsets.shape[0], n_labels if candidates is None else 2),
                     dtype=np.float64)
    rows_log_lcpdfs(level.volume, level.temps, sites, rows[:n_rows], models, ops, lcpdf,
                    None if candidates is None else pairs[:n_rows], log_l)
    score = np.empty(n_labels, dtype=np.float64)
    pen2 = np.empty(2, dtype=np.float64)
    two = np.empty(2, dtype=np.float64)
    for b in range(n_rows):
        q = rows[b]
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        current = level.labels_volume[i, j, k]
        if candidates is None:
            objective_scores(log_l[b], rule.heuristic, rule.penalty, score)
            chosen = sample_index(score, rule.temperature, uniforms[q])
        else:
            chosen = candidates[q]
            objective_scores(log_l[b], rule.heuristic, penalty_pair(rule.penalty, pairs[b], pen2),
                             two)
            if not metropolis_accept(two[1] - two[0], rule.temperature, uniforms[q]):
                chosen = current
        new_labels[q] = chosen
        if chosen != current:
            set_voxel(level, i, j, k, chosen, models.labels[chosen])


@serial_and_parallel
def anneal_update_class(loop):
    def anneal_update_class(level, sites, candidates, uniforms, models, ops, lcpdf, rule,
                            old_labels, new_labels):
        """One annealing step at every site of one colour class, at ``rule.temperature``.

        ``rule``: :class:`AnnealRule`; the other arguments as for :data:`icm_update_class`.
        ``candidates`` (S,) int64, Metropolis: the site's current label is replaced by
        ``candidates[q]`` if :func:`metropolis_accept` agrees on the change of the heuristic's
        objective (ML_H2a or ML_H2b, plus ``penalty``); only these two labels' LCPDFs are
        computed, so the cost does not grow with the number of labels. ``candidates`` None,
        heat-bath: the new label is drawn from ``exp(objective / temperature) / Z`` over all
        labels (this project's addition).
        Inherited sites are skipped unless ``rule.resynth``. ``level.temps`` only sets the
        neighbours' trust (all zero during annealing: every neighbour counts).
        ``old_labels``/``new_labels`` receive the label indices (-2 where not visited).
        Randomness comes only from ``candidates`` and ``uniforms``, drawn by the caller: the
        result does not depend on the number of threads.
        """
        for chunk in loop(chunk_count(sites.shape[0], ops)):
            anneal_update_chunk(chunk * chunk_sites(ops), level, sites, candidates, uniforms,
                                models, ops, lcpdf, rule, old_labels, new_labels)
    return anneal_update_class
