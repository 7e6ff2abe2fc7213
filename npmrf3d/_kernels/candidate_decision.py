"""Compiled NP-MRF decisions among a voxel's candidates (the coherent NP-MRF sampler).

Private helpers of :func:`npmrf3d._kernels.kcoherence_solver.solve`: the per-view Parzen
estimate of a colour from a voxel's votes, the heuristics of Urs, Da Costa and Germain
2014 (docs/model.md, section 3) over the candidates, and the Metropolis step of an annealed
decision (docs/model.md, section 5). Each is a plain function of its arguments, so the solver
stays parallel over voxels and a result depends on no thread count: random numbers are hashes
of a salt and the voxel (:func:`npmrf3d._kernels.kcoherence.mix`).

The codes below are the solver's ``likelihood`` (the rule) and ``sampler`` (the annealed draw).
"""

from __future__ import annotations

import numpy as np

from ._jit import jit, jit_inline
from .kcoherence import mix, value_bin

#: The solver's rule among a voxel's heaviest votes (``SolverRule.likelihood``): the
#: configuration's own (medoid or mean), or an NP-MRF heuristic over the views' Parzen
#: estimates -- the product (ML_H2b), the minimum (ML_H2a), the least confident view's best
#: candidate (ML_H1a) or the mean of the views' best candidates (ML_H1b).
OWN_SOLVER, ML_H2B, ML_H2A, ML_H1A, ML_H1B = 0, 1, 2, 3, 4
#: The annealed draw of the NP-MRF rules with an objective (``SolverRule.sampler``): a
#: heat-bath step over the candidates, or a Metropolis step from the current colour.
HEAT_BATH, METROPOLIS = 0, 1

_TWO_31 = 2147483648.0

#: Relative gap between two candidates' scores as products (:func:`highest_objective`) below
#: which their order is settled by the exact objectives: a product of a few estimates and a
#: sum of their logarithms each round within about 1e-13 of the exact value, far inside it.
NEAR_TIE = 1e-9


@jit
def value_prior(bins, val_hist, val_target, val_unit, kappa):
    """Histogram prior of a colour whose value bins are ``bins`` (C,):
    ``kappa * sum_c log((T_c(b_c) + e) / (H_c(b_c) + e))`` (``H`` the volume's, ``T`` the
    exemplars' histogram in units of an even bin, ``e = 1 / val_unit``: one voxel). Positive for
    under-represented values, zero when the histograms agree."""
    e = 1.0 / val_unit
    prior = 0.0
    for ch in range(bins.shape[0]):
        b = bins[ch]
        prior += kappa * np.log((val_target[ch, b] + e) / (max(val_hist[ch, b], 0.0) + e))
    return prior


@jit
def view_likelihoods(colour, ex_flat, vg, vv, vw, count, vsum, h2c, outlier, lik):
    """Every view's Parzen estimate of ``colour`` (C,) float32 into ``lik`` (V,):
    ``(1 - outlier) * sum_{q in v} vw[q] exp(-||colour - e_q||^2 / h2c) / vsum[v] + outlier``
    over the ``count`` votes (texel ``vg[q]``, view ``vv[q]``, weight ``vw[q]``); ``outlier``
    alone for a view without votes (``vsum[v] == 0``)."""
    n_views = lik.shape[0]
    for v in range(n_views):
        lik[v] = 0.0
    for q in range(count):
        dd = np.float64(0.0)  # float64 also without the compiler (float32 terms)
        for ch in range(ex_flat.shape[1]):
            diff = colour[ch] - ex_flat[vg[q], ch]
            dd += diff * diff
        lik[vv[q]] += vw[q] * np.exp(-dd / h2c)
    for v in range(n_views):
        lik[v] = (1.0 - outlier) * lik[v] / vsum[v] + outlier if vsum[v] > 0.0 else outlier


@jit
def kernel_table(ex_flat, reps, h2c, out):
    """The Parzen kernel of :func:`view_likelihoods` between every two of the distinct colours
    ``ex_flat[reps]`` into ``out`` (n, n): ``out[a, b] = exp(-||e_a - e_b||^2 / h2c)``, computed
    as :func:`view_likelihoods` computes it (float32 differences, squares summed over the
    channels in float64), so a look-up gives the same bits as the exponential."""
    for a in range(reps.shape[0]):
        colour = ex_flat[reps[a]]
        for b in range(reps.shape[0]):
            dd = np.float64(0.0)
            for ch in range(ex_flat.shape[1]):
                diff = colour[ch] - ex_flat[reps[b], ch]
                dd += diff * diff
            out[a, b] = np.exp(-dd / h2c)


