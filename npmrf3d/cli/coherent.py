"""``npmrf3d coherent``: the coherent NP-MRF sampler (:mod:`npmrf3d.methods.npmrf_coherent`).

Options, defaults, limits and ``--help`` come from the fields of
:class:`npmrf3d.methods.npmrf_coherent.CoherentConfig` through
:func:`npmrf3d.cli._generic.add_method_parser`.
"""

from __future__ import annotations

from ..methods.npmrf_coherent import METHOD
from ._generic import add_method_parser

__all__ = ["register"]


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
        out="npmrf3d-coherent-out", formatter_class=formatter_class,
    )
