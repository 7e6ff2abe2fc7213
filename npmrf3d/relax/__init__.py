"""Relaxation algorithms, one module each: ``icm`` (per-voxel temperatures) and ``anneal``."""

from .anneal import relax_anneal
from .icm import relax_icm

RELAXATIONS = {"icm": relax_icm, "anneal": relax_anneal}

__all__ = ["RELAXATIONS", "relax_anneal", "relax_icm"]