@jit
def view_likelihoods_table(row, uid, vv, vw, count, vsum, outlier, lik):
    """:func:`view_likelihoods` with the kernels looked up: ``row`` the candidate colour's row of
    :func:`kernel_table`, ``uid[q]`` the colour index of vote ``q``. Same sums in the same
    order, so the same bits."""
    n_views = lik.shape[0]
    for v in range(n_views):
        lik[v] = 0.0
    for q in range(count):
        lik[vv[q]] += vw[q] * row[uid[q]]
    for v in range(n_views):
        lik[v] = (1.0 - outlier) * lik[v] / vsum[v] + outlier if vsum[v] > 0.0 else outlier


@jit_inline
def candidate_likelihoods(kernel, rows, n_try, uid, vv, vw, count, vsum, outlier, out):
    """:func:`view_likelihoods_table` of ``n_try`` candidates at once: candidate ``a``'s estimates
    (its kernel row ``kernel[rows[a]]``) into ``out[a]`` (n_try, V). The votes come sorted by
    view (the solver enumerates them view by view), so each view's sum runs over one stretch of
    them; eight candidates go side by side (the solver's eight heaviest votes in one pass over
    the votes), each with its own sums in the same order, so the same bits. Votes not sorted by
    view: one candidate at a time."""
    n_views = out.shape[1]
    for q in range(1, count):
        if vv[q] < vv[q - 1]:
            for a in range(n_try):
                view_likelihoods_table(kernel[rows[a]], uid, vv, vw, count, vsum, outlier, out[a])
            return
    for a in range(0, n_try, 8):
        last = n_try - 1
        k0 = kernel[rows[a]]
        k1 = kernel[rows[min(a + 1, last)]]
        k2 = kernel[rows[min(a + 2, last)]]
        k3 = kernel[rows[min(a + 3, last)]]
        k4 = kernel[rows[min(a + 4, last)]]
        k5 = kernel[rows[min(a + 5, last)]]
        k6 = kernel[rows[min(a + 6, last)]]
        k7 = kernel[rows[min(a + 7, last)]]
        q = 0
        for v in range(n_views):
            s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = 0.0
            while q < count and vv[q] == v:
                w = vw[q]
                i = uid[q]
                s0 += w * k0[i]
                s1 += w * k1[i]
                s2 += w * k2[i]
                s3 += w * k3[i]
                s4 += w * k4[i]
                s5 += w * k5[i]
                s6 += w * k6[i]
                s7 += w * k7[i]
                q += 1
            # a slot past the last candidate repeats the last one's row and sums: the same value
            out[a, v] = s0
            out[min(a + 1, last), v] = s1
            out[min(a + 2, last), v] = s2
            out[min(a + 3, last), v] = s3
            out[min(a + 4, last), v] = s4
            out[min(a + 5, last), v] = s5
            out[min(a + 6, last), v] = s6
            out[min(a + 7, last), v] = s7
            for b in range(a, min(a + 8, n_try)):
                out[b, v] = (1.0 - outlier) * out[b, v] / vsum[v] + outlier if vsum[v] > 0.0 else outlier


@jit_inline
def objective(lik, likelihood, prior):
    """The score of the rules with an objective from the views' estimates ``lik``: ML_H2b's
    ``sum_v log L_v + prior``, or ML_H2a's ``min_v L_v * exp(prior)`` (``prior`` 0: none)."""
    if likelihood != ML_H2B:
        return objective_product(lik, likelihood, 1.0 if prior == 0.0 else np.exp(prior))
    score = 0.0
    for v in range(lik.shape[0]):
        score += np.log(lik[v])
    return score + prior if prior != 0.0 else score


@jit_inline
def objective_product(lik, likelihood, exp_prior):
    """:func:`objective` as a product, for ranking without logarithms: ML_H2b's
    ``prod_v L_v * exp(prior)`` (the exponential of its log-score) or ML_H2a's
    ``min_v L_v * exp(prior)`` (its very value); ``exp_prior`` is ``exp(prior)`` (1: none)."""
    if likelihood == ML_H2B:
        product = exp_prior
        for v in range(lik.shape[0]):
            product *= lik[v]
        return product
    least = np.inf
    for v in range(lik.shape[0]):
        least = min(least, lik[v])
    return least * exp_prior


