"""Heuristic choice of one value from the per-view LCPDFs, and the parallel ICM class update.

Heuristic codes (SPEC.md section 3): 0 = ML_H1a, 1 = ML_H1b, 2 = ML_H2a, 3 = ML_H2b.
Decision codes: 0 = argmax (the paper's ICM), 1 = draw from ``exp(score / tau)`` with a
pre-drawn uniform (this project's stochastic decision, see docs/quality.md).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ._jit import jit, jit_parallel, prange
from .parzen import (
    gather_neighbours,
    log_lcpdf_at_labels,
    log_lcpdf_from_distances,
    neighbour_distances,
)

H1A, H1B, H2A, H2B = 0, 1, 2, 3
ARGMAX, SAMPLE = 0, 1




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
def site_log_lcpdfs(volume, temps, i, j, k, models, adapt_eps, min_two_h2, prune, outlier,
                    buffers, log_l):
    """Per-view log-LCPDF of site (i, j, k) into ``log_l`` (V, K)."""
    values, trust, dist, weights, nonzero, log_weights, rows, wbuf = buffers
    n_views = models.offsets.shape[0]
    for v in range(n_views):
        gather_neighbours(volume, temps, i, j, k, models.offsets[v], values, trust)
        n = models.n_patches[v]
        neighbour_distances(values, trust, models.patches_t[v], n, dist, rows)
        log_lcpdf_from_distances(
            dist, n, models.label_starts[v], models.labels, models.inv_two_h2[v],
            models.inv_two_hc2[v], adapt_eps, min_two_h2, prune, models.log_norm_const[v],
            models.kernel_tables[v], outlier,
            weights, nonzero, log_weights, wbuf, log_l[v],
        )


@jit
def site_log_lcpdfs_at(volume, temps, i, j, k, models, adapt_eps, min_two_h2, prune, outlier,
                       query, buffers, log_q):
    """Per-view log-LCPDF of site (i, j, k) at the labels ``query`` (Q,) into ``log_q`` (V, Q)."""
    values, trust, dist, weights, nonzero, log_weights, rows, wbuf = buffers
    for v in range(models.offsets.shape[0]):
        gather_neighbours(volume, temps, i, j, k, models.offsets[v], values, trust)
        n = models.n_patches[v]
        neighbour_distances(values, trust, models.patches_t[v], n, dist, rows)
        log_lcpdf_at_labels(
            dist, n, models.label_starts[v], models.labels, models.inv_two_h2[v],
            models.inv_two_hc2[v], adapt_eps, min_two_h2, prune, models.log_norm_const[v],
            outlier, query, weights, nonzero, log_weights, wbuf, log_q[v],
        )


@jit
def make_buffers(models):
    """Scratch arrays for one thread: values, trust, dist, weights, nonzero, log_weights, rows,
    wbuf (the label stage's float32 weights and their exponent bits)."""
    n_m = models.offsets.shape[1]
    n_labels = models.labels.shape[0]
    return (
        np.empty(models.patches_t.shape[1], dtype=np.float32),
        np.empty(n_m, dtype=np.float32),
        np.empty(models.patches_t.shape[2], dtype=np.float32),
        np.zeros(n_labels, dtype=np.float64),
        np.empty(n_labels, dtype=np.int64),
        np.empty(n_labels, dtype=np.float64),
        np.empty(models.patches_t.shape[1], dtype=np.int64),
        np.empty((2, models.patches_t.shape[2]), dtype=np.float32),
    )


CHUNK = 8
#: Classes with fewer sites run in the calling thread: starting a parallel region costs more
#: than it saves there (milliseconds when the cores are busy), and the result is the same.
PARALLEL_MIN_SITES = 64


@jit
def cool_site(temps, i, j, k, union_offsets, xi):
    """The ICM temperature update of site ``(i, j, k)`` after its decision: the mean of ``xi``
    and its union neighbourhood's temperatures, ``max(0, (xi + sum_r T[x + o_r]) / n_union)``
    (SPEC.md section 4; toroidal volume)."""
    n1, n2, n3 = temps.shape
    n_union = union_offsets.shape[0]
    total = 0.0
    for r in range(n_union):
        total += temps[(i + union_offsets[r, 0]) % n1, (j + union_offsets[r, 1]) % n2,
                       (k + union_offsets[r, 2]) % n3]
    temps[i, j, k] = max(0.0, (xi + total) / n_union)


@jit
def icm_update_sites(
    start, stop, volume, labels_volume, temps, inherited, sites, uniforms, models, heuristic,
    decision, tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier, old_labels,
    new_labels,
):
    """The ICM update of sites ``start .. stop - 1`` of one class (see :func:`icm_update_class`)."""
    n_views = models.offsets.shape[0]
    n_labels = models.labels.shape[0]
    nc = volume.shape[3]
    buffers = make_buffers(models)
    log_l = np.empty((n_views, n_labels), dtype=np.float64)
    score = np.empty(n_labels, dtype=np.float64)
    value = np.empty(nc, dtype=np.float32)
    for q in range(start, stop):
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        is_inherited = inherited[i, j, k]
        if not (temps[i, j, k] > 0.0 or (resynth and is_inherited)):
            old_labels[q] = -2
            new_labels[q] = -2
            continue
        site_log_lcpdfs(volume, temps, i, j, k, models, adapt_eps, min_two_h2, prune,
                        outlier, buffers, log_l)
        chosen = choose_label(log_l, heuristic, decision, tau, uniforms[q], penalty,
                              models.labels, value, score)
        old_labels[q] = labels_volume[i, j, k]
        new_labels[q] = chosen
        labels_volume[i, j, k] = chosen
        for c in range(nc):
            volume[i, j, k, c] = value[c]
        if not is_inherited:
            cool_site(temps, i, j, k, models.union_offsets, xi)


@jit_parallel
def icm_update_class(
    volume, labels_volume, temps, inherited, sites, uniforms, models, heuristic, decision,
    tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier, old_labels, new_labels,
):
    """Update every site of one colour class (sites never interact, so order is irrelevant).

    ``sites`` (S, 3) int64. A site is visited when its temperature is positive, or when it is
    inherited and ``resynth`` is set. Its new value is the heuristic's choice; afterwards a
    non-inherited site cools as ``t_s = max(0, (xi + sum_{r in N_s} t_r) / |N_s|)``.
    ``old_labels``/``new_labels`` (S,) receive the label indices (-2 where not visited), so the
    caller can update label counts. Randomness comes only from ``uniforms`` (S,), drawn by the
    caller before this call: the result does not depend on the number of threads.
    """
    n_sites = sites.shape[0]
    n_chunks = (n_sites + CHUNK - 1) // CHUNK
    for chunk in prange(n_chunks):
        icm_update_sites(chunk * CHUNK, min(n_sites, (chunk + 1) * CHUNK), volume,
                         labels_volume, temps, inherited, sites, uniforms, models, heuristic,
                         decision, tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty,
                         outlier, old_labels, new_labels)


@jit
def icm_update_class_serial(
    volume, labels_volume, temps, inherited, sites, uniforms, models, heuristic, decision,
    tau, xi, resynth, adapt_eps, min_two_h2, prune, penalty, outlier, old_labels, new_labels,
):
    """:func:`icm_update_class` in the calling thread (for small classes; same result)."""
    icm_update_sites(0, sites.shape[0], volume, labels_volume, temps, inherited, sites,
                     uniforms, models, heuristic, decision, tau, xi, resynth, adapt_eps,
                     min_two_h2, prune, penalty, outlier, old_labels, new_labels)


METROPOLIS, HEAT_BATH = 0, 1


@jit
def penalty_pair(penalty, pair, out):
    """``out[q] = penalty[pair[q]]``: the penalty of the labels a Metropolis step compares."""
    for q in range(pair.shape[0]):
        out[q] = penalty[pair[q]]
    return out


@jit
def anneal_update_sites(
    start, stop, volume, labels_volume, temps, inherited, sites, candidates, uniforms, models,
    heuristic, sampler, temperature, resynth, adapt_eps, min_two_h2, prune, penalty, outlier,
    old_labels, new_labels,
):
    """The annealing step of sites ``start .. stop - 1`` of one class (see
    :func:`anneal_update_class`)."""
    n_views = models.offsets.shape[0]
    n_labels = models.labels.shape[0]
    nc = volume.shape[3]
    buffers = make_buffers(models)
    log_l = np.empty((n_views, n_labels), dtype=np.float64)
    score = np.empty(n_labels, dtype=np.float64)
    pair = np.empty(2, dtype=np.int64)
    log_pair = np.empty((n_views, 2), dtype=np.float64)
    pen2 = np.empty(2, dtype=np.float64)
    two = np.empty(2, dtype=np.float64)
    for q in range(start, stop):
        i, j, k = sites[q, 0], sites[q, 1], sites[q, 2]
        if inherited[i, j, k] and not resynth:
            old_labels[q] = -2
            new_labels[q] = -2
            continue
        current = labels_volume[i, j, k]
        if sampler == HEAT_BATH:
            site_log_lcpdfs(volume, temps, i, j, k, models, adapt_eps, min_two_h2, prune,
                            outlier, buffers, log_l)
            objective_scores(log_l, heuristic, penalty, score)
            chosen = sample_index(score, temperature, uniforms[q])
        else:
            chosen = candidates[q]
            if current >= 0 and chosen != current:
                pair[0] = current
                pair[1] = chosen
                site_log_lcpdfs_at(volume, temps, i, j, k, models, adapt_eps, min_two_h2,
                                   prune, outlier, pair, buffers, log_pair)
                objective_scores(log_pair, heuristic, penalty_pair(penalty, pair, pen2), two)
                if not metropolis_accept(two[1] - two[0], temperature, uniforms[q]):
                    chosen = current
        old_labels[q] = current
        new_labels[q] = chosen
        if chosen != current:
            labels_volume[i, j, k] = chosen
            for c in range(nc):
                volume[i, j, k, c] = models.labels[chosen, c]


@jit_parallel
def anneal_update_class(
    volume, labels_volume, temps, inherited, sites, candidates, uniforms, models, heuristic,
    sampler, temperature, resynth, adapt_eps, min_two_h2, prune, penalty, outlier, old_labels,
    new_labels,
):
    """One annealing step at every site of one colour class, at global ``temperature``.

    ``sampler`` METROPOLIS: the site's current label is replaced by ``candidates[q]`` if
    :func:`metropolis_accept` agrees on the change of the heuristic's objective (ML_H2a or
    ML_H2b, plus ``penalty``); only these two labels' LCPDFs are computed, so the cost does
    not grow with the number of labels. HEAT_BATH: the new label is drawn from
    ``exp(objective / temperature) / Z`` over all labels (this project's addition).
    Inherited sites are skipped unless ``resynth``. ``temps`` only sets the neighbours' trust
    (all zero during annealing: every neighbour counts). ``old_labels``/``new_labels`` receive
    the label indices (-2 where not visited). Randomness comes only from ``candidates`` and
    ``uniforms``, drawn by the caller: the result does not depend on the number of threads.
    """
    n_sites = sites.shape[0]
    n_chunks = (n_sites + CHUNK - 1) // CHUNK
    for chunk in prange(n_chunks):
        anneal_update_sites(chunk * CHUNK, min(n_sites, (chunk + 1) * CHUNK), volume,
                            labels_volume, temps, inherited, sites, candidates, uniforms, models,
                            heuristic, sampler, temperature, resynth, adapt_eps, min_two_h2,
                            prune, penalty, outlier, old_labels, new_labels)


@jit
def anneal_update_class_serial(
    volume, labels_volume, temps, inherited, sites, candidates, uniforms, models, heuristic,
    sampler, temperature, resynth, adapt_eps, min_two_h2, prune, penalty, outlier, old_labels,
    new_labels,
):
    """:func:`anneal_update_class` in the calling thread (for small classes; same result)."""
    anneal_update_sites(0, sites.shape[0], volume, labels_volume, temps, inherited, sites,
                        candidates, uniforms, models, heuristic, sampler, temperature, resynth,
                        adapt_eps, min_two_h2, prune, penalty, outlier, old_labels, new_labels)
