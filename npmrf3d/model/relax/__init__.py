"""Relaxation algorithms, one module each: ``icm`` (per-voxel temperatures) and ``anneal``.

:data:`RELAXATIONS` maps a name to a :class:`Relaxation`: the function that relaxes one level
and the frozen dataclass of its own options (whose field defaults are the defaults of the API,
the configuration and the command line). The sweep body both share is :mod:`._sweep`.
"""

from typing import NamedTuple

from .anneal import AnnealOptions, relax_anneal
from .icm import IcmOptions, relax_icm


class Relaxation(NamedTuple):
    """A relaxation: ``run(volume, labels_volume, temps, inherited, models, classes, *, ...)``
    and its options dataclass."""

    run: object
    options: type


RELAXATIONS: dict[str, Relaxation] = {
    "icm": Relaxation(relax_icm, IcmOptions),
    "anneal": Relaxation(relax_anneal, AnnealOptions),
}

__all__ = ["AnnealOptions", "IcmOptions", "RELAXATIONS", "Relaxation", "relax_anneal", "relax_icm"]