@jit_inline
def highest_objective(products, n_try, liks, likelihood, prior_of, first):
    """The first of the ``n_try`` candidates with the highest :func:`objective` (its estimates
    ``liks[a]`` (V,), its prior ``prior_of[a]``, 0 without), ranked by ``products[a]`` -- the
    objective as a product, ``prod_v L_v * exp(prior)`` for ML_H2b (the exponential of its
    log-score, without a logarithm per view) or ``min_v L_v * exp(prior)`` for ML_H2a (its very
    value) -- and, among the candidates within :data:`NEAR_TIE` of the highest product, by their
    objectives themselves, so the winner is the one the objectives pick. A highest product
    outside ``[1e-200, 1e200]`` (an extreme prior) is not trusted: every objective is computed.
    Returns the winner's index, or ``first`` when no score beats ``-inf`` (the objectives'
    own rule: a strictly higher score wins, the first on ties)."""
    top = 0
    for a in range(1, n_try):
        if products[a] > products[top]:
            top = a
    cut = -np.inf
    if 1e-200 <= products[top] <= 1e200:
        cut = products[top] * (1.0 - NEAR_TIE)
    best = first
    best_e = np.inf
    n_views = liks.shape[1]
    for a in range(n_try):
        if products[a] >= cut:
            # an earlier candidate with the same estimates and prior has the same score, which a
            # later one does not beat (ties go to the first): not computed again
            repeat = False
            for b in range(a):
                if products[b] >= cut and prior_of[b] == prior_of[a]:
                    same = True
                    for v in range(n_views):
                        if liks[b, v] != liks[a, v]:
                            same = False
                    if same:
                        repeat = True
                        break
            if repeat:
                continue
            score = objective(liks[a], likelihood, prior_of[a])
            if -score < best_e:
                best_e = -score
                best = a
    return best


@jit
def colour_score(colour, ex_flat, vg, vv, vw, count, vsum, h2c, outlier, likelihood, hist_args, bins, lik):
    """Log-score of any colour (C,) float32 -- the voxel's current one for a Metropolis step --
    by the same Parzen estimate against the same votes as a candidate (:func:`view_likelihoods`,
    :func:`objective`, the log of ML_H2a's), with the histogram prior of the colour's value bins
    (``hist_args`` = ``(val_hist, val_target, val_unit, val_prior, val_lo, val_scale)``;
    ``bins`` (C,) int64 scratch)."""
    val_hist, val_target, val_unit, val_prior, val_lo, val_scale = hist_args
    view_likelihoods(colour, ex_flat, vg, vv, vw, count, vsum, h2c, outlier, lik)
    prior = 0.0
    if val_prior > 0.0:
        for ch in range(colour.shape[0]):
            bins[ch] = value_bin(colour[ch], val_lo[ch], val_scale[ch], val_hist.shape[1])
        prior = value_prior(bins, val_hist, val_target, val_unit, val_prior)
    score = objective(lik, likelihood, prior)
    return score if likelihood == ML_H2B else np.log(score)


@jit
def metropolis(scores, n_try, current, temperature, key):
    """A Metropolis step among ``n_try`` candidates of log-scores ``scores``: the proposal ``a``
    is drawn uniformly from ``(mix(key) + 0.5) / 2**31``; it is accepted when its score is at
    least the ``current`` colour's, else with probability ``exp((scores[a] - current) /
    temperature)`` against ``(mix(mix(key) + 2**31) + 0.5) / 2**31`` (a second hash of the same
    counter). Returns ``a``, or -1 when the voxel keeps its colour."""
    h = mix(key)
    a = min(int((h + 0.5) / _TWO_31 * n_try), n_try - 1)
    gap = scores[a] - current
    if gap >= 0.0:
        return a
    x = (mix(h + 2147483648) + 0.5) / _TWO_31
    return a if x < np.exp(gap / temperature) else -1


@jit
def view_winners(table, n_try, vsum, winners):
    """ML_H1's per-view searches: ``winners[v]`` the candidate with the highest estimate
    ``table[a, v]`` in view ``v`` (first on ties), -1 for a view without votes (it proposes
    nothing)."""
    for v in range(table.shape[1]):
        winners[v] = -1
        if vsum[v] <= 0.0:
            continue
        for a in range(n_try):
            if winners[v] < 0 or table[a, v] > table[winners[v], v]:
                winners[v] = a


