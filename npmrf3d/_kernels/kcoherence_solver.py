"""Compiled discrete solver of the k-coherence engine (Chen & Wang 2010, section 4.2).

Why one module of ~680 lines: one kernel, :func:`solve`, whose decision rules (weighted mean,
weighted medoid, the NP-MRF rules and their annealed draws, the latter's helpers in
:mod:`npmrf3d._kernels.candidate_decision`) share the votes and their buffers (trusted or not),
with its helpers (the votes, the candidates' scores, the copy of a texel and its sources, the
histograms' update after a batch; compiled functions that :func:`solve` calls) and the four
bundles of its arguments.

Private: called by :mod:`npmrf3d.model.kcoherence_engine` with validated arrays only; nothing
here raises a user-facing error. :func:`solve` (parallel over the voxels of a batch): every voxel
takes, among the texels voted by all overlapping neighbourhoods of all views, one texel, colour
and source -- the one nearest to the votes' weighted mean (IRLS weights divided by the
position-histogram factor), a weighted medoid, or the highest NP-MRF score. The histograms are
frozen within a batch and updated (sequentially) between batches. Its arguments come in four
bundles: the views' packed exemplars (:class:`PackedViews`), the histograms
(:class:`SolverHistograms`), the votes' trust (:class:`VoteTrust`) and the decision
(:class:`SolverRule`).

Geometry as in :mod:`npmrf3d._kernels.kcoherence`. Results depend only on the inputs: parallel
loops write only their own voxel, and every order-dependent step (histogram updates) runs in
one thread in a fixed order.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from . import candidate_decision as _decide
from ._jit import jit, jit_inline, jit_parallel, prange
from .smoothness import add_smoothness, smoothness_prior
from .candidate_decision import HEAT_BATH, METROPOLIS, ML_H1A, ML_H1B, ML_H2A, ML_H2B, value_prior
from .kcoherence import first_site, global_flat, grid_voxels, mix, value_bin, wrap


class PackedViews(NamedTuple):
    """The views' exemplars of one level packed for the solver (:func:`solve`).

    axes : (V, 2) int64, each view's volume axes of the exemplar row and column
    texels : (G, C) float32, the exemplars' pixels as rows (an exemplar shared by views once)
    offsets : (V,) int64, each view's first row in ``texels``
    widths : (V,) int64, each view's exemplar width
    window, anchor, grid : int, the window side, its anchor and the site spacing
    """

    axes: np.ndarray
    texels: np.ndarray
    offsets: np.ndarray
    widths: np.ndarray
    window: int
    anchor: int
    grid: int


class SolverHistograms(NamedTuple):
    """The histograms the solver weighs votes by; ``positions`` and ``values`` are updated in
    place (:func:`solve`).

    positions : (sum of the views' pixels,) float64, voxels per source pixel, packed per view
    position_offsets : (V,) int64, each view's first entry in ``positions``
    theta : (V,) float64, each view's even count per pixel
    position_weight, position_boost : float, strengths (:func:`_votes`)
    texel_bins : (G, C) int64, the value bin of every packed texel per channel
    values : (C, bins) float64, the volume's value histogram in units of ``value_unit`` voxels
    value_target : (C, bins) float64, the exemplars' in the same units
    value_weight, value_prior : float, strengths of the vote weighting and of the prior
    value_lo, value_scale : (C,) float64, the binning (:func:`value_bin`)
    value_unit : float, voxels per even bin
    follow : bool, the histograms follow the new sources after each batch (False: the caller
        sets them before each batch, as a block reading its pilot's does, and each voxel's
        sources are written as it is decided)
    """

    positions: np.ndarray
    position_offsets: np.ndarray
    theta: np.ndarray
    position_weight: float
    position_boost: float
    texel_bins: np.ndarray
    values: np.ndarray
    value_target: np.ndarray
    value_weight: float
    value_prior: float
    value_lo: np.ndarray
    value_scale: np.ndarray
    value_unit: float
    follow: bool = True


class SolverRule(NamedTuple):
    """How the solver decides (:func:`solve`).

    medoid : int, 0 = the voted texel nearest the weighted mean, else the candidates are the
        texels of the ``medoid`` heaviest votes
    balance : bool, every view's votes of a voxel weigh the same in total
    likelihood : int, a code of :mod:`npmrf3d._kernels.candidate_decision`: ``OWN_SOLVER`` (a
        weighted medoid), ``ML_H2B``, ``ML_H2A``, ``ML_H1A`` or ``ML_H1B``
    h2c, outlier : float, the NP-MRF rule's centre kernel ``2 h_c^2`` and outlier share
    temperature, salt : float and int, the annealed draw (temperature 0: the highest score)
    sampler : int, the annealed draw's rule, ``HEAT_BATH`` or ``METROPOLIS``
    origin, extent : (3,) int64 each, where the volume lies in the level's whole grid (the
        draws hash :func:`npmrf3d._kernels.kcoherence.global_flat`; ``extent`` 0: the whole grid)
    colour_ids, kernel : (G,) int64 and (n, n) float64, optional: every packed texel's index
        among the distinct colours and the NP-MRF rule's kernel between them
        (:func:`npmrf3d._kernels.candidate_decision.kernel_table` with ``h2c``), looked up instead
        of computed (same bits); empty: computed
    smoothness : float, the NP-MRF rule's smoothness prior's strength (0 = none,
        :mod:`npmrf3d._kernels.smoothness`)
    previous : (N0, N1, N2, C) float32, the volume before the pass, whose face neighbours the
        smoothness prior reads (any shape when ``smoothness`` is 0)
    inv_span : (C,) float64, one over each channel's range of exemplar values
    """

    medoid: int
    balance: bool
    likelihood: int
    h2c: float
    outlier: float
    temperature: float
    salt: int
    sampler: int = HEAT_BATH
    origin: np.ndarray = np.zeros(3, dtype=np.int64)
    extent: np.ndarray = np.zeros(3, dtype=np.int64)
    colour_ids: np.ndarray = np.zeros(0, dtype=np.int64)
    kernel: np.ndarray = np.zeros((0, 0), dtype=np.float64)
    smoothness: float = 0.0
    previous: np.ndarray = np.zeros((0, 0, 0, 1), dtype=np.float32)
    inv_span: np.ndarray = np.ones(1, dtype=np.float64)


class VoteTrust(NamedTuple):
    """How much the votes are trusted (ICM with per-voxel temperatures, Urs et al. 2014;
    :func:`_votes`); :data:`NO_TRUST` (empty arrays) trusts every vote fully.

    voxels : (N0, N1, N2) float32, every voxel's trust ``1 - t``
    windows : (V, N0, N1, N2) float32, per view the sum of ``voxels`` over the window of every site
    """

    voxels: np.ndarray
    windows: np.ndarray


NO_TRUST = VoteTrust(np.zeros((0, 0, 0), dtype=np.float32), np.zeros((0, 0, 0, 0), dtype=np.float32))


@jit
def _texel_factors(views, hist, n_views, factors, vdiv, priors, exp_priors):
    """Per packed position-histogram entry, the factors :func:`_votes` weighs a vote for that
    texel by while the histograms are frozen (one batch), side by side in ``factors`` (n, 2) so
    that a vote reads both from one cache line: ``factors[i, 0]`` the position divisor
    ``1 + position_weight * excess`` (1.0 when not over-used), ``factors[i, 1]`` the boost
    ``1 - position_boost * excess`` (1.0 when over-used or without boost); per packed texel
    ``vdiv`` the value-histogram divisor ``1 + val_weight * over`` (1.0 without). A factor of
    1.0 leaves a weight exactly as it is, so the weights keep their bits. With ``value_prior >
    0``, ``priors`` gets every packed texel's histogram prior (:func:`value_prior`) and
    ``exp_priors`` its exponential."""
    pos_hist, hist_off, theta = hist.positions, hist.position_offsets, hist.theta
    position_weight, position_boost = hist.position_weight, hist.position_boost
    ex_bins, val_hist, val_target, val_weight = hist.texel_bins, hist.values, hist.value_target, hist.value_weight
    for v in range(n_views):
        lo = hist_off[v]
        hi = hist_off[v + 1] if v + 1 < n_views else pos_hist.shape[0]
        for i in range(lo, hi):
            excess = pos_hist[i] / theta[v] - 1.0
            factors[i, 0] = 1.0
            factors[i, 1] = 1.0
            if excess > 0.0:
                factors[i, 0] = 1.0 + position_weight * excess
            elif position_boost > 0.0:
                factors[i, 1] = 1.0 - position_boost * excess
    if val_weight > 0.0:
        for g in range(vdiv.shape[0]):
            over = 0.0
            for ch in range(ex_bins.shape[1]):
                b = ex_bins[g, ch]
                gap = val_hist[ch, b] - val_target[ch, b]
                if gap > 0.0:
                    over += gap
            vdiv[g] = 1.0 + val_weight * over
    if hist.value_prior > 0.0:
        for g in range(priors.shape[0]):
            priors[g] = value_prior(ex_bins[g], val_hist, val_target, hist.value_unit, hist.value_prior)
            exp_priors[g] = np.exp(priors[g])


@jit_inline
def _votes(p0, p1, p2, assign, flat_assign, flat_omega, views, hist, trust, flat_windows, out_g, out_v, out_w, factors,
           vdiv, sites, view_starts, vsum, colour_ids, out_ids):
    """Texels voted for voxel ``(p0, p1, p2)`` by every overlapping neighbourhood of every view.

    A neighbourhood at site ``u`` matched with centre ``e`` votes for the texel ``e + (x - u)``
    (plane offsets) with weight ``omega[u] / (1 + position_weight * max(0, H(texel) / theta - 1))``
    (paper eq. 4 with a strength); with ``position_boost > 0`` an under-used texel's weight is
    multiplied by ``1 + position_boost * (1 - H(texel) / theta)`` (this project's addition).
    With ``val_weight > 0`` the weight is further divided by the **value-histogram** factor
    ``1 + val_weight * sum_c max(0, val_hist[c, b_c] - val_target[c, b_c])`` (``b_c`` =
    ``ex_bins[texel, c]``; histograms in units of an even bin's share, this project's addition
    after Kopf et al. 2007's histogram matching). Votes are enumerated view by view, then by row offset
    ``x_r - u_r`` from ``-anchor`` to ``window - 1 - anchor``, then by column offset; texels are
    written as packed rows ``ex_off[v] + local``, and view ``v``'s votes are
    ``view_starts[v] .. view_starts[v + 1] - 1`` (``view_starts``: V + 1 entries). Returns the
    number of votes.

    With ``trust`` (:class:`VoteTrust`, not empty) a vote's weight is further multiplied by the
    mean trust of its neighbourhood's pixels other than the voxel decided,
    ``(windows[v, u] - voxels[x]) / (window**2 - 1)``: a hot neighbourhood says little, and one
    with no trusted pixel does not vote.

    ``views`` (:class:`PackedViews`) holds ``view_axes`` (``axes``), ``ex_off`` (``offsets``),
    ``ewidth`` (``widths``), ``window``, ``anchor`` and ``grid``; ``hist``
    (:class:`SolverHistograms`) ``pos_hist`` (``positions``), ``hist_off``
    (``position_offsets``), ``theta``, the strengths, ``ex_bins`` (``texel_bins``), ``val_hist``
    (``values``) and ``val_target`` (``value_target``).

    ``factors`` and ``vdiv`` are the histograms' factors of every texel (:func:`_texel_factors`);
    ``sites`` (3,) the array index of the first search site along each axis
    (:func:`npmrf3d._kernels.kcoherence.first_site`). ``flat_assign``, ``flat_omega`` and
    ``flat_windows`` are ``assign``, ``omega`` and ``trust.windows`` flattened, once per pass
    rather than per voxel (``assign`` gives the shapes).

    ``vsum`` gets each view's sum of its votes' weights, added in the votes' order (the sums of
    :func:`_view_sums`, the same bits); with ``colour_ids`` not empty, ``out_ids`` every vote's
    texel's colour index ``colour_ids[out_g[q]]``.
    """
    view_axes, ex_off, ewidth = views.axes, views.offsets, views.widths
    tabled = colour_ids.shape[0] > 0
    window, anchor, grid = views.window, views.anchor, views.grid
    hist_off, val_weight = hist.position_offsets, hist.value_weight
    n1 = assign.shape[2]
    n2 = assign.shape[3]
    strides = (n1 * n2, n2, 1)
    n_vox = assign.shape[1] * n1 * n2
    weighted = trust.voxels.shape[0] > 0
    own = np.float64(trust.voxels[p0, p1, p2]) if weighted else 0.0
    here = p0 * strides[0] + p1 * strides[1] + p2
    count = 0
    for v in range(assign.shape[0]):
        view_starts[v] = count
        total = 0.0
        ra = view_axes[v, 0]
        ca = view_axes[v, 1]
        nr = assign.shape[1 + ra]
        nc = assign.shape[1 + ca]
        xr = p0 if ra == 0 else (p1 if ra == 1 else p2)
        xc = p0 if ca == 0 else (p1 if ca == 1 else p2)
        step_r = strides[ra]
        step_c = strides[ca]
        # the flat index of site (u_r, u_c) of this view: base + u_r * step_r + u_c * step_c
        base = v * n_vox + here - xr * step_r - xc * step_c
        w = ewidth[v]
        # the offsets whose sites are searched: x - offset on the sites' lattice (every offset
        # when grid is 1; a level's side is a multiple of grid, so wrapping keeps the lattice)
        first_r = -anchor
        first_c = -anchor
        if grid > 1:
            first_r += (xr - sites[ra] + anchor) % grid
            first_c += (xc - sites[ca] + anchor) % grid
        for orow in range(first_r, window - anchor, grid):
            row = base + wrap(xr - orow, nr) * step_r
            for ocol in range(first_c, window - anchor, grid):
                site = row + wrap(xc - ocol, nc) * step_c
                e = flat_assign[site]
                if e < 0:
                    continue
                share = 1.0
                if weighted:
                    share = (np.float64(flat_windows[site]) - own) / (window * window - 1)
                    if share <= 0.0:
                        continue
                local = e + orow * w + ocol  # (e // w + orow) * w + (e % w + ocol)
                i = hist_off[v] + local
                # omega / (1 + position_weight * excess) or omega * (1 - position_boost * excess)
                weight = np.float64(flat_omega[site]) / factors[i, 0] * factors[i, 1]
                if val_weight > 0.0:
                    weight = weight / vdiv[ex_off[v] + local]
                if weighted:
                    weight = weight * share
                g = ex_off[v] + local
                out_g[count] = g
                out_v[count] = v
                out_w[count] = weight
                if tabled:
                    out_ids[count] = colour_ids[g]
                total += weight
                count += 1
        vsum[v] = total
    view_starts[assign.shape[0]] = count
    return count


@jit_inline
def _top_votes(vg, vv, vw, count, n_views, most, tops, keys, bits):
    """The votes of the ``most`` heaviest distinct (texel, view) into ``tops``, heaviest first:
    a (texel, view) weighs its heaviest vote, ties go to the earlier vote, and it is represented
    by the first of its heaviest votes. Returns how many (at most the distinct (texel, view)
    among the votes).

    In rounds, each taking the first of the heaviest votes left and dropping every vote of its
    (texel, view): that vote is its (texel, view)'s representative, and the rounds take them
    heaviest first, the earlier on ties; a round's drop and the next round's heaviest are one
    pass over the votes. The weights are positive, so their float64 bits
    (``bits``, scratch of ``count`` int64, -1 once dropped) order as the weights do: the rounds
    compare integers, in loops without data-dependent branches. ``keys`` (scratch of ``count``)
    holds every vote's ``texel * n_views + view``."""
    weight_bits = vw.view(np.int64)
    top = np.int64(-1)
    for q in range(count):
        keys[q] = vg[q] * n_views + vv[q]
        bits[q] = weight_bits[q]
        top = max(top, bits[q])
    n = 0
    while n < most and top >= 0:
        pick = 0
        while bits[pick] != top:
            pick += 1
        tops[n] = pick
        n += 1
        if n == most:
            break
        # drop the pick's (texel, view) and find the next round's heaviest in the same pass
        key = keys[pick]
        top = np.int64(-1)
        for q in range(count):
            b = bits[q] if keys[q] != key else np.int64(-1)
            bits[q] = b
            top = max(top, b)
    return n


@jit_inline
def _view_sums(vv, vw, count, vsum):
    """Per view, the sum of its votes' weights (``vsum``, one entry per view)."""
    for v in range(vsum.shape[0]):
        vsum[v] = 0.0
    for q in range(count):
        vsum[vv[q]] += vw[q]


@jit
def _nearest_to_mean(ex_flat, vg, vw, count, mean):
    """The vote whose texel is nearest to the votes' weighted mean colour (``mean``, a buffer of
    one colour), the first on ties: Chen–Wang's mean solver."""
    channels = mean.shape[0]
    total = 0.0
    for ch in range(channels):
        mean[ch] = 0.0
    for q in range(count):
        total += vw[q]
        for ch in range(channels):
            mean[ch] += vw[q] * ex_flat[vg[q], ch]
    for ch in range(channels):
        mean[ch] /= total
    best = 0
    best_d = np.inf
    for q in range(count):
        dd = 0.0
        for ch in range(channels):
            diff = ex_flat[vg[q], ch] - mean[ch]
            dd += diff * diff
        if dd < best_d:
            best_d = dd
            best = q
    return best


@jit
def _medoid_energy(ex_flat, ga, vg, vw, count):
    """``sum_q w_q ||e_ga - e_q||`` over the votes: the weighted medoid's energy of texel ``ga``."""
    e_sum = 0.0
    for q2 in range(count):
        dd = 0.0
        for ch in range(ex_flat.shape[1]):
            diff = ex_flat[ga, ch] - ex_flat[vg[q2], ch]
            dd += diff * diff
        e_sum += vw[q2] * np.sqrt(dd)
    return e_sum


@jit_inline
def _score_candidates(ex_flat, vg, vv, vw, count, vsum, tops, n_try, likelihood, ranked, tabled, h2c, outlier,
                      priors, exp_priors, val_prior, lik, liks, products, prior_of, table, scores):
    """Judge the ``n_try`` candidates ``tops`` (votes, heaviest first): the NP-MRF rule's view
    estimates (``liks`` already filled when ``tabled``) into ``products`` and ``prior_of``
    (``ranked``), ``table`` (the per-view rules) or ``scores`` (annealed objectives); without a
    rule the weighted medoid's energy. Returns the vote of the lowest energy or highest
    objective (the first on ties; 0 when the rule decides later)."""
    best = 0
    best_e = np.inf
    for a in range(n_try):
        ga = vg[tops[a]]
        if likelihood:
            if tabled:
                for v in range(lik.shape[0]):
                    lik[v] = liks[a, v]
            else:
                _decide.view_likelihoods(ex_flat[ga], ex_flat, vg, vv, vw, count, vsum, h2c, outlier, lik)
            prior = 0.0
            if val_prior > 0.0:
                prior = priors[ga]
            if ranked:
                products[a] = _decide.objective_product(lik, likelihood, exp_priors[ga])
                prior_of[a] = prior
                if not tabled:
                    for v in range(lik.shape[0]):
                        liks[a, v] = lik[v]
                continue
            if likelihood >= ML_H1A:
                # per-view rules: each view's estimate, times the prior's factor
                for v in range(lik.shape[0]):
                    table[a, v] = lik[v] * np.exp(prior)
                continue
            score = _decide.objective(lik, likelihood, prior)
            scores[a] = score if likelihood == ML_H2B else np.log(score)
            if -score < best_e:
                best_e = -score
                best = tops[a]
            continue
        e_sum = _medoid_energy(ex_flat, ga, vg, vw, count)
        if val_prior > 0.0:
            e_sum *= np.exp(-priors[ga])
        if e_sum < best_e:
            best_e = e_sum
            best = tops[a]
    return best


@jit
def _heat_bath(scores, n_try, temperature, key):
    """The candidate drawn with probability proportional to ``exp(score / temperature)`` from the
    uniform of the hash ``key``; -1 when every score is -inf (the voxel keeps the best)."""
    top_l = scores[0]
    for a in range(1, n_try):
        top_l = max(top_l, scores[a])
    if not top_l > -np.inf:
        return -1
    total = 0.0
    for a in range(n_try):
        total += np.exp((scores[a] - top_l) / temperature)
    x = (mix(key) + 0.5) / 2147483648.0 * total
    acc = 0.0
    for a in range(n_try):
        acc += np.exp((scores[a] - top_l) / temperature)
        if x < acc:
            return a
    return n_try - 1


@jit_inline
def _copy_texel(volume, p0, p1, p2, texel, texel_bins, val_lo, val_scale, n_bins, old_bins_t, new_bins_t):
    """Give voxel ``(p0, p1, p2)`` the colour of ``texel`` (its value bins ``texel_bins``); when it
    changes, its old and new bins go to ``old_bins_t`` and ``new_bins_t``. Returns 1 if the
    colour changed, else 0."""
    flag = 0
    for ch in range(texel.shape[0]):
        if volume[p0, p1, p2, ch] != texel[ch]:
            flag = 1
    if flag:
        for ch in range(texel.shape[0]):
            old_bins_t[ch] = value_bin(volume[p0, p1, p2, ch], val_lo[ch], val_scale[ch], n_bins)
            new_bins_t[ch] = texel_bins[ch]
    for ch in range(texel.shape[0]):
        volume[p0, p1, p2, ch] = texel[ch]
    return flag


@jit_inline
def _copied_sources(best, vg, vv, view_starts, ex_flat, ex_off, new_src_t):
    """Each view's new source after copying vote ``best``'s texel: the texel itself for its own
    view, for every other view its voted texel nearest to the copied colour (unchanged without
    votes)."""
    g = vg[best]
    for v in range(new_src_t.shape[0]):
        if v == vv[best]:
            new_src_t[v] = g - ex_off[v]
            continue
        near = _decide.nearest_in(view_starts[v], view_starts[v + 1], g, vg, ex_flat)
        if near >= 0:
            new_src_t[v] = vg[near] - ex_off[v]


@jit
def _follow_histograms(src, hist, order, start, flags, old_bins, new_bins, new_src):
    """After a batch, in one thread and in a fixed order: the value histograms follow the changed
    voxels, the position histograms and ``src`` the new sources. Returns the voxels changed."""
    pos_hist, hist_off, val_hist, val_unit = hist.positions, hist.position_offsets, hist.values, hist.value_unit
    n1, n2 = src.shape[2], src.shape[3]
    changed = 0
    for t in range(flags.shape[0]):
        flat = order[start + t]
        p0 = flat // (n1 * n2)
        p1 = (flat // n2) % n1
        p2 = flat % n2
        changed += flags[t]
        if flags[t]:
            for ch in range(old_bins.shape[1]):
                val_hist[ch, old_bins[t, ch]] -= 1.0 / val_unit
                val_hist[ch, new_bins[t, ch]] += 1.0 / val_unit
        for v in range(src.shape[0]):
            old = src[v, p0, p1, p2]
            new = new_src[t, v]
            pos_hist[hist_off[v] + old] -= 1.0
            pos_hist[hist_off[v] + new] += 1.0
            src[v, p0, p1, p2] = new
    return changed


@jit_parallel
def solve(volume, src, assign, omega, views, hist, trust, rule, order, batch_bounds, chunk):
    """Discrete solver (paper section 4.2 with eq. 4), one pass over all voxels.

    ``views`` (:class:`PackedViews`) holds the packed texels ``ex_flat`` and each view's offset
    ``ex_off``; ``hist`` (:class:`SolverHistograms`) the position histograms ``pos_hist`` (at
    ``hist_off``) and the value histograms ``val_*`` with the texels' bins ``ex_bins``; ``rule``
    (:class:`SolverRule`) the decision. ``chunk`` voxels form one parallel work item (any value
    gives the same result).

    ``trust`` (:class:`VoteTrust`) weighs the votes by their neighbourhoods' trust (:func:`_votes`;
    :data:`NO_TRUST`: all trusted).

    Voxels are visited in ``order`` (flat indices), cut into batches at ``batch_bounds``. Within a
    batch every voxel (in parallel) gathers its votes (:func:`_votes`), computes their weighted
    mean colour and copies the voted texel nearest to it (first one on ties) -- or, with
    ``medoid > 0``, among the texels of the ``medoid`` heaviest votes (distinct texel and view),
    the one ``p`` minimising ``sum_q w_q ||e_p - e_q||`` over all votes (a weighted medoid): ``volume`` gets its
    colour, and each view's source becomes that view's voted texel nearest to the copied colour
    (the copied texel itself for its own view). After the batch, in one thread, the position
    histograms ``pos_hist`` (packed per view at ``hist_off``, counts of voxels per source pixel)
    move from the old sources to the new ones. Returns the number of voxels whose colour changed.

    With an NP-MRF ``likelihood`` (the codes of :mod:`npmrf3d._kernels.candidate_decision`) the
    candidates of the ``medoid`` heaviest votes are judged instead by the NP-MRF rule (the
    coherent NP-MRF sampler, :mod:`npmrf3d.methods.npmrf_coherent`): per view, a Parzen estimate
    of the candidate colour's probability from that view's votes,
    ``L_v(p) = sum_{q in v} w_q exp(-||e_p - e_q||^2 / h2c) / sum_{q in v} w_q``, mixed with an
    ``outlier`` share. ML_H2b and ML_H2a combine the views by the product or the minimum and the
    highest score wins (first on ties). ML_H1a and ML_H1b (Urs et al. 2014's per-view argmax
    rules) let each view with votes pick its candidate of highest ``L_v`` (first on ties); ML_H1a
    copies the pick whose own ``L_v`` is the lowest (the least confident view decides, first view
    on ties), ML_H1b gives the voxel the **mean of the picks' colours** -- generally not an
    exemplar colour, the averaging artefact the paper shows -- and each view's source becomes
    its own pick (:func:`npmrf3d._kernels.candidate_decision.winner_sources`). Both ignore
    ``temperature`` (they have no objective to anneal).

    Value histograms (``val_weight > 0``): ``val_hist`` (C, bins) holds the volume's per-channel
    histogram in units of ``val_unit`` voxels (an even bin's share), ``val_target`` the
    exemplars' in the same units, ``ex_bins`` (rows of ``ex_flat``, C) every texel's bins (by
    :func:`value_bins` with ``val_lo``, ``val_scale``); votes are weighted down by the excess of
    their texel's bins (:func:`_votes`) and ``val_hist`` follows the changed voxels between
    batches, so the volume's histogram is pulled towards the exemplars'. With the NP-MRF rule the
    score of a candidate also gets the histogram prior :func:`value_prior` with strength
    ``val_prior`` (0 = off; added to the ML_H2b log-score, a factor ``exp(prior)`` on the ML_H2a
    score and on every view's estimate for ML_H1a and ML_H1b), which vanishes when the
    histograms agree.

    With ``smoothness > 0`` (NP-MRF rule only) every candidate's score also gets the smoothness
    prior of its colour against the voxel's face neighbours in ``previous``
    (:mod:`npmrf3d._kernels.smoothness`), in every rule's terms: added to the log-score, a factor
    ``exp(prior)`` on ML_H2a's score and on each view's estimate of ML_H1a and ML_H1b.

    Annealing (``temperature > 0``, NP-MRF rule only): instead of the highest score, the voxel
    draws candidate ``a`` with probability proportional to ``exp(l_a / temperature)`` (a
    heat-bath step over its candidates; ``l_a`` the ML_H2b log-score, or the log of the ML_H2a
    score), from the uniform ``(mix(salt * n_voxels + flat) + 0.5) / 2**31`` -- a hash of the
    voxel, so the draw depends on no thread count (``salt < 2**31``). With ``sampler``
    ``METROPOLIS`` the voxel instead proposes one candidate drawn uniformly from the same hash and
    accepts it by the Metropolis rule against its current colour's log-score, computed by the
    same estimate from the same votes (:func:`npmrf3d._kernels.candidate_decision.metropolis`);
    a rejected voxel keeps its colour and sources.
    """
    ex_flat, ex_off = views.texels, views.offsets
    ex_bins, val_hist, val_prior = hist.texel_bins, hist.values, hist.value_prior
    val_lo, val_scale, n_bins = hist.value_lo, hist.value_scale, hist.values.shape[1]
    medoid, balance, likelihood, h2c = rule.medoid, rule.balance, rule.likelihood, rule.h2c
    outlier, temperature, salt, sampler = rule.outlier, rule.temperature, rule.salt, rule.sampler
    hist_args = (val_hist, hist.value_target, hist.value_unit, val_prior, val_lo, val_scale)
    colour_ids, kernel = rule.colour_ids, rule.kernel
    smooth, previous, inv_span = rule.smoothness, rule.previous, rule.inv_span
    tabled = kernel.shape[0] > 0
    n_views = assign.shape[0]
    n0, n1, n2, channels = volume.shape
    n_vox = grid_voxels(volume.shape, rule.extent)
    cap = n_views * views.window * views.window
    tried = max(medoid, 1)
    changed = 0
    factors = np.empty((hist.positions.shape[0], 2), dtype=np.float64)
    vdiv = np.empty(ex_flat.shape[0], dtype=np.float64)
    priors = np.zeros(ex_flat.shape[0], dtype=np.float64)
    exp_priors = np.ones(ex_flat.shape[0], dtype=np.float64)
    # the highest objective alone (no annealed draw): ranked by products, no logarithms
    ranked = (likelihood == ML_H2B or likelihood == ML_H2A) and temperature == 0.0
    flat_assign = assign.reshape(-1)
    flat_omega = omega.reshape(-1)
    flat_windows = trust.windows.reshape(-1)
    sites = np.empty(3, dtype=np.int64)
    for axis in range(3):
        sites[axis] = first_site(rule.origin, rule.extent, axis, views.grid)
    for b in range(batch_bounds.shape[0] - 1):
        start = batch_bounds[b]
        m = batch_bounds[b + 1] - start
        new_src = np.empty((m, n_views), dtype=np.int32)
        flags = np.zeros(m, dtype=np.int64)
        old_bins = np.zeros((m, channels), dtype=np.int64)
        new_bins = np.zeros((m, channels), dtype=np.int64)
        n_chunks = (m + chunk - 1) // chunk
        _texel_factors(views, hist, n_views, factors, vdiv, priors, exp_priors)
        for c in prange(n_chunks):
            vg = np.empty(cap, dtype=np.int64)
            vv = np.empty(cap, dtype=np.int64)
            vw = np.empty(cap, dtype=np.float64)
            mean = np.empty(channels, dtype=np.float64)
            vsum = np.empty(n_views, dtype=np.float64)
            uid = np.empty(cap, dtype=np.int64)
            view_starts = np.empty(n_views + 1, dtype=np.int64)
            rows = np.empty(tried, dtype=np.int64)
            liks = np.empty((tried, n_views), dtype=np.float64)
            tops = np.empty(tried, dtype=np.int64)
            vote_keys = np.empty(cap, dtype=np.int64)
            vote_bits = np.empty(cap, dtype=np.int64)
            lik = np.empty(n_views, dtype=np.float64)
            scores = np.empty(tried, dtype=np.float64)
            products = np.empty(tried, dtype=np.float64)
            prior_of = np.zeros(tried, dtype=np.float64)
            table = np.empty((tried, n_views), dtype=np.float64)
            winners = np.empty(n_views, dtype=np.int64)
            colour = np.empty(channels, dtype=np.float32)
            bins = np.empty(channels, dtype=np.int64)
            for t in range(c * chunk, min(m, (c + 1) * chunk)):
                flat = order[start + t]
                p0 = flat // (n1 * n2)
                p1 = (flat // n2) % n1
                p2 = flat % n2
                count = _votes(p0, p1, p2, assign, flat_assign, flat_omega, views, hist, trust, flat_windows, vg, vv,
                               vw, factors, vdiv, sites, view_starts, vsum, colour_ids, uid)
                for v in range(n_views):
                    new_src[t, v] = src[v, p0, p1, p2]
                if count == 0:
                    continue
                if balance:
                    # every view gets the same total say: its votes' weights sum to 1 (then the
                    # sums of the balanced weights)
                    for q in range(count):
                        vw[q] /= vsum[vv[q]]
                    _view_sums(vv, vw, count, vsum)
                if not medoid:
                    best = _nearest_to_mean(ex_flat, vg, vw, count, mean)
                else:
                    # candidates: the votes of the `medoid` heaviest distinct (texel, view), heaviest
                    # first (ties: the earlier vote)
                    n_try = _top_votes(vg, vv, vw, count, n_views, medoid, tops, vote_keys, vote_bits)
                    if likelihood:
                        # the votes' per-view sums and colour ids came with them (_votes); the
                        # balanced weights' sums were taken above
                        if tabled:
                            for a in range(n_try):
                                rows[a] = uid[tops[a]]  # the vote's colour id, read by _votes
                            _decide.candidate_likelihoods(kernel, rows, n_try, uid, vv, vw, count, vsum, outlier, liks)
                    best = _score_candidates(ex_flat, vg, vv, vw, count, vsum, tops, n_try, likelihood, ranked, tabled,
                                             h2c, outlier, priors, exp_priors, val_prior, lik, liks, products, prior_of,
                                             table, scores)
                    if likelihood and smooth > 0.0:
                        add_smoothness(ex_flat, vg, tops, n_try, previous, p0, p1, p2, inv_span, smooth, likelihood,
                                       ranked, products, prior_of, table, scores)
                    if ranked:
                        win = _decide.highest_objective(products, n_try, liks, likelihood, prior_of, -1)
                        best = tops[win] if win >= 0 else 0
                    elif likelihood >= ML_H1A:
                        _decide.view_winners(table, n_try, vsum, winners)
                        if winners.max() < 0:
                            continue
                        if likelihood == ML_H1B:
                            _decide.mean_of_winners(colour, winners, tops, vg, ex_flat)
                            flags[t] = _decide.write_colour(volume, p0, p1, p2, colour, hist_args, old_bins[t],
                                                            new_bins[t])
                            _decide.winner_sources(winners, tops, vg, vv, view_starts, ex_flat, ex_off, new_src[t])
                            continue
                        best = tops[_decide.least_confident(table, winners)]
                    elif likelihood and temperature > 0.0 and sampler == METROPOLIS:
                        current = _decide.colour_score(volume[p0, p1, p2], ex_flat, vg, vv, vw, count, vsum, h2c,
                                                       outlier, likelihood, hist_args, bins, lik)
                        if smooth > 0.0:
                            current += smoothness_prior(volume[p0, p1, p2], previous, p0, p1, p2, inv_span, smooth)
                        key = salt * n_vox + global_flat(p0, p1, p2, volume.shape, rule.origin, rule.extent)
                        pick = _decide.metropolis(scores, n_try, current, temperature, key)
                        if pick < 0:
                            continue
                        best = tops[pick]
                    elif likelihood and temperature > 0.0 and n_try > 1:
                        key = salt * n_vox + global_flat(p0, p1, p2, volume.shape, rule.origin, rule.extent)
                        pick = _heat_bath(scores, n_try, temperature, key)
                        if pick >= 0:
                            best = tops[pick]
                g = vg[best]
                flags[t] = _copy_texel(volume, p0, p1, p2, ex_flat[g], ex_bins[g], val_lo, val_scale, n_bins,
                                       old_bins[t], new_bins[t])
                _copied_sources(best, vg, vv, view_starts, ex_flat, ex_off, new_src[t])
        if not hist.follow:
            # no histogram to move: every voxel's own sources, in parallel (a voxel reads only its own)
            for t in prange(m):
                flat = order[start + t]
                for v in range(n_views):
                    src[v, flat // (n1 * n2), (flat // n2) % n1, flat % n2] = new_src[t, v]
            changed += flags.sum()
            continue
        changed += _follow_histograms(src, hist, order, start, flags, old_bins, new_bins, new_src)
    return changed
