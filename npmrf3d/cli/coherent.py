"""``npmrf3d coherent``: the coherent NP-MRF sampler (:mod:`npmrf3d.methods.npmrf_coherent`).

Options, defaults and ``--help`` come from :class:`npmrf3d.methods.npmrf_coherent.CoherentConfig` through
:func:`npmrf3d.cli._generic.add_method_parser`.
"""

from __future__ import annotations

from ..methods.npmrf_coherent import METHOD
from ._generic import add_method_parser
from .baseline import CHEN_WANG_HELP, refuse_coherence_bias

__all__ = ["register", "FIELD_HELP"]

#: One line per configuration field of :class:`npmrf3d.methods.npmrf_coherent.CoherentConfig`.
FIELD_HELP = {
    "window": "window side per level, coarsest first: one number or one per level",
    "levels": "resolution levels, coarse to fine",
    "iterations": "search + decision iterations per level: one number or one per level, coarsest first",
    "grid": "neighbourhoods searched and voting every GRID voxels along both plane axes of each view "
            "(1 = every voxel)",
    "heuristic": "how the views' Parzen estimates decide among the candidates: ML_H2b (product) or "
                 "ML_H2a (minimum) of the views' estimates; ML_H1a (each view picks its best, the least "
                 "confident view's pick wins) or ML_H1b (the mean of the views' picks: makes colours the "
                 "exemplar lacks), both ICM only (--t0 0)",
    "centre_bandwidth": "width of the Parzen kernel on candidate colours, as a factor of the exemplar's "
                        "standard deviation, > 0",
    "outlier": "share of a uniform term mixed into each view's estimate before the views combine, in [0, 1)",
    "k": "size of the k-coherence sets",
    "index_weight": "strength of the index-histogram penalty on the search distance, >= 0 (0 = off)",
    "position_weight": "strength of the position-histogram re-weighting of the votes, >= 0 (0 = off)",
    "position_boost": "votes for under-used exemplar pixels weigh up to 1 + B times more, >= 0 (0 = off)",
    "random_candidates": "random valid centres added to each site's candidates (reach sparse features)",
    **{name: CHEN_WANG_HELP[name] for name in ("global_share", "coherence_bias", "value_weight",
                                               "value_prior", "value_bins", "phase_weight", "blockwise",
                                               "pilot", "whole_voxels")},
    "t0": "annealing: first temperature of each level; each voxel draws among its candidates with "
          "probability ~ exp(score / T) (0 = no annealing: the highest score decides), >= 0",
    "t_end": "annealing: last temperature of each level, in (0, t0] (geometric) or [0, t0] (linear)",
    "schedule": "annealing: how the temperature falls from --t0 to --t-end over a level's iterations "
                "(geometric or linear)",
    "sampler": "annealing: heat-bath (draw among the candidates ~ exp(score / T)) or metropolis (propose "
               "one candidate uniformly, accept it if it scores at least the current colour, else with "
               "probability exp(score difference / T))",
    "icm": "ICM with per-voxel temperatures (Urs et al. 2014) instead of --iterations: trust-weighted "
           "search and votes, warm voxels re-decided until the stop rule",
    "xi": "icm: cooling step, a negative number (more negative cools faster)",
    "stop": "icm: stop a level once the global temperature fell by this fraction, in (0, 1] (1 = down to 0)",
    "max_sweeps": "icm: hard limit of sweeps per level, a positive integer",
    "upsample": "icm: the 7 non-inherited children of a voxel copy its shifted source (8/8) or get random "
                "sources (1/8)",
    "inherit": "icm: inherited voxels may still change (resynth) or are frozen (fixed); their temperature "
               "stays 0",
}


def register(commands, formatter_class) -> None:
    """Add the ``coherent`` sub-command."""
    add_method_parser(
        commands, "coherent", METHOD,
        help="synthesise with the coherent NP-MRF sampler (NP-MRF likelihood over coherent candidates)",
        description=(
            "The coherent NP-MRF sampler: each view's Parzen estimate sums over the coherent\n"
            "candidates of every neighbourhood that contains a voxel (Chen & Wang's search,\n"
            "votes and histograms), the views combine by a heuristic (ML_H2b, ML_H2a, ML_H1a or\n"
            "ML_H1b), and the voxel copies the chosen exemplar texel. Colours are exemplar\n"
            "colours, except ML_H1b's means of the views' picks.\n\n"
            "examples:\n"
            "  npmrf3d coherent bundled:gravel --size 64\n"
            "  npmrf3d coherent wood.png --size 128 --out wood"
        ),
        out="npmrf3d-coherent-out", field_help=FIELD_HELP, formatter_class=formatter_class,
        refuse=refuse_coherence_bias,
    )