@jit
def least_confident(table, winners):
    """ML_H1a: among the views' winners, the one whose own view's estimate is the lowest (the
    least confident view decides; first view on ties). Returns the candidate, -1 when no view
    proposes."""
    pick = -1
    low = np.inf
    for v in range(winners.shape[0]):
        a = winners[v]
        if a >= 0 and table[a, v] < low:
            low = table[a, v]
            pick = a
    return pick


@jit
def mean_of_winners(colour, winners, tops, vg, ex_flat):
    """ML_H1b: the mean of the views' winning colours into ``colour`` (C,) float32 (float64 sums
    over the views that propose, in view order; candidate ``a`` is the texel ``vg[tops[a]]``).
    Generally not an exemplar colour: Urs et al. 2014's averaging artefact."""
    n = 0
    for ch in range(colour.shape[0]):
        colour[ch] = 0.0
    acc = np.zeros(colour.shape[0], dtype=np.float64)
    for v in range(winners.shape[0]):
        if winners[v] < 0:
            continue
        n += 1
        for ch in range(colour.shape[0]):
            acc[ch] += ex_flat[vg[tops[winners[v]]], ch]
    for ch in range(colour.shape[0]):
        colour[ch] = acc[ch] / n


@jit
def winner_sources(winners, tops, vg, vv, view_starts, ex_flat, ex_off, new_src_t):
    """ML_H1b's sources: each proposing view's source becomes its own winner -- the winning
    texel (candidate ``a`` is vote ``tops[a]`` of the votes: texels ``vg``, views ``vv``, view
    ``v``'s ``view_starts[v] .. view_starts[v + 1] - 1``) when it is that view's vote, else that
    view's voted texel nearest to the winner's colour (first on ties, :func:`nearest_in`).
    ``new_src_t`` (V,) is written for the proposing views only."""
    for v in range(winners.shape[0]):
        if winners[v] < 0:
            continue
        g = vg[tops[winners[v]]]
        if vv[tops[winners[v]]] == v:
            new_src_t[v] = g - ex_off[v]
            continue
        near = nearest_in(view_starts[v], view_starts[v + 1], g, vg, ex_flat)
        if near >= 0:
            new_src_t[v] = vg[near] - ex_off[v]


@jit_inline
def nearest_in(lo, hi, g, vg, ex_flat):
    """Of the votes ``lo .. hi - 1`` (one view's stretch: the solver enumerates the votes view
    by view), the one whose texel is nearest in colour to texel ``g`` (first on ties), -1 for
    an empty stretch. Every vote is compared, the nearest so far kept by selections rather
    than branches (which the distances' order would mispredict)."""
    near = -1
    near_d = np.inf
    for q in range(lo, hi):
        dd = 0.0
        for ch in range(ex_flat.shape[1]):
            diff = ex_flat[vg[q], ch] - ex_flat[g, ch]
            dd += diff * diff
        nearer = dd < near_d
        near = q if nearer else near
        near_d = dd if nearer else near_d
    return near


@jit
def write_colour(volume, p0, p1, p2, colour, hist_args, old_bins_t, new_bins_t):
    """Give voxel ``(p0, p1, p2)`` the colour ``colour`` (C,) float32 (ML_H1b's mean, no texel);
    when it changes, its old and new value bins go to ``old_bins_t`` and ``new_bins_t`` (C,) for
    the solver's histogram update. Returns 1 if the colour changed, else 0."""
    val_hist, val_lo, val_scale = hist_args[0], hist_args[4], hist_args[5]
    flag = 0
    for ch in range(colour.shape[0]):
        if volume[p0, p1, p2, ch] != colour[ch]:
            flag = 1
    if flag:
        for ch in range(colour.shape[0]):
            old_bins_t[ch] = value_bin(volume[p0, p1, p2, ch], val_lo[ch], val_scale[ch], val_hist.shape[1])
            new_bins_t[ch] = value_bin(colour[ch], val_lo[ch], val_scale[ch], val_hist.shape[1])
    for ch in range(colour.shape[0]):
        volume[p0, p1, p2, ch] = colour[ch]
    return flag
